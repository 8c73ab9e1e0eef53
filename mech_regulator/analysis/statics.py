"""Statics of a governed machine (docs/theory.md §8.3, §8.6): the governor's static characteristic, its
degree of non-uniformity and insensitivity, and the operating point of the cycle-averaged machine
for a given load, with the static error (droop) a load change leaves.

The machine is cycle-averaged at constant speed (MachineModel.cycle_averages): in steady operation
throttle * M_d(omega) + M_c(omega) = 0 in the mean over a dynamic period.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mech_regulator.governors.kind import OperatingPoint
from mech_regulator.governors.sensor import CentrifugalSensor
from mech_regulator.model import MachineModel

__all__ = ["Droop", "OperatingPoint", "StaticCharacteristic", "droop", "operating_point", "static_characteristic"]


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


def static_characteristic(sensor: CentrifugalSensor, points: int = 101) -> StaticCharacteristic:
    """A centrifugal sensor's static characteristic: the speed at which the lift vanishes at each sleeve position z
    (Porter: omega_g^2 = ((m + M) g + F_spring(z) +- F_s) / (m l cos a); CentrifugalSensor.equilibrium_speed)."""
    sleeve = np.linspace(*sensor.characteristic_range(), points)
    static = sensor.static_friction
    speed = np.array([sensor.equilibrium_speed(z) for z in sleeve])
    low = np.array([sensor.equilibrium_speed(z, -static) for z in sleeve])
    high = np.array([sensor.equilibrium_speed(z, static) for z in sleeve])
    statism = (speed[-1] - speed[0]) / (0.5 * (speed[-1] + speed[0]))
    return StaticCharacteristic(sleeve, speed, low, high, statism, (high - low) / speed)


def operating_point(model: MachineModel, external_load: float) -> OperatingPoint:
    """Steady operation of the cycle-averaged governed machine under an external load [N m]: throttle * M_d(omega) +
    M_c(omega) = 0 together with its governor's statics (GovernorKind.operating_point)."""
    governor = model.governor
    if governor is None:
        raise ValueError(f"scene '{model.scene.name}' has no governor: it has no operating point")
    return governor.operating_point(model, external_load)


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
