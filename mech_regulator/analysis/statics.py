"""Statics of a governed machine (docs/theory.md §8.3, §8.6): the governor's static characteristic, its
degree of non-uniformity and insensitivity, and the operating point of the cycle-averaged machine
for a given load, with the static error (droop) a load change leaves.

The machine is cycle-averaged at constant speed (MachineModel.cycle_averages): in steady operation
throttle * M_d(omega) + M_c(omega) = 0 in the mean over a dynamic period.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from mech_regulator.governors import Governor
from mech_regulator.governors.pi import ElectronicGovernor
from mech_regulator.model import MachineModel


@dataclass(frozen=True)
class StaticCharacteristic:
    """Equilibrium crank speed against sleeve position over the stroke (the part of it where a speed can
    hold the sleeve: CentrifugalSensor.characteristic_range).

    sleeve [m]; speed [rad/s] (no friction); speed_low / speed_high [rad/s]: the band within which
    static friction holds the sleeve; statism = (omega(z_high) - omega(z_low)) / omega_mean over the
    stroke [-]; insensitivity = (speed_high - speed_low) / speed at each sleeve position [-].
    """

    sleeve: np.ndarray
    speed: np.ndarray
    speed_low: np.ndarray
    speed_high: np.ndarray
    statism: float
    insensitivity: np.ndarray


def static_characteristic(governor: Governor, points: int = 101) -> StaticCharacteristic:
    """The sensor's static characteristic: the speed at which the lift vanishes at each sleeve position z (Porter:
    omega_g^2 = ((m + M) g + F_spring(z) +- F_s) / (m l cos a); CentrifugalSensor.equilibrium_speed)."""
    sensor = governor.sensor
    sleeve = np.linspace(*sensor.characteristic_range(), points)
    static = sensor.static_friction
    speed = np.array([sensor.equilibrium_speed(z) for z in sleeve])
    low = np.array([sensor.equilibrium_speed(z, -static) for z in sleeve])
    high = np.array([sensor.equilibrium_speed(z, static) for z in sleeve])
    statism = (speed[-1] - speed[0]) / (0.5 * (speed[-1] + speed[0]))
    return StaticCharacteristic(sleeve, speed, low, high, statism, (high - low) / speed)


@dataclass(frozen=True)
class OperatingPoint:
    """Steady operation of the cycle-averaged governed machine under an external load.

    external_load [N m]; speed [rad/s]; sleeve [m]; throttle [-]; servo [-] (indirect, else NaN);
    limited: what holds the point instead of the governor ('' when the governor regulates), e.g.
    'sleeve on its high stop' or 'servo on its low stop'; mean_inertia [kg m^2].
    """

    external_load: float
    speed: float
    sleeve: float
    throttle: float
    servo: float
    limited: str
    mean_inertia: float


def operating_point(model: MachineModel, external_load: float) -> OperatingPoint:
    """Solve throttle * M_d(omega) + M_c(omega) = 0 together with the governor's statics.

    direct: omega = omega(z) on the static characteristic, throttle = valve(z), one equation in z;
    indirect without or with isodromic feedback: z = pilot_neutral (astatic), throttle from the balance;
    rigid feedback: pilot closed at z = pilot_neutral - rho (s - s_ref), one equation in z.
    If the balance needs a sleeve or servo beyond its stops, the point sits on the stop and the speed
    follows from the machine's own balance at that throttle.
    """
    governor = model.governor
    assert governor is not None, "operating_point reads a machine with a governor"
    if isinstance(governor, ElectronicGovernor):  # kind 'pi'
        return _pi_operating_point(model, external_load)
    sensor = governor.sensor
    valve = governor.valve  # throttle(z) for direct action, None for indirect (Governor)
    z_low, z_high = sensor.characteristic_range()
    mean_inertia = model.cycle_averages(sensor.equilibrium_speed(z_low), external_load)[0]

    def surplus(throttle: float, omega: float) -> float:
        _, drive, other = model.cycle_averages(omega, external_load)
        return throttle * drive + other

    def point(z: float, throttle: float, servo: float, limited: str = "") -> OperatingPoint:
        omega = sensor.equilibrium_speed(z)
        if limited:
            omega = _machine_speed(lambda w: surplus(throttle, w), omega)
            if math.isnan(omega):
                return OperatingPoint(
                    external_load,
                    omega,
                    z,
                    throttle,
                    servo,
                    f"{limited}; no steady speed at that throttle",
                    mean_inertia,
                )
            z = sensor.equilibrium_sleeve(omega)
            if valve is not None:
                throttle = valve(z)
        return OperatingPoint(external_load, omega, z, throttle, servo, limited, mean_inertia)

    if valve is not None:

        def balance(z: float) -> float:
            return surplus(valve(z), sensor.equilibrium_speed(z))

        if balance(z_high) > 0.0:
            return point(z_high, valve(z_high), math.nan, "sleeve on its high stop")
        if balance(z_low) < 0.0:
            return point(z_low, valve(z_low), math.nan, "sleeve on its low stop")
        z = optimize.brentq(balance, z_low, z_high, xtol=1e-14)
        return point(z, valve(z), math.nan)

    s_low, s_high = governor.travel
    if governor.feedback == "rigid":

        def servo_at(z: float) -> float:
            return governor.feedback_reference - (z - governor.pilot_neutral) / governor.feedback_gain
    else:

        def servo_at(z: float) -> float:
            return model.balance_throttle(sensor.equilibrium_speed(z), external_load)

    def balance_servo(z: float) -> float:
        return surplus(min(max(servo_at(z), s_low), s_high), sensor.equilibrium_speed(z))

    z = governor.pilot_neutral
    if governor.feedback == "rigid":
        for stop, name, outside in (
            (z_high, "high", balance_servo(z_high) > 0.0),
            (z_low, "low", balance_servo(z_low) < 0.0),
        ):
            if outside:
                servo = min(max(servo_at(stop), s_low), s_high)
                return point(stop, servo, servo, f"sleeve on its {name} stop")
        z = optimize.brentq(balance_servo, z_low, z_high, xtol=1e-14)
    servo = servo_at(z)
    if servo > s_high:
        return point(z, s_high, s_high, "servo on its high stop")
    if servo < s_low:
        return point(z, s_low, s_low, "servo on its low stop")
    return point(z, servo, servo)


def _pi_operating_point(model: MachineModel, external_load: float) -> OperatingPoint:
    """The PI governor's steady state (docs/theory.md §8.10): the integral part removes any speed error, so the speed
    is the set speed and the throttle the one that balances the load there, unless that throttle lies beyond the
    valve's travel: then the valve sits on its stop and the speed follows from the machine's own balance. No sleeve,
    no servo (NaN)."""
    governor = model.governor
    assert isinstance(governor, ElectronicGovernor), "_pi_operating_point reads a PI governor"
    omega = governor.set_speed()
    mean_inertia = model.cycle_averages(omega, external_load)[0]
    throttle = model.balance_throttle(omega, external_load)
    low, high = governor.travel
    if low <= throttle <= high:
        return OperatingPoint(external_load, omega, math.nan, throttle, math.nan, "", mean_inertia)
    stop, name = (high, "high") if throttle > high else (low, "low")

    def surplus(w: float) -> float:
        _, drive, other = model.cycle_averages(w, external_load)
        return stop * drive + other

    limited = f"valve on its {name} stop"
    speed = _machine_speed(surplus, omega)
    if math.isnan(speed):
        limited += "; no steady speed at that throttle"
    return OperatingPoint(external_load, speed, math.nan, stop, math.nan, limited, mean_inertia)


def _machine_speed(surplus, guess: float) -> float:
    """Speed [rad/s] where the averaged machine balances at a fixed throttle: root of surplus(omega)
    bracketed outward from guess (NaN if the machine has no steady speed)."""
    lo, hi = guess, guess
    for _ in range(60):
        if surplus(lo) > 0.0 > surplus(hi) or surplus(lo) < 0.0 < surplus(hi):
            return optimize.brentq(surplus, lo, hi, xtol=1e-12)
        lo, hi = lo / 1.25, hi * 1.25
    return math.nan


@dataclass(frozen=True)
class Droop:
    """Static error of the governed machine: slope d omega / d load [rad/s per N m] at the scene's
    initial load and the speed change [rad/s] each of the scenario's load events will leave."""

    per_unit_load: float
    per_event: list[float]


def droop(model: MachineModel) -> Droop:
    """Speed change per unit of external load, and per load event, from operating points."""
    load = model.external_load(0.0)
    step = max(1e-3, 1e-3 * abs(load))
    slope = (operating_point(model, load + step).speed - operating_point(model, load - step).speed) / (2 * step)
    levels = [load] + [event.torque for event in model.scene.scenario.load_events]
    speeds = [operating_point(model, level).speed for level in levels]
    return Droop(slope, [after - before for before, after in zip(speeds, speeds[1:])])
