"""The electronic PI speed governor (docs/theory.md §8.10): it measures the crank speed and sets the throttle valve
with a proportional-integral law, without a centrifugal sensor.

With the relative speed error e = (omega_s - omega) / omega_s, the command is u = x + K_p e and the throttle
clip(u, low, high) within the valve's travel; the integral part x [-] (the governor's one state, y[2]) follows

    x' = (K_p e + clip(u) - u) / T_i,

which is K_p e / T_i (u = K_p (e + 1/T_i int e dt)) while the valve is within its travel; on a stop it is
(clip(u) - x) / T_i, so that x tracks the stop instead of winding up (back-calculation, tracking time T_i). The
right-hand side is continuous: the governor has no modes and no guards. The law is the module's functions pi_throttle
and pi_integral_rate, which both paths run (solvers/compiled/codegen.py compiles their source).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mech_regulator.governors.kind import (
    AveragedMachine,
    GovernorKind,
    GovernorSource,
    Guard,
    Mode,
    OperatingPoint,
    SourceWriter,
    builds,
    machine_speed,
)
from mech_regulator.scene import governor_keys

INTEGRAL = 2  # index of the integral part x in the full state vector


def pi_throttle(integral, omega, set_speed, gain, integral_time, low, high):
    """Throttle [-]: u = x + K_p (omega_s - omega) / omega_s clipped to [low, high] (integral_time unread: the two
    functions take the same numbers, ElectronicGovernor.law)."""
    command = integral + gain * (set_speed - omega) / set_speed
    return min(max(command, low), high)


def pi_integral_rate(integral, omega, set_speed, gain, integral_time, low, high):
    """x' [1/s] = (K_p e + clip(u) - u) / T_i: K_p e / T_i within the travel, (clip(u) - x) / T_i on a stop."""
    return (pi_throttle(integral, omega, set_speed, gain, integral_time, low, high) - integral) / integral_time


def pi_loop_coefficients(
    gain: float, integral_time: float, set_speed: float, drive: float, self_regulation: float, inertia: float
) -> tuple[float, float]:
    """(a1, a0) of the closed loop's characteristic polynomial p^2 + a1 p + a0 at the set speed (docs/theory.md
    §8.10): the cycle-averaged machine J_m omega' = throttle M_d + M_c with drive = M_d [N m] and self_regulation D =
    d(throttle M_d + M_c)/d omega at a fixed throttle [N m s], inertia J_m [kg m^2]; a1 = (K_p M_d / omega_s - D) / J_m,
    a0 = K_p M_d / (omega_s T_i J_m). Stable iff both are positive (Hurwitz for a quadratic)."""
    a1 = (gain * drive / set_speed - self_regulation) / inertia
    return a1, gain * drive / (set_speed * integral_time * inertia)


