"""Advice on the choice of solver: a stiff elastic coupling makes explicit methods crawl.

The coupling's relative motion (twist) is a damped oscillator of the two inertias against each other,
with reduced inertia J_r = J1 I2 / (J1 + I2) (J1 and I2 the two sides' mean inertias) and, for a nonlinear
characteristic, the local stiffness k = dM_elastic/dtwist at the operating twist (the static twist at the
initial speed):

    J_r twist'' + c twist' + k twist = ...,   lambda = -c / (2 J_r) +- sqrt((c / (2 J_r))^2 - k / J_r).

An explicit Runge-Kutta method stays stable only while h |lambda| stays inside its stability region
(about 3 to 6 along the negative real axis and the imaginary axis), whatever the tolerance asks for:
a fast mode that has long decayed still dictates the step. Implicit methods (Radau, BDF) are not
limited by it. The adaptive methods shrink their steps to stay stable (slowly: stiffness_advice); the
fixed-step RK4 cannot, so a step outside its region is refused (rk4_stability_refusal): its amplification
per step of the mode, R(h lambda) with R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24, must keep |R| <= 1.
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass

import numpy as np

from mech_regulator.model import MachineModel

EXPLICIT_METHODS = ("RK45", "RK23", "DOP853", "RK4")
STABILITY_LIMIT = 3.0  # h |lambda| an explicit method of this family keeps stable (conservatively) [-]
STIFF_STEPS = 20_000  # steps imposed by stability alone above which the user is advised to switch


@dataclass(frozen=True)
class CouplingModes:
    """The coupling's relative mode: reduced inertia [kg m^2], the (local) stiffness k [N m/rad] at the operating
    twist [rad], natural frequency sqrt(k / J_r) [rad/s], damping ratio c / (2 sqrt(k J_r)) [-] and the eigenvalue
    of largest magnitude [1/s]."""

    reduced_inertia: float
    stiffness: float
    operating_twist: float
    natural_frequency: float
    damping_ratio: float
    fastest: complex


def coupling_modes(model: MachineModel) -> CouplingModes | None:
    """The coupling's relative mode (module docstring), or None without a coupling."""
    coupling = model.coupling
    if coupling is None:
        return None
    crank_inertia = model.mean_crank_inertia
    driven_inertia = float(np.mean([coupling.driven.state(angle)[0] for angle in np.linspace(0.0, 2.0 * math.pi, 360,
                                                                                                 endpoint=False)]))
    reduced = crank_inertia * driven_inertia / (crank_inertia + driven_inertia)
    twist = model.static_twist(model.scene.scenario.initial.omega)
    stiffness = float(coupling.local_stiffness(twist))
    natural = math.sqrt(stiffness / reduced)
    ratio = coupling.damping / (2.0 * math.sqrt(stiffness * reduced))
    half = coupling.damping / (2.0 * reduced)
    root = cmath.sqrt(half * half - stiffness / reduced)
    return CouplingModes(reduced, stiffness, twist, natural, ratio, max(-half + root, -half - root, key=abs))


def stiffness_advice(model: MachineModel) -> str | None:
    """A note for the user when the scene's explicit method would need more than STIFF_STEPS steps for
    stability alone over the scenario (None otherwise)."""
    modes = coupling_modes(model)
    method = model.scene.solver.method
    if modes is None or method not in EXPLICIT_METHODS:
        return None
    largest_step = STABILITY_LIMIT / abs(modes.fastest)
    steps = model.scene.scenario.duration / largest_step
    if steps <= STIFF_STEPS:
        return None
    return (f"the coupling is stiff: its fastest mode has |lambda| = {abs(modes.fastest):.3g} 1/s (natural frequency "
            f"{modes.natural_frequency:.3g} rad/s, damping ratio {modes.damping_ratio:.3g}), so {method} needs steps "
            f"below about {largest_step:.2g} s for stability alone, some {steps:.2g} steps; an implicit method is "
            "not limited by it: set solver.method: Radau (or BDF; with steps longer than the vibration's period "
            "they damp it out, keeping the mean motion and the mean coupling moment)")


def rk4_amplification(z: complex) -> float:
    """|R(z)|, R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24: how much one classic RK4 step of y' = lambda y multiplies y
    by, z = h lambda (the step is stable for the mode while it is <= 1)."""
    return abs(1.0 + z * (1.0 + z * (0.5 + z * (1.0 / 6.0 + z / 24.0))))


def rk4_largest_stable_step(eigenvalue: complex) -> float:
    """The largest h [s] with |R(h lambda)| <= 1 for RK4 (bisection on the ray h lambda; about 2.785 / |lambda| on
    the negative real axis, 2 sqrt 2 / |lambda| on the imaginary axis)."""
    low, high = 0.0, 3.0 / abs(eigenvalue)  # RK4's region lies within |z| < 2.9 along every ray that leaves it
    if rk4_amplification(high * eigenvalue) <= 1.0:
        return high
    for _ in range(100):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if rk4_amplification(middle * eigenvalue) <= 1.0 else (low, middle)
    return low


def rk4_stability_refusal(model: MachineModel) -> str | None:
    """Why the scene's RK4 step cannot run its coupling (its fastest mode outside RK4's stability region: the
    vibration would grow every step and swamp the motion), or None (not RK4, no coupling, or a stable step)."""
    settings = model.scene.solver
    modes = coupling_modes(model)
    if settings.method != "RK4" or modes is None or rk4_amplification(settings.step * modes.fastest) <= 1.0:
        return None
    largest = rk4_largest_stable_step(modes.fastest)
    return (f"solver.step = {settings.step:g} s: RK4 is unstable on the coupling's fastest mode (|lambda| = "
            f"{abs(modes.fastest):.4g} 1/s, natural frequency {modes.natural_frequency:.4g} rad/s, damping ratio "
            f"{modes.damping_ratio:.3g}; one step multiplies it by {rk4_amplification(settings.step * modes.fastest):.3g}); "
            f"expected solver.step <= {largest:.3g} s, or an implicit method (solver.method: Radau or BDF, or "
            "Rosenbrock23 with solver.path: fast)")
