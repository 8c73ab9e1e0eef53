"""Kinetostatics of a planar linkage by groups (source 001, chapter 3): the joint reactions from the farthest group
inward and the balancing moment on the crank.

Every class-II group is statically determinate (3 n = 2 p5: six equilibrium equations, six reaction unknowns).
With d'Alembert's inertia forces each link is in equilibrium; written for a link's coordinates (x, y of its origin r,
theta) its equations are

    m a_S = F,    I alpha + (S - r) x m a_S = M_r,

F the forces on it and M_r their moment about r (gravity m g at S, an output load, the joints' reactions). The
reactions of a joint are the multipliers lambda of its constraint equations (flat_derivatives.joint_rows): a joint
contributes `(dC/dx_link)^T lambda` to each of its links, so a group's links give `A^T lambda = (inertia - applied -
reactions of the groups farther out)`, A the matrix of its kinematics (flat_derivatives.group_matrix). A revolute
joint's lambda is the force on its first link from its second [N] (its second link gets -lambda); a prismatic joint's
are the normal force N on the slider along i w (w the guide's direction) [N] and the couple on the slider [N m] (the
guide gets the opposite). Solving the groups from the last one to the first, each passes its outer joints' reactions
inward; the crank's equilibrium then gives its bearing's reaction and the balancing moment M_b, which equals the reduced
form `J epsilon + 1/2 J' omega^2 - M_weight - Q q'` (J of kinematics.make_reduced, the crank included) — a
built-in check of both. The right-hand sides are linear in (omega^2, epsilon, g, Q), so two load cases share one
position solution and one inverse per group: (omega, epsilon = 0, Q, with gravity) and (0, 1, 0, without), the
reactions at epsilon = 0 and their rate with epsilon, whose sum weighted (1, epsilon) is any state's.

The equations are written once, in flat.py (`flat_kinetostatics.kinetostatics`, `flat_kinetostatics.joint_loads`), which
make_kinetostatics runs compiled; what joint friction reads (make_joint_loads) is the same solution written out per kind
of linkage as straight-line code (symbolic.joint_loads_source), run here compiled (symbolic.reference_function) as the
fast path runs it in a scene's right-hand side, with flat_kinetostatics.joint_loads its independent check (the tests).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from mech_regulator import cache
from mech_regulator.mechanisms.kinetostatics import JointLoads, Kinetostatics
from mech_regulator.mechanisms.linkage import flat, flat_kinetostatics, flat_program, symbolic
from mech_regulator.mechanisms.linkage.cam import CamFollower
from mech_regulator.mechanisms.linkage.groups import RedundantLink
from mech_regulator.mechanisms.linkage.kinematics import make_solver
from mech_regulator.mechanisms.linkage.model import PRISMATIC, Linkage, LinkageError
from mech_regulator.mechanisms.linkage.structure import Structure


class LinkageLoads(NamedTuple):
    """Joint reactions by joint name: revolute, the force on its first link from its second, Fx + i Fy [N];
    prismatic, (N [N] along i w on the slider, couple on the slider [N m]); and the balancing moment M_b on the
    crank [N m]."""

    reactions: dict[str, complex | tuple[float, float]]
    balancing: float


def indeterminate(structure: Structure) -> str | None:
    """Why the linkage's joint reactions cannot be computed, or None: a redundant link makes it statically
    indeterminate (its reactions do not follow from equilibrium alone); a cam pair's contact is not among the
    groups' reactions yet (linkage/cam.py gives its contact force)."""
    cams = [group.pair.name for group in structure.groups if isinstance(group, CamFollower)]
    if cams:
        return (
            f"the cam pair {cams[0]}'s contact is not in the kinetostatics by groups yet (its contact force is the "
            "cam's own: `structure` prints the speed at which the follower jumps)"
        )
    if not any(isinstance(group, RedundantLink) for group in structure.groups):
        return None
    return (
        f"a redundant constraint ({'; '.join(structure.redundant)}) makes the linkage statically indeterminate: "
        "its joint reactions do not follow from equilibrium alone"
    )


def _program(linkage: Linkage, structure: Structure, gravity: tuple[float, float] | None) -> np.ndarray:
    """The linkage's flat program (flat_program.encode); a redundant link is refused (indeterminate)."""
    reason = indeterminate(structure)
    if reason is not None:
        raise LinkageError(reason)
    return flat_program.encode(linkage, structure.groups, gravity)


