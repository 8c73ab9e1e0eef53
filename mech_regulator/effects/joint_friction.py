"""Joint friction (physics.md section 7, source 001): friction moments in the revolute joints from the joint
reactions of the kinetostatic analysis, sliding friction of the slider on its guide, and a thrust collar.

- Journal of radius r with reaction R: `M_f = lambda_p f' r |R|`, `f' = f / sqrt(1 + f^2)`, lambda_p = 1
  (clearance), pi/2 (new close fit), 4/pi (run-in); `rho = lambda_p f' r` is the friction-circle radius.
- Guide: friction force `f_guide |N|` against the slider's velocity (a linkage: in each of its prismatic joints,
  N its normal force, the sliding speed relative to the guide; the couple a slider's block carries is not read).
- Thrust collar (r1, r2, axial load Q): new `2/3 f Q (r2^3 - r1^3)/(r2^2 - r1^2)`, run-in `f Q (r1 + r2)/2`.

Each friction opposes the relative motion in its joint; reduced to the crank by power,
`M_joint_friction = -sign(omega) F`, `F = M_collar + sum_j rho_j |k_j| |R_j| + f_guide |x'| |N|` with
`k_j = omega_rel,j / omega` (for the guide, x' = dx/dphi). The reactions are affine in epsilon,
`R_j = R0_j + R1_j epsilon` (mechanisms.kinetostatics; a linkage's from its kinetostatics by groups,
mechanisms.linkage.make_joint_loads), so the equation of motion is implicit in epsilon:

    J epsilon = M - sign(omega) F(epsilon),   M = M_d + M_c - 1/2 J' omega^2 (every other moment).

`F` is convex in epsilon with slope at most `K = sum_j rho_j |k_j| |R1_j| (+ f_guide |x'| |N1|)`; while
K < J the left side minus the right is strictly increasing and Newton's method converges to its single
root from any start. K >= J is self-locking: friction would grow faster with the acceleration than the
inertia, and the equation can have no or several solutions; build_model refuses such a machine.

At rest (omega = 0) friction opposes the motion the other moments would start and cannot exceed them:
if |M| <= F(0) (the friction with the reactions of the state at rest), epsilon = 0 and the machine stays
at rest; otherwise it breaks away in the direction of M with the friction at its kinetic value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from mech_regulator.mechanisms import build_kinetostatics
from mech_regulator.mechanisms.kinetostatics import Kinetostatics
from mech_regulator.scene import schema

FIT_FACTOR = {"clearance": 1.0, "new": math.pi / 2.0, "run_in": 4.0 / math.pi}  # lambda_p [-]
NEWTON_TOLERANCE = 1e-14   # relative size of the last Newton step on epsilon [-]
NEWTON_ITERATIONS = 50     # more means the equation in epsilon has no root (self-locking)
LOCKING_SAMPLES = 720      # crank angles per turn at which build_model checks for self-locking


def reduced_friction_coefficient(f: float) -> float:
    """f' = f / sqrt(1 + f^2) [-] of a journal of coefficient f [-] (source 001)."""
    return f / math.sqrt(1.0 + f * f)


def friction_circle_radius(f: float, radius: float, fit: str) -> float:
    """rho = lambda_p f' r [m] for a journal of radius r [m] with the fit's pressure factor lambda_p: the
    friction moment is rho |R|."""
    return FIT_FACTOR[fit] * reduced_friction_coefficient(f) * radius


def thrust_collar_moment(f: float, axial_load: float, inner: float, outer: float, state: str) -> float:
    """Friction moment of an annular thrust collar [N m]: new (uniform pressure)
    `2/3 f Q (r2^3 - r1^3)/(r2^2 - r1^2)`, run-in (uniform wear) `f Q (r1 + r2)/2`; Q [N], radii [m]."""
    if state == "new":
        return 2.0 / 3.0 * f * axial_load * (outer ** 3 - inner ** 3) / (outer ** 2 - inner ** 2)
    return f * axial_load * (inner + outer) / 2.0


