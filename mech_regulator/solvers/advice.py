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
    driven_inertia = float(
        np.mean([coupling.driven.state(angle)[0] for angle in np.linspace(0.0, 2.0 * math.pi, 360, endpoint=False)])
    )
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
    return (
        f"the coupling is stiff: its fastest mode has |lambda| = {abs(modes.fastest):.3g} 1/s (natural frequency "
        f"{modes.natural_frequency:.3g} rad/s, damping ratio {modes.damping_ratio:.3g}), so {method} needs steps "
        f"below about {largest_step:.2g} s for stability alone, some {steps:.2g} steps; an implicit method is "
        "not limited by it: set solver.method: Radau (or BDF; with steps longer than the vibration's period "
        "they damp it out, keeping the mean motion and the mean coupling moment)"
    )


def speed_relaxation_rate(model: MachineModel) -> float:
    """-d epsilon / d omega of the crank alone at the initial state [1/s] (the rate its speed settles at when
    positive: J against d M / d omega), by a difference on the side of the initial speed away from 0 (a Coulomb
    moment's jump at rest is not a slope); 0 when it cannot be worked out."""
    y = np.array(model.initial_state(), dtype=float)
    omega = float(y[1])
    delta = 1e-3 * max(1.0, abs(omega)) * (1.0 if omega >= 0.0 else -1.0)

    def acceleration(speed: float) -> float:
        state = y.copy()
        state[1] = speed
        J, moment = model.crank_side(0.0, state)
        return moment / J

    try:
        with np.errstate(all="ignore"):
            rate = -(acceleration(omega + 2.0 * delta) - acceleration(omega + delta)) / delta
    except (ArithmeticError, ValueError):
        return 0.0
    return rate if math.isfinite(rate) else 0.0


def stiffness_refusal(model: MachineModel) -> str | None:
    """Why the scene's explicit adaptive method (RK45, RK23, DOP853) cannot run it within MAX_STEPS steps (limits.py):
    its fastest decaying mode — the coupling's, or the crank speed's own settling (J against d M / d omega; a
    machine.inertia of 1e-300 kg m^2 settles in 1e-298 s) — needs more steps than that for stability alone, however
    loose the tolerances. None otherwise (an implicit method is not limited by it; RK4 with an unstable step blows up
    within a few steps and is stopped there)."""
    from mech_regulator.scene.limits import MAX_STEPS

    method, duration = model.scene.solver.method, model.scene.scenario.duration
    if method not in ("RK45", "RK23", "DOP853"):
        return None
    expected = "expected solver.method: Radau or BDF (implicit, not limited by it)" + (
        ", or Rosenbrock23 with solver.path: fast" if model.scene.solver.path == "fast" else ""
    )
    rate = speed_relaxation_rate(model)
    steps = duration * rate / STABILITY_LIMIT
    if steps > MAX_STEPS:
        J = model.crank_side(0.0, np.array(model.initial_state(), dtype=float))[0]
        return (
            f"solver.method = {method}: the crank's speed settles in {1.0 / rate:.3g} s (J = {J:.3g} kg m^2 "
            f"against d M / d omega = {-rate * J:.3g} N m s/rad at the start), so over {duration:g} s an explicit method "
            f"needs some {steps:.2g} steps for stability alone, beyond the limit of {MAX_STEPS:g}; {expected}, "
            "or an inertia that fits the moments (machine.inertia)"
        )
    modes = coupling_modes(model)
    if modes is not None and duration * abs(modes.fastest) / STABILITY_LIMIT > MAX_STEPS:
        steps = duration * abs(modes.fastest) / STABILITY_LIMIT
        return (
            f"solver.method = {method}: the coupling's fastest mode has |lambda| = {abs(modes.fastest):.3g} 1/s "
            f"(machine.coupling stiffness {modes.stiffness:.3g} N m/rad on a reduced inertia of "
            f"{modes.reduced_inertia:.3g} kg m^2), so over {duration:g} s an explicit method needs some "
            f"{steps:.2g} steps for stability alone, beyond the limit of {MAX_STEPS:g}; {expected}"
        )
    fastest = fastest_mode(model, at_least=STABILITY_LIMIT * MAX_STEPS / duration)
    if fastest is not None and duration * abs(fastest[0]) / STABILITY_LIMIT > MAX_STEPS:
        steps = duration * abs(fastest[0]) / STABILITY_LIMIT
        name = fastest[1]
        keys = STATE_KEYS.get(name, "the scene's values")
        return (
            f"solver.method = {method}: the scene's fastest mode at the start has |lambda| = {abs(fastest[0]):.3g} "
            f"1/s, mostly in the state {name} ({keys}), so over {duration:g} s an explicit method needs some "
            f"{steps:.2g} steps for stability alone, beyond the limit of {MAX_STEPS:g}; {expected}"
        )
    return None