def make_kinetostatics(
    linkage: Linkage, structure: Structure, gravity: tuple[float, float] | None
) -> Callable[[float, float, float, float], LinkageLoads]:
    """Build `loads(phi, omega, epsilon, Q) -> LinkageLoads` (module docstring; the compiled
    flat_kinetostatics.kinetostatics), Q the generalised force on the output (a force along the output joint's guide on
    its slider [N], or a moment on the output link [N m]); raises the LinkageError of the group that fails at phi."""
    program = _program(linkage, structure, gravity)
    kinetostatics = flat.compiled_announced("kinetostatics")
    n_poses, n_residual, n_multipliers = flat_kinetostatics.workspace_sizes(program, 0)
    poses, scratch = np.empty(n_poses), np.empty(flat_program.SCRATCH_SHAPE)
    residual, multipliers = np.empty((n_residual, 2)), np.empty((n_multipliers, 2))
    slots = {
        joint.name: int(program[flat_kinetostatics.joint_map(program, 0) + 1 + flat_program.JOINT_SIZE + 2 * k + 1])
        for k, joint in enumerate(linkage.joints)
    }

    def loads(phi: float, omega: float, epsilon: float, output_force: float = 0.0) -> LinkageLoads:
        solved, constant, per_epsilon = kinetostatics(
            phi, omega, output_force, program, 0, poses, scratch, residual, multipliers
        )
        if not solved:
            make_solver(linkage, structure.groups)(phi)  # raises the group's LinkageError
        first, second = multipliers[0::2] @ (1.0, epsilon), multipliers[1::2] @ (1.0, epsilon)
        reactions = {}
        for joint in linkage.joints:
            slot = slots[joint.name]
            reactions[joint.name] = (
                (float(first[slot]), float(second[slot]))
                if joint.kind == PRISMATIC
                else complex(first[slot], second[slot])
            )
        return LinkageLoads(reactions, float(constant + per_epsilon * epsilon))

    return loads


def make_joint_loads(
    linkage: Linkage, structure: Structure, gravity: tuple[float, float] | None
) -> tuple[Kinetostatics, tuple[str, ...]]:
    """The linkage's kinetostatics in the form joint friction reads (mechanisms.kinetostatics.JointLoads) and its
    joint names (the linkage's order): `loads(phi, omega, Q)` gives every joint's reaction
    affine in epsilon, `R = R0 + R1 epsilon`: a revolute joint's, the force on its first link from its second, Fx + i
    Fy [N]; a prismatic joint's, the normal force on the slider in the guide's own frame, i N [N] (as a
    crank–slider's guide: N along i w, w the guide's direction; its couple, which joint friction does not read, is
    left out), so |R| = |N| and Im R = N, whose sign changes joint friction locates; the balancing moment (M_b0
    [N m], M_b1 [kg m^2]); and the ratios: a revolute joint's relative angular speed theta_a' - theta_b' [-], a
    prismatic joint's sliding speed over omega, `Re((P_s' - r_g' - i theta_g' (P_s - r_g)) conj w)` [m/rad]. It runs
    the code generated from the linkage's groups (symbolic.joint_loads_source: flat_kinetostatics.joint_loads written
    out per kind of linkage) compiled (symbolic.reference_function), the very source the fast path compiles; within
    cache.run_uncompiled, the general solver's plain flat_kinetostatics.joint_loads (the same numbers). Raises the
    LinkageError of the group that fails at phi."""
    program = _program(linkage, structure, gravity)
    if cache.uncompiled():
        joint_loads = flat_kinetostatics.joint_loads
    else:
        joint_loads = symbolic.reference_function(symbolic.joint_loads_source(program)[0])

    def loads(phi: float, omega: float, output_force: float) -> JointLoads:
        constant, per_epsilon, ratios, balancing, balancing_rate = joint_loads(phi, omega, output_force, program, 0)
        if not math.isfinite(balancing):  # a square root of a negative number or a division by zero
            make_solver(linkage, structure.groups)(phi)  # raises the group's LinkageError
            raise LinkageError(
                f"the linkage's joint reactions are not finite at crank angle {math.degrees(phi):.3f} deg"
            )
        return JointLoads(constant, per_epsilon, (balancing, balancing_rate), ratios)

    return loads, tuple(joint.name for joint in linkage.joints)