@dataclass(frozen=True)
class JointFrictionModel:
    """Joint friction assembled for the hot path.

    names: the joints with friction, in the kinetostatics' order ('guide' for the slider's guide);
    indices: their positions in the kinetostatics' joints; arms: friction-circle radius rho_j [m] of each
    journal, f_guide [-] for the guide; collar: the thrust collar's moment [N m] (0 without one);
    loads: the mechanism's kinetostatics, or None without a mechanism; formula: what it computes.
    """

    names: tuple[str, ...]
    indices: tuple[int, ...]
    arms: tuple[float, ...]
    collar: float
    loads: Kinetostatics | None
    formula: str

    def _terms(self, phi: float, omega: float, force: float) -> list[tuple[float, complex, complex]]:
        """(rho_j |k_j|, R0_j, R1_j) of every joint with friction at (phi, omega, output force)."""
        if self.loads is None:
            return []
        loads = self.loads(phi, omega, force)
        return [(arm * abs(loads.ratios[i]), loads.constant[i], loads.per_epsilon[i])
                for i, arm in zip(self.indices, self.arms)]

    def acceleration(self, phi: float, omega: float, force: float, inertia: float, moment: float) -> float:
        """epsilon [rad/s^2] solving `J epsilon = M - sign(omega) F(epsilon)` (module docstring) at crank angle
        phi [rad], speed omega [rad/s], output-link force Q [N or N m], reduced inertia J [kg m^2] and every
        other moment M [N m]; at rest, 0 while |M| <= F(0). NaN if Newton's method does not converge."""
        terms = self._terms(phi, omega, force)
        at_rest = self.collar + sum(weight * abs(r0) for weight, r0, _ in terms)
        if omega > 0.0:
            sign = 1.0
        elif omega < 0.0:
            sign = -1.0
        elif abs(moment) <= at_rest:
            return 0.0
        else:
            sign = 1.0 if moment > 0.0 else -1.0
        epsilon = (moment - sign * at_rest) / inertia
        if not terms:
            return epsilon
        for _ in range(NEWTON_ITERATIONS):
            friction, slope = self.collar, 0.0
            for weight, r0, r1 in terms:
                reaction = r0 + r1 * epsilon
                size = abs(reaction)
                friction += weight * size
                if size > 0.0:
                    slope += weight * (r1.real * reaction.real + r1.imag * reaction.imag) / size
            step = (inertia * epsilon - moment + sign * friction) / (inertia + sign * slope)
            epsilon -= step
            if abs(step) <= NEWTON_TOLERANCE * (abs(epsilon) + (abs(moment) + friction) / inertia):
                return epsilon
        return math.nan

    def joint_values(self, phi: float, omega: float, epsilon: float, force: float
                     ) -> tuple[list[float], list[float], float]:
        """At a state with crank acceleration epsilon [rad/s^2]: the friction in each joint of `names` (moment
        rho |R| [N m] of a journal, force f |N| [N] of the guide), the reaction magnitudes |R| [N], and the
        friction F reduced to the crank [N m] (module docstring; the sign is left to the caller)."""
        if self.loads is None:
            return [], [], self.collar
        loads = self.loads(phi, omega, force)
        reactions = [abs(loads.constant[i] + loads.per_epsilon[i] * epsilon) for i in self.indices]
        frictions = [arm * size for arm, size in zip(self.arms, reactions)]
        reduced = self.collar + sum(value * abs(loads.ratios[i]) for value, i in zip(frictions, self.indices))
        return frictions, reactions, reduced

    def locking_ratio(self, phi: float, inertia: float) -> float:
        """K / J at crank angle phi [rad] for reduced inertia J [kg m^2]: K = sum_j rho_j |k_j| |R1_j|, the
        largest slope of the friction with epsilon [kg m^2]; >= 1 is self-locking."""
        return sum(weight * abs(r1) for weight, _, r1 in self._terms(phi, 0.0, 0.0)) / inertia


def build_joint_friction(machine: schema.Machine) -> JointFrictionModel:
    """The JointFrictionModel of a scene's `machine.joint_friction`."""
    spec = machine.joint_friction
    f = spec.coefficient
    collar = spec.thrust_collar
    collar_moment = 0.0 if collar is None else thrust_collar_moment(f, collar.axial_load, collar.inner_radius,
                                                                   collar.outer_radius, collar.state)
    parts = [f"thrust collar {collar_moment:.4g} N m ({collar.state})"] if collar is not None else []
    mechanism = machine.mechanism
    if mechanism is None or mechanism.type == "walking_beam" or getattr(mechanism, "cylinders", None) is not None:
        # no kinetostatics for these (scene.schema refuses their joints): the thrust collar alone
        return JointFrictionModel((), (), (), collar_moment, None, f"f = {f:g}: " + ", ".join(parts))
    gravity = tuple(machine.gravity) if machine.gravity is not None else None
    loads, joints = build_kinetostatics(machine.mechanism, gravity)
    if mechanism.type == "linkage":  # its journals by joint name; every prismatic joint slides with f_guide
        journals = dict(spec.journals)
        slides = {name for name, joint in mechanism.joints.items() if joint.type == "prismatic"}
    else:
        journals = {name: getattr(spec.joints, name) for name in type(spec.joints).model_fields}
        slides = {"guide"}
    names, indices, arms = [], [], []
    for index, joint in enumerate(joints):
        journal = journals.get(joint)
        if journal is not None:
            arm = friction_circle_radius(f, journal.radius, journal.fit)
            parts.append(f"{joint} rho = {arm * 1000:.4g} mm ({journal.fit})")
        elif joint in slides and spec.guide > 0.0:
            arm = spec.guide
            parts.append(f"{joint} f = {arm:g}")
        else:
            continue
        names.append(joint)
        indices.append(index)
        arms.append(arm)
    return JointFrictionModel(tuple(names), tuple(indices), tuple(arms), collar_moment, loads,
                              f"f = {f:g}: " + ", ".join(parts))


def worst_locking(friction: JointFrictionModel, inertia: Callable[[float], float]) -> tuple[float, float]:
    """(crank angle [rad], K / J) where the friction's slope in epsilon comes closest to the reduced inertia
    J(phi) [kg m^2] over LOCKING_SAMPLES angles of a turn."""
    angles = [2.0 * math.pi * i / LOCKING_SAMPLES for i in range(LOCKING_SAMPLES)]
    return max(((phi, friction.locking_ratio(phi, inertia(phi))) for phi in angles), key=lambda pair: pair[1])