def energy_step_refusal(model: MachineModel) -> str | None:
    """Why the energy method's crank-angle step cannot cover the scene within MAX_STEPS steps (limits.py), or None:
    the angle it turns is estimated as the larger of omega_0 T and the smaller of 1/2 |epsilon_0| T^2 and
    omega_balance T, epsilon_0 the cycle-mean acceleration at the initial speed (MachineModel.cycle_averages: the
    J' omega^2 / 2 term and the weights average out) and omega_balance the speed at which the mean moments balance
    (a start from rest: limits.run_refusals, which sees only the scene, cannot tell)."""
    from mech_regulator.scene.limits import MAX_STEPS

    scene = model.scene
    if scene.solver.method != "energy":
        return None
    duration, omega = scene.scenario.duration, abs(scene.scenario.initial.omega)
    try:
        J_mean, drive, other = model.cycle_averages(omega, model.external_load(0.0))
        epsilon = abs(drive + other) / J_mean
        from mech_regulator.model.steady import balance_speed

        try:
            balance = balance_speed(model)
        except Exception:  # no speed at which the moments balance (SceneError), or they cannot be averaged
            balance = math.inf
        turned = max(omega * duration, min(0.5 * epsilon * duration * duration, balance * duration))
    except (ArithmeticError, ValueError, IndexError, TypeError):
        return None
    steps = turned / math.radians(scene.solver.phi_step_deg)
    if not steps > MAX_STEPS:
        return None
    return (
        f"solver.phi_step_deg = {scene.solver.phi_step_deg:g} deg would take about {steps:.2g} steps: over "
        f"{duration:g} s the crank turns some {turned:.3g} rad (from omega = {omega:g} rad/s, mean epsilon = "
        f"{epsilon:.3g} rad/s^2 at the start); expected at most {MAX_STEPS:g} steps: solver.phi_step_deg >= "
        f"{math.degrees(turned / MAX_STEPS):.3g} deg"
    )


# The keys that set how fast each state moves (for stiffness_refusal's message).
STATE_KEYS = {
    "phi": "machine.inertia, machine.loads",
    "omega": "machine.inertia, machine.drive, machine.loads",
    "arm_angle": "governor.ball_mass, governor.arm_length (Hartnell: ball_arm, sleeve_arm), governor.spring, "
    "governor.damping",
    "arm_rate": "governor.ball_mass, governor.sleeve_mass, governor.damping, governor.spring",
    "servo": "governor.servo.gain, governor.feedback",
    "feedback_shift": "governor.feedback.gain, governor.feedback.time_constant",
    "integral": "governor.gain, governor.integral_time",
    "twist": "machine.coupling",
    "omega_driven": "machine.coupling, machine.clutch, the driven part's loads",
}


NORM_MARGIN = 1e-9  # relative: covers the round-off of the computed eigenvalues and of the norm (fastest_mode)


def fastest_mode(model: MachineModel, at_least: float = 0.0) -> tuple[float, str] | None:
    """(|lambda| [1/s], the state it moves most) of the fastest non-growing eigenvalue of the right-hand side's
    Jacobian J at the initial state, in its initial mode (by differences on one side of each state, the crank angle in
    the direction of motion, so that a moment jumping exactly at the start is not taken for a slope); None when it
    cannot be worked out, or when no eigenvalue can exceed at_least [1/s].

    The eigenvalues are computed only when they could: every eigenvalue has |lambda| <= ||J||_inf = max_i sum_j
    |J_ij| (from J v = lambda v, |lambda| ||v||_inf = ||J v||_inf <= ||J||_inf ||v||_inf), and the computed ones are
    exact eigenvalues of J + E with ||E|| of order n eps ||J|| (LAPACK's backward stability), so they too stay below
    ||J||_inf (1 + NORM_MARGIN); when that is at most at_least, None is returned without them."""
    y0 = np.array(model.initial_state(), dtype=float)
    names = model.state_names()
    try:
        rhs = model.rhs(model.piece_at(0.0), None, model.initial_mode(y0), ideal=True)
        columns = []
        with np.errstate(all="ignore"):
            for index in range(y0.size):  # a few states: plain Python floats are quicker than numpy's calls here
                sign = -1.0 if index == 0 and y0[1] < 0.0 else 1.0
                delta = sign * 1e-7 * max(1.0, abs(y0[index]))
                near, far = y0.copy(), y0.copy()
                near[index] += delta
                far[index] += 2.0 * delta
                columns.append(
                    [
                        (float(high) - float(low)) / delta
                        for high, low in zip(rhs(0.0, far), rhs(0.0, near), strict=True)
                    ]
                )
            rows = [list(row) for row in zip(*columns)]  # the Jacobian's
            if not all(math.isfinite(value) for row in rows for value in row):
                return None
            if max(sum(abs(value) for value in row) for row in rows) * (1.0 + NORM_MARGIN) <= at_least:
                return None
            values, vectors = np.linalg.eig(np.array(rows))
    except (ArithmeticError, ValueError, IndexError, TypeError, np.linalg.LinAlgError):
        return None
    candidates = [index for index in range(values.size) if values[index].real <= 0.0]
    if not candidates:
        return None
    index = max(candidates, key=lambda i: abs(values[i]))
    return float(abs(values[index])), names[int(np.argmax(np.abs(vectors[:, index])))]


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
    if settings.method != "RK4":  # before the coupling's modes, which cost a coupled scene 0.1-1 ms
        return None
    modes = coupling_modes(model)
    if modes is None or rk4_amplification(settings.step * modes.fastest) <= 1.0:
        return None
    largest = rk4_largest_stable_step(modes.fastest)
    return (
        f"solver.step = {settings.step:g} s: RK4 is unstable on the coupling's fastest mode (|lambda| = "
        f"{abs(modes.fastest):.4g} 1/s, natural frequency {modes.natural_frequency:.4g} rad/s, damping ratio "
        f"{modes.damping_ratio:.3g}; one step multiplies it by {rk4_amplification(settings.step * modes.fastest):.3g}); "
        f"expected solver.step <= {largest:.3g} s, or an implicit method (solver.method: Radau or BDF, or "
        "Rosenbrock23 with solver.path: fast)"
    )
