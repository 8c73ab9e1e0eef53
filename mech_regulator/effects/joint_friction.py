"""Joint friction (docs/theory.md §6, source 001): friction moments in the revolute joints from the joint
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

Corners (docs/theory.md §6.5). F has a kink wherever a joint's relative rate k_j changes sign (|k_j|: the wrist pin's
rate, the rod's, at 90 and 270 deg; the guide's x' at the dead centres; a linkage's joints likewise) and where a
guide's normal force N changes sign (|N|: a crank–slider's guide, each prismatic joint of a linkage). The first are
fixed crank angles (`corner_angles`, periodic in one turn), the solvers restart on them as on a table's knots; the
second depends on the state (phi, omega and epsilon), a guard N = 0 of its own per guide. Between two corners the
solvers read F continued along its piece, s_j k_j for |k_j| and s_N N for each guide's |N| with the signs s held
(`acceleration`'s ratio_signs and normal_signs), so the right-hand side is smooth there.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from mech_regulator.mechanisms import build_kinetostatics
from mech_regulator.mechanisms.kinetostatics import Kinetostatics
from mech_regulator.scene import machine_keys

FIT_FACTOR = {"clearance": 1.0, "new": math.pi / 2.0, "run_in": 4.0 / math.pi}  # lambda_p [-]
NEWTON_TOLERANCE = 1e-14  # relative size of the last Newton step on epsilon [-]
NEWTON_ITERATIONS = 50  # more means the equation in epsilon has no root (self-locking)
LOCKING_SAMPLES = 720  # crank angles per turn at which build_model checks for self-locking
CORNER_SAMPLES = 720  # crank angles per turn at which a joint's relative rate is checked for a sign change
SAME_CORNER = 1e-9  # corner angles of several joints closer than this [rad] are one corner


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
        return 2.0 / 3.0 * f * axial_load * (outer**3 - inner**3) / (outer**2 - inner**2)
    return f * axial_load * (inner + outer) / 2.0


def friction_acceleration(
    omega,
    moment,
    inertia,
    collar,
    arms,
    ratios,
    constant,
    per_epsilon,
    with_joints,
    tolerance,
    iterations,
    ratio_signs,
    normal_signs,
):
    """epsilon [rad/s^2] solving J epsilon = M - sign(omega) F(epsilon), F = M_collar + sum_j rho_j |k_j| |R0_j +
    R1_j epsilon| (module docstring), by Newton's method from the friction at rest; at rest (omega = 0) 0 while
    |M| <= F(0), else breaking away in the direction of M; NaN without convergence. Both paths run this one function
    (JointFrictionModel.acceleration in Python; the fast path compiles it with numba as it stands: plain loops over
    sequences indexed by joint). moment M [N m], inertia J [kg m^2], collar M_collar [N m]; per joint: arms rho_j [m]
    (f_guide for a guide; 0 for a joint without friction, whose terms add exact zeros), ratios k_j [-], the
    reactions' constant R0_j and per_epsilon R1_j (complex Fx + i Fy [N], [N s^2]); with_joints False: the collar
    alone (no kinetostatics); tolerance: the relative size of the last step [-]; iterations: at most. Between two
    corners (docs/theory.md §6.5): ratio_signs s_j (0: |k_j|) read rho_j s_j k_j, normal_signs s_N (0: |R|) a guide's
    |N| (its reaction i N) as s_N N, per joint (0 for every joint but the guides)."""
    at_rest = 0.0
    if with_joints:
        for j in range(len(arms)):
            weight = arms[j] * (abs(ratios[j]) if ratio_signs[j] == 0.0 else ratio_signs[j] * ratios[j])
            at_rest += weight * (normal_signs[j] * constant[j].imag if normal_signs[j] != 0.0 else abs(constant[j]))
    at_rest = collar + at_rest
    if omega > 0.0:
        sign = 1.0
    elif omega < 0.0:
        sign = -1.0
    elif abs(moment) <= at_rest:
        return 0.0
    else:
        sign = 1.0 if moment > 0.0 else -1.0
    epsilon = (moment - sign * at_rest) / inertia
    if not with_joints:
        return epsilon
    for _ in range(iterations):
        friction, slope = collar, 0.0
        for j in range(len(arms)):
            weight = arms[j] * (abs(ratios[j]) if ratio_signs[j] == 0.0 else ratio_signs[j] * ratios[j])
            reaction = constant[j] + per_epsilon[j] * epsilon
            size = normal_signs[j] * reaction.imag if normal_signs[j] != 0.0 else abs(reaction)
            friction += weight * size
            if normal_signs[j] != 0.0:
                slope += weight * normal_signs[j] * per_epsilon[j].imag
            elif size > 0.0:
                slope += weight * (per_epsilon[j].real * reaction.real + per_epsilon[j].imag * reaction.imag) / size
        step = (inertia * epsilon - moment + sign * friction) / (inertia + sign * slope)
        epsilon -= step
        if abs(step) <= tolerance * (abs(epsilon) + (abs(moment) + friction) / inertia):
            return epsilon
    return math.nan


@dataclass(frozen=True)
class JointFrictionModel:
    """Joint friction assembled for the hot path.

    names: the joints with friction, in the kinetostatics' order ('guide' for the slider's guide);
    indices: their positions in the kinetostatics' joints; arms: friction-circle radius rho_j [m] of each
    journal, f_guide [-] for the guide; collar: the thrust collar's moment [N m] (0 without one);
    loads: the mechanism's kinetostatics, or None without a mechanism; formula: what it computes;
    guides: the positions in names of the guides with friction (a crank–slider's guide, a linkage's prismatic
    joints; the reaction i N in the guide's own frame, N the normal force [N]), whose |N| has a corner where N
    changes sign; corner_angles: the crank angles in [0, 2 pi) [rad] where the
    relative rate k_j of a joint with friction changes sign (a corner of |k_j|; the kinematics repeat every turn);
    corner_signs: the signs of the k_j (in names' order) from each corner angle to the next (the last to the first).
    """

    names: tuple[str, ...]
    indices: tuple[int, ...]
    arms: tuple[float, ...]
    collar: float
    loads: Kinetostatics | None
    formula: str
    guides: tuple[int, ...] = ()
    corner_angles: tuple[float, ...] = ()
    corner_signs: tuple[tuple[float, ...], ...] = ()

    def ratio_signs(self, phi: float) -> tuple[float, ...]:
        """The sign (+1 or -1) of each joint's relative rate k_j at crank angle phi [rad] that is not a corner angle
        (in names' order; corner_signs; the model must have corner angles): between two corner angles the solvers
        read rho_j s_j k_j for rho_j |k_j|."""
        return self.corner_signs[bisect.bisect_right(self.corner_angles, phi % (2.0 * math.pi)) - 1]

    def acceleration(
        self,
        phi: float,
        omega: float,
        force: float,
        inertia: float,
        moment: float,
        ratio_signs: tuple[float, ...] | None = None,
        normal_signs: tuple[float, ...] = (),
    ) -> float:
        """epsilon [rad/s^2] solving `J epsilon = M - sign(omega) F(epsilon)` (module docstring) at crank angle
        phi [rad], speed omega [rad/s], output-link force Q [N or N m], reduced inertia J [kg m^2] and every
        other moment M [N m]; at rest, 0 while |M| <= F(0). NaN if Newton's method does not converge.
        ratio_signs, normal_signs: F continued along its piece between two corners (module docstring: s_j k_j for
        |k_j|, one per joint in names' order; a guide's |R_j| read as s_N N = s_N Im R_j, one per guide in guides'
        order); None and (): F itself. Solved by friction_acceleration, the function the fast path compiles."""
        if self.loads is None:
            return friction_acceleration(
                omega, moment, inertia, self.collar, (), (), (), (), False, NEWTON_TOLERANCE, NEWTON_ITERATIONS, (), ()
            )
        normals = [0.0] * len(self.names)
        for k, position in enumerate(self.guides if normal_signs else ()):
            normals[position] = normal_signs[k]
        loads = self.loads(phi, omega, force)
        return friction_acceleration(
            omega,
            moment,
            inertia,
            self.collar,
            self.arms,
            [loads.ratios[i] for i in self.indices],
            [loads.constant[i] for i in self.indices],
            [loads.per_epsilon[i] for i in self.indices],
            True,
            NEWTON_TOLERANCE,
            NEWTON_ITERATIONS,
            ratio_signs or (0.0,) * len(self.names),
            normals,
        )

    def guide_normal(self, phi: float, omega: float, epsilon: float, force: float, guide: int = 0) -> float:
        """The normal force N [N] of guide number `guide` (in guides' order; signed, the guard of its corner) at crank
        angle phi [rad], speed omega [rad/s], acceleration epsilon [rad/s^2] and output force Q [N or N m]; the
        machine must have that guide with friction."""
        assert self.loads is not None, "guide_normal reads a mechanism's kinetostatics"
        loads = self.loads(phi, omega, force)
        index = self.indices[self.guides[guide]]
        return (loads.constant[index] + loads.per_epsilon[index] * epsilon).imag

    def joint_values(
        self, phi: float, omega: float, epsilon: float, force: float
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
        if self.loads is None:
            return 0.0
        loads = self.loads(phi, 0.0, 0.0)
        return (
            sum(arm * abs(loads.ratios[i]) * abs(loads.per_epsilon[i]) for i, arm in zip(self.indices, self.arms))
            / inertia
        )


def build_joint_friction(machine: machine_keys.Machine) -> JointFrictionModel:
    """The JointFrictionModel of a scene's `machine.joint_friction`."""
    spec = machine.joint_friction
    assert spec is not None, "build_joint_friction reads a machine with joint_friction"
    f = spec.coefficient
    collar = spec.thrust_collar
    collar_moment = (
        0.0
        if collar is None
        else thrust_collar_moment(f, collar.axial_load, collar.inner_radius, collar.outer_radius, collar.state)
    )
    parts = [f"thrust collar {collar_moment:.4g} N m ({collar.state})"] if collar is not None else []
    mechanism = machine.mechanism
    if mechanism is None or mechanism.type == "walking_beam" or getattr(mechanism, "cylinders", None) is not None:
        # no kinetostatics for these (scene.schema refuses their joints): the thrust collar alone
        return JointFrictionModel((), (), (), collar_moment, None, f"f = {f:g}: " + ", ".join(parts))
    gravity = (machine.gravity[0], machine.gravity[1]) if machine.gravity is not None else None
    loads, joints = build_kinetostatics(mechanism, gravity)
    if mechanism.type == "linkage":  # its journals by joint name; every prismatic joint slides with f_guide
        journals = dict(spec.journals)
        slides = {name for name, joint in mechanism.joints.items() if joint.type == "prismatic"}
    else:
        journals = {name: getattr(spec.joints, name) for name in type(spec.joints).model_fields}
        slides = {"guide"}
    names: list[str] = []
    indices: list[int] = []
    arms: list[float] = []
    guides: list[int] = []
    for index, joint in enumerate(joints):
        journal = journals.get(joint)
        if journal is not None:
            arm = friction_circle_radius(f, journal.radius, journal.fit)
            parts.append(f"{joint} rho = {arm * 1000:.4g} mm ({journal.fit})")
        elif joint in slides and spec.guide > 0.0:
            arm = spec.guide
            parts.append(f"{joint} f = {arm:g}")
            guides.append(len(names))
        else:
            continue
        names.append(joint)
        indices.append(index)
        arms.append(arm)
    corners = _corner_angles(loads, indices)
    middles = [0.5 * (a + b) for a, b in zip(corners, corners[1:] + (corners[0] + 2.0 * math.pi,))] if corners else []
    signs = tuple(tuple(1.0 if loads(phi, 0.0, 0.0).ratios[i] >= 0.0 else -1.0 for i in indices) for phi in middles)
    return JointFrictionModel(
        tuple(names),
        tuple(indices),
        tuple(arms),
        collar_moment,
        loads,
        f"f = {f:g}: " + ", ".join(parts),
        tuple(guides),
        corners,
        signs,
    )


def _corner_angles(loads: Kinetostatics, indices: list[int]) -> tuple[float, ...]:
    """The crank angles in [0, 2 pi) [rad] where the relative rate k_j(phi) of one of the joints at `indices` of
    the kinetostatics changes sign: sampled at CORNER_SAMPLES + 1 angles over a turn (a zero counting as
    positive), each change located by Brent's method (a root within 1e-12 rad of 0 or 2 pi taken as 0), and a root
    at 0 itself where round-off puts k(0) and k(2 pi) on both sides of it; roots of several joints within
    SAME_CORNER are one corner."""
    angles = np.linspace(0.0, 2.0 * math.pi, CORNER_SAMPLES + 1)
    corners = set()
    for index in indices:

        def rate(phi: float, index: int = index) -> float:
            return loads(phi, 0.0, 0.0).ratios[index]

        ahead = [rate(phi) >= 0.0 for phi in angles]
        for k in np.flatnonzero(np.array(ahead[:-1]) != np.array(ahead[1:])):
            root = optimize.brentq(rate, angles[k], angles[k + 1], xtol=1e-15, rtol=4.0 * np.finfo(float).eps)
            angle = root % (2.0 * math.pi)
            corners.add(0.0 if min(angle, 2.0 * math.pi - angle) < 1e-12 else angle)  # a root at the turn's ends: 0
        if ahead[0] != ahead[-1]:  # k(0) = k(2 pi) but for round-off, which put them on both sides of a root at 0
            corners.add(0.0)
    merged: list[float] = []
    for angle in sorted(corners):
        if not merged or angle - merged[-1] > SAME_CORNER:
            merged.append(angle)
    if len(merged) > 1 and merged[0] + 2.0 * math.pi - merged[-1] <= SAME_CORNER:
        merged.pop()  # the same corner on both sides of the turn's start
    return tuple(merged)


def worst_locking(friction: JointFrictionModel, inertia: Callable[[float], float]) -> tuple[float, float]:
    """(crank angle [rad], K / J) where the friction's slope in epsilon comes closest to the reduced inertia
    J(phi) [kg m^2] over LOCKING_SAMPLES angles of a turn."""
    angles = [2.0 * math.pi * i / LOCKING_SAMPLES for i in range(LOCKING_SAMPLES)]
    return max(((phi, friction.locking_ratio(phi, inertia(phi))) for phi in angles), key=lambda pair: pair[1])
