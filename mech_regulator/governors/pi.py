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

Mode = tuple[str, str]
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
class ElectronicGovernor:
    """The PI governor assembled from its scene entry: set_speed omega_s [rad/s] (crank), gain K_p [-] (throttle per
    relative speed error), integral_time T_i [s], travel (low, high) [-] of the valve."""

    set_point: float
    gain: float
    integral_time: float
    travel: tuple[float, float] = (0.0, 1.0)

    kind = "pi"
    state_names = ("integral",)
    has_friction = False
    valve_breaks = ()  # no valve table: the throttle is the law's output itself

    def law(self, ideal: bool = False) -> tuple[float, ...]:
        """The numbers pi_throttle and pi_integral_rate read after x and omega: (omega_s, K_p, T_i, low, high);
        ideal: without the travel's limits (the linearised loop)."""
        low, high = (-math.inf, math.inf) if ideal else self.travel
        return self.set_point, self.gain, self.integral_time, low, high

    def throttle(self, y: np.ndarray, ideal: bool = False) -> float:
        """Throttle 0..1 at state y (pi_throttle)."""
        return pi_throttle(y[INTEGRAL], y[1], *self.law(ideal))

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

    def guards(self, mode: Mode) -> list:
        """None: the right-hand side is continuous."""
        return []

    def signals(self, y: np.ndarray) -> dict[str, np.ndarray | float]:
        """The governor's outputs at state(s) y besides the throttle: the integral part x [-]."""
        return {"integral": y[INTEGRAL]}

    def describe(self) -> list[str]:
        """Lines for `describe`: the PI law."""
        return [
            (
                f"electronic PI governor: throttle = x + {self.gain:g} (omega_s - omega) / omega_s within "
                f"{self.travel[0]:g}..{self.travel[1]:g}, omega_s = {self.set_point:g} rad/s, x' = {self.gain:g} e / "
                f"{self.integral_time:g} s (tracking the travel's stops)"
            )
        ]
