"""Kinematics of a planar linkage group by group, and its reduction to the crank (docs/theory.md §5.3, §2.1).

At crank angle phi the crank's pose is theta = phi with its pivot point on the frame's; the groups are then
placed and differentiated from the crank outward. The equations are written once, in flat.py, and run compiled
(flat.compiled: the same functions the fast path compiles into a scene's right-hand side); this module is their
dict form. Every link's pose carries [r, theta, r', theta', r'', theta''] (derivatives with respect to phi), so
that a point p of a link moves as `P = r + q`, `P' = r' + i theta' q`, `P'' = r'' + (i theta'' - theta'^2) q`,
q = p e^{i theta}; at crank speed omega and acceleration epsilon its velocity is P' omega and its acceleration
P'' omega^2 + P' epsilon.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Protocol

import numpy as np

from mech_regulator.mechanisms.linkage import flat, flat_positions, flat_program
from mech_regulator.mechanisms.linkage.groups import Pose, failure_message, packed
from mech_regulator.mechanisms.linkage.model import Linkage, LinkageError

if TYPE_CHECKING:  # structure.py finds redundant links with this module's solver
    from mech_regulator.mechanisms.linkage.structure import Group, Structure

Motion = tuple[complex, complex, complex]  # (P [m], dP/dphi [m/rad], d2P/dphi2 [m/rad^2])
ASSEMBLY_SAMPLES = 720  # crank angles over a turn at which a linkage is checked to assemble (every 0.5 deg)


class PoseSolver(Protocol):
    """`solve_at(phi, derivatives=True) -> {link: pose}`: the poses of the links at crank angle phi [rad]
    (make_solver)."""

    def __call__(self, phi: float, derivatives: bool = True) -> dict[str, Pose]: ...


def make_solver(linkage: Linkage, groups: Sequence[Group]) -> PoseSolver:
    """Build `solve_at(phi, derivatives=True) -> {link: pose}` placing the crank and these groups (a structure's,
    or the ones found so far) at crank angle phi [rad] (flat_poses.solve_poses); raises LinkageError naming the group
    that cannot assemble, or is at a dead point, and the angle (groups.failure_message)."""
    program = flat_program.encode(linkage, groups, None)
    names = list(flat_program.link_indices(linkage))
    solve_poses = flat.compiled_announced("solve_poses")
    scratch = np.empty(flat_program.SCRATCH_SHAPE)

    def solve_at(phi: float, derivatives: bool = True) -> dict[str, Pose]:
        poses = np.empty(flat_program.POSE_SIZE * len(names))
        status, group, *numbers = solve_poses(phi, program, 0, poses, scratch, derivatives)
        if status != flat_program.SOLVED:
            raise LinkageError(failure_message(groups[group], status, tuple(numbers), phi))
        values = poses.tolist()
        return {
            name: [
                complex(values[k], values[k + 1]),
                values[k + 2],
                complex(values[k + 3], values[k + 4]),
                values[k + 5],
                complex(values[k + 6], values[k + 7]),
                values[k + 8],
            ]
            for name, k in zip(names, range(0, len(values), flat_program.POSE_SIZE))
        }

    return solve_at


def solve(linkage: Linkage, structure: Structure, phi: float, derivatives: bool = True) -> dict[str, Pose]:
    """The poses of every link at crank angle phi [rad] (with derivatives unless `derivatives` is False, then
    zero); raises LinkageError naming the group that cannot assemble, or is at a dead point, and the angle."""
    return make_solver(linkage, structure.groups)(phi, derivatives)


def motion(pose: Pose, point: complex) -> Motion:
    """(P, P', P'') of the point `point` (link coordinates [m]) of a link with this pose (flat_positions.motion)."""
    return flat_positions.motion(packed(pose), 0, point)


def make_reduced(
    linkage: Linkage, structure: Structure, gravity: tuple[float, float] | None
) -> Callable[[float], tuple[float, float, float, float, float]]:
    """Build `reduced(phi) -> (J_links, dJ_links/dphi, M_weight, q, q')` for this linkage by the general solver (the
    contract of mechanisms/__init__.py; flat_poses.reduced_from_poses gives the sums): the compiled flat_poses.reduced
    on the linkage's program; where it gives NaN (a group fails), the LinkageError of make_solver. A machine runs the
    code generated from the groups instead (symbolic.make_reduced, mechanisms.build_reduced); this is its independent
    check (each group differentiated through its constraint system, not by the chain rule)."""
    program = flat_program.encode(linkage, structure.groups, gravity)
    compiled = flat.compiled_announced("reduced")

    def reduced(phi: float) -> tuple[float, float, float, float, float]:
        values = compiled(phi, program, 0)
        if math.isnan(values[0]):
            make_solver(linkage, structure.groups)(phi)  # raises the group's LinkageError
        return values

    return reduced


def moving_points(linkage: Linkage) -> list[tuple[str, str]]:
    """(point, link) of the points whose motion is reported: the revolute joints off the frame (not a cam pair's
    contact, which is no link's point), the prismatic
    joints' slider points that no revolute joint of the slider already marks, then the points of interest."""
    found: dict[str, str] = {}
    for joint in sorted(linkage.joints, key=lambda j: j.kind != "revolute"):
        if joint.kind == "gear":  # a mesh has no point of its own (its gears' centres are pivots)
            continue
        link = joint.links[1]
        if (linkage.frame in joint.links and joint.kind == "revolute") or joint.kind == "cam":  # a contact: no point
            continue
        local = linkage.link(link).points[joint.name]
        if joint.kind == "prismatic" and any(
            on == link and linkage.link(link).points[name] == local for name, on in found.items()
        ):
            continue
        found.setdefault(joint.name, link)
    for point in linkage.points:
        found.setdefault(
            point, next(link.name for link in linkage.links if link.name != linkage.frame and point in link.points)
        )
    return list(found.items())


def make_point_motions(linkage: Linkage, structure: Structure) -> Callable[[float], dict[str, Motion]]:
    """`motions(phi) -> {point: (P, P', P'')}` of the moving_points (complex numbers x + i y)."""
    points = [(name, link, linkage.link(link).points[name]) for name, link in moving_points(linkage)]
    solve_at = make_solver(linkage, structure.groups)

    def motions(phi: float) -> dict[str, Motion]:
        poses = solve_at(phi)
        return {name: motion(poses[link], local) for name, link, local in points}

    return motions


def assembly_failures(linkage: Linkage, structure: Structure, samples: int = ASSEMBLY_SAMPLES) -> list[str]:
    """Where the linkage cannot be assembled or meets a dead point over a turn of the crank, checked at `samples`
    crank angles: one message per group naming the group, its spans [deg] and why it fails at the first angle;
    [] if none."""
    spans: dict[str, list[list[float]]] = {}
    first_reason: dict[str, str] = {}
    step = 360.0 / samples
    solve_at = make_solver(linkage, structure.groups)
    for k in range(samples):
        phi_deg = k * step
        try:
            solve_at(math.radians(phi_deg))
        except LinkageError as error:
            what, reason = str(error).split(" at crank angle ", 1)
            first_reason.setdefault(what, reason)
            group_spans = spans.setdefault(what, [])
            if group_spans and abs(group_spans[-1][1] - (phi_deg - step)) < 1e-9:
                group_spans[-1][1] = phi_deg
            else:
                group_spans.append([phi_deg, phi_deg])
    for group_spans in spans.values():  # a span through 0 deg is one: 342 to 378 deg, not 0 to 18 and 342 to 359.5
        if len(group_spans) > 1 and group_spans[0][0] == 0.0 and abs(group_spans[-1][1] - (360.0 - step)) < 1e-9:
            group_spans[-1][1] = group_spans.pop(0)[1] + 360.0
    return [
        f"{what} fails for crank angles {', '.join(f'{lo:g} to {hi:g} deg' for lo, hi in group_spans)} "
        f"(checked every {step:g} deg; at {first_reason[what]})"
        for what, group_spans in spans.items()
    ]