@dataclass(frozen=True)
class ElectronicGovernor(GovernorKind):
    """The PI governor assembled from its scene entry: set_speed omega_s [rad/s] (crank), gain K_p [-] (throttle per
    relative speed error), integral_time T_i [s], travel (low, high) [-] of the valve. No sensor, no valve table (the
    throttle is the law's output itself), no modes."""

    set_point: float
    gain: float
    integral_time: float
    travel: tuple[float, float] = (0.0, 1.0)

    kind = "pi"
    speed_action = True  # the proportional part
    sensor = None
    valve = None
    state_names = ("integral",)
    state_units = ("-",)
    hybrid = False

    def law(self, ideal: bool = False) -> tuple[float, ...]:
        """The numbers pi_throttle and pi_integral_rate read after x and omega: (omega_s, K_p, T_i, low, high);
        ideal: without the travel's limits (the linearised loop)."""
        low, high = (-math.inf, math.inf) if ideal else self.travel
        return self.set_point, self.gain, self.integral_time, low, high

    def throttle(self, y: np.ndarray, ideal: bool = False) -> float:
        """Throttle 0..1 at state y (pi_throttle)."""
        return pi_throttle(y[INTEGRAL], y[1], *self.law(ideal))

    @property
    def throttle_range(self) -> tuple[float, float]:
        """The valve's travel (low, high) [-]."""
        return self.travel

    def throttle_command(self, y: np.ndarray) -> tuple[float, float]:
        """The command x + K_p (omega_s - omega) / omega_s at state y [-] (pi_throttle without the travel's stops) and
        its sensitivity to the crank speed, -K_p / omega_s [s/rad]."""
        return self.throttle(y, ideal=True), -self.gain / self.set_point

    def set_speed(self) -> float:
        """The crank speed [rad/s] the governor holds: its set point, at every load within the valve's travel."""
        return self.set_point

    def initial_state(
        self, omega: float, sleeve: float | None, servo: float | None, balance_throttle: Callable[[float], float]
    ) -> np.ndarray:
        """The integral part at t = 0: the throttle that balances the load at the initial speed omega [rad/s], less
        the proportional part there (sleeve and servo: none, the scene's schema refuses them)."""
        balance = min(max(balance_throttle(omega), self.travel[0]), self.travel[1])
        return np.array([balance - self.gain * (self.set_point - omega) / self.set_point])

    def initial_mode(self, y: np.ndarray) -> Mode:
        """No modes: ('', '')."""
        return "", ""

    def derivatives(self, mode: Mode | None, ideal: bool = False) -> Callable[[np.ndarray], list[float]]:
        """y -> [x'] (pi_integral_rate); ideal: without the travel's limits."""
        law = self.law(ideal)
        return lambda y: [pi_integral_rate(y[INTEGRAL], y[1], *law)]

    def guards(self, mode: Mode) -> list[Guard]:
        """None: the right-hand side is continuous."""
        return []

    def signals(self, y: np.ndarray) -> dict[str, np.ndarray | float]:
        """The governor's outputs at state(s) y besides the throttle: the integral part x [-]."""
        return {"integral": y[INTEGRAL]}

    def source(self, writer: SourceWriter, valve_anchor: str) -> GovernorSource:
        """pi_throttle and pi_integral_rate compiled, the law's numbers in p; no guards."""
        throttle_name, rate_name = writer.shared(pi_throttle, pi_integral_rate)
        law = f"y[{INTEGRAL}], omega, " + ", ".join(writer.scalar(value) for value in self.law())
        return GovernorSource(f"{throttle_name}({law})", [f"dydt[{INTEGRAL}] = {rate_name}({law})"], [], 0)

    def operating_point(self, machine: AveragedMachine, external_load: float) -> OperatingPoint:
        """The steady state (docs/theory.md §8.10): the integral part removes any speed error, so the speed is the set
        speed and the throttle the one that balances the load there, unless that throttle lies beyond the valve's
        travel: then the valve sits on its stop and the speed follows from the machine's own balance. No sleeve, no
        servo (NaN)."""
        omega = self.set_speed()
        mean_inertia = machine.cycle_averages(omega, external_load)[0]
        throttle = machine.balance_throttle(omega, external_load)
        low, high = self.travel
        if low <= throttle <= high:
            return OperatingPoint(external_load, omega, math.nan, throttle, math.nan, "", mean_inertia)
        stop, name = (high, "high") if throttle > high else (low, "low")

        def surplus(w: float) -> float:
            _, drive, other = machine.cycle_averages(w, external_load)
            return stop * drive + other

        limited = f"valve on its {name} stop"
        speed = machine_speed(surplus, omega)
        if math.isnan(speed):
            limited += "; no steady speed at that throttle"
        return OperatingPoint(external_load, speed, math.nan, stop, math.nan, limited, mean_inertia)

    def equilibrium_state(self, point: OperatingPoint) -> np.ndarray:
        """[x]: the integral part x = throttle - K_p e at the point."""
        error = (self.set_point - point.speed) / self.set_point
        return np.array([point.throttle - self.gain * error])

    def state_scale(self, point: OperatingPoint) -> np.ndarray:
        """[1]: x is a throttle."""
        return np.array([1.0])

    def loop_coefficients(self, machine: AveragedMachine, point: OperatingPoint) -> tuple[float, float]:
        """(a1, a0) of the PI loop at an operating point (pi_loop_coefficients, docs/theory.md §8.10): the averaged
        machine's drive M_d and inertia J_m at the point's speed, its self-regulation D = d(throttle M_d + M_c)/d omega
        at the point's throttle by central differences."""
        load = point.external_load
        inertia, drive, _ = machine.cycle_averages(point.speed, load)

        def net(omega: float) -> float:
            _, drive_at, other = machine.cycle_averages(omega, load)
            return point.throttle * drive_at + other

        step = 1e-6 * max(abs(point.speed), 1.0)
        regulation = (net(point.speed + step) - net(point.speed - step)) / (2.0 * step)
        return pi_loop_coefficients(self.gain, self.integral_time, self.set_point, drive, regulation, inertia)

    def title(self) -> str:
        """'electronic PI governor'."""
        return "electronic PI governor"

    def set_speed_text(self) -> str:
        """Its set speed, held at every load within the valve's travel."""
        return (
            f"Set speed ω_set = {self.set_speed():.6g} rad/s: the electronic PI governor's, "
            "held at every load the valve can balance. Throttle in 0..1; below it the integral "
            "part x of the PI law."
        )

    def plotted(self) -> tuple[str, str, float, str]:
        """The integral part x [-] (no sleeve)."""
        return "integral", "integral part x", 1.0, "-"

    def joints(self) -> tuple[tuple[str, str, str | None], ...]:
        """throttle and integral."""
        return ("throttle", "throttle", None), ("integral", "integral", None)

    def describe(self) -> list[str]:
        """Lines for `describe`: the PI law."""
        return [
            (
                f"electronic PI governor: throttle = x + {self.gain:g} (omega_s - omega) / omega_s within "
                f"{self.travel[0]:g}..{self.travel[1]:g}, omega_s = {self.set_point:g} rad/s, x' = {self.gain:g} e / "
                f"{self.integral_time:g} s (tracking the travel's stops)"
            )
        ]


@builds(governor_keys.PIGovernor)
def build(spec: governor_keys.PIGovernor, balance_throttle: Callable[[float], float]) -> ElectronicGovernor:
    """The PI governor of a scene's entry (type 'pi')."""
    return ElectronicGovernor(
        set_point=spec.set_speed,
        gain=spec.gain,
        integral_time=spec.integral_time,
        travel=(spec.travel[0], spec.travel[1]),
    )
