"""Class-II Assur groups (dyads) of a planar linkage: position in closed form, velocity and acceleration ratios.

A dyad is two links L1, L2 joined by an internal joint, each joined by one external joint to a link already
known (the frame, the crank or an earlier group). Its type reads external joint of L1, internal joint, external
joint of L2 (source 001): RRR, RRP, RPR, PRP, RPP (PRR and PPR are RRP and RPP read from the other end, and
are stored in that order). Link poses are (r, theta) with a point p of the link at `P = r + p e^{i theta}`.

Position, closed form per type (sigma = the group's branch, +1 or -1):
- RRR: C = B + l1 e^{i (arg(D - B) + sigma acos((l1^2 + f^2 - l2^2) / (2 l1 f)))}, f = |D - B|: the internal
  joint C lies left of the directed line B -> D for sigma = +1 (B, D: the external joints of L1, L2).
- RRP: L2's angle is fixed by its prismatic joint, so C runs on a known line C0 + s w (w: the guide's direction);
  with the circle |C - B| = l1, `s = -Re(m conj w) + sigma sqrt(Re(m conj w)^2 - |m|^2 + l1^2)`, m = C0 - B:
  sigma = +1 takes C further along the guide's direction.
- RPR: the guide link G (pivot Pg) and the slider link S (pivot Ps) turn together, theta_S = theta_G + alpha;
  the slider's point on the guide's line gives `sin(psi - theta_G - beta) = -h / rho` with rho e^{i psi} =
  Ps - Pg, beta the guide's direction in G and h the line's offset from the pivots (below); sigma = +1 takes the
  root with (Ps - Pg) pointing along the guide's direction.
- PRP: both angles fixed; C is the intersection of two known lines.
- RPP: both angles fixed and L1 pinned at B, so L1 is known; L2's origin is the intersection of two lines.

Velocity and acceleration ratios (derivatives with respect to the crank angle phi) come from the joints'
constraint equations C(x) = 0 differentiated once and twice along the motion, x = the links' (x, y, theta):
`A u' = -K k'` and `A u'' = -K k'' - gamma`, u the group's six unknown coordinates, k those of the known links,
A and K the partial derivatives of the six constraint equations, gamma their terms quadratic in the first
derivatives. This is exact (no finite differences): the ratios are those of source 004's differentiated loop.

These equations are written once, in flat.py (place_group, differentiate_group, joint_rows), which the reference
and the compiled fast path both run; this module holds the groups' description (Dyad, RedundantLink), the message
of a group that fails (failure_message) and the dict form of a joint's constraint rows (_rows).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from mech_regulator.mechanisms.linkage import flat_derivatives, flat_program
from mech_regulator.mechanisms.linkage.model import Joint, Linkage, LinkageError

if TYPE_CHECKING:  # structure.py gathers the groups of every kind
    from mech_regulator.mechanisms.linkage.structure import Group

# A link's pose and its derivatives with respect to phi: [r, theta, r', theta', r'', theta''] (r complex [m]).
Pose = list

SUPPORTED_TYPES = ("RRR", "RRP", "RPR", "PRP", "RPP")
PARALLELOGRAM_TOLERANCE = 1e-12  # relative difference of opposite sides still called equal (parallelogram_joint)


@dataclass(frozen=True)
class Dyad:
    """A class-II group: links (L1, L2), the internal joint between them, the external joints (of L1, of L2),
    its type (one of SUPPORTED_TYPES) and its branch (+1 or -1); `parallelogram`: for an RRR group whose outer
    joints B, D sit on links joined by a revolute joint P with P B C D a parallelogram (|B - P| = |C - D|, |D - P| =
    |C - B|) kept so through its change points by a redundant link, that joint P: the group then follows
    `C = D + (B - P)` (the parallelogram, smooth through the change points where the branches meet) instead of
    a branch (parallelogram_joint, structure._decompose)."""

    links: tuple[str, str]
    internal: Joint
    externals: tuple[Joint, Joint]
    kind: str
    branch: int
    parallelogram: Joint | None = None

    @property
    def name(self) -> str:
        """The group's name: its type and its internal joint, e.g. 'RRR group C'."""
        return f"{self.kind} group {self.internal.name}"

    @property
    def joints(self) -> tuple[Joint, Joint, Joint]:
        return (self.externals[0], self.internal, self.externals[1])


@dataclass(frozen=True)
class RedundantLink:
    """A link joined by two revolute joints to known links whose distance stays its own: it adds one redundant
    constraint (source 001's parallelogram); its pose follows from the two joints."""

    link: str
    joints: tuple[Joint, Joint]
    kind: str = "redundant link"

    @property
    def name(self) -> str:
        return f"redundant link {self.link}"

    @property
    def links(self) -> tuple[str]:
        return (self.link,)


def make_dyad(
    linkage: Linkage, links: tuple[str, str], internal: Joint, externals: tuple[Joint, Joint], branch: int
) -> Dyad:
    """The dyad of these links and joints in the stored order (PRR -> RRP, PPR -> RPP by swapping the ends);
    raises LinkageError for a PPP group (no position: its links can translate together) and for a link of an RRR
    group whose two joints are at one point (no direction)."""
    letters = externals[0].letter + internal.letter + externals[1].letter
    if letters in ("PRR", "PPR"):
        links, externals, letters = links[::-1], externals[::-1], letters[::-1]
    if letters not in SUPPORTED_TYPES:
        raise LinkageError(
            f"the group of links {list(links)} has joints {letters} "
            f"({', '.join(j.name for j in (externals[0], internal, externals[1]))}); "
            f"expected a class-II group of type {', '.join(SUPPORTED_TYPES)}"
        )
    for link, outer in zip(links, externals):
        points = linkage.link(link).points
        if letters == "RRR" and points[outer.name] == points[internal.name]:
            raise LinkageError(
                f"the link {link} of the RRR group {internal.name} has its joints {outer.name} and "
                f"{internal.name} at one point [{points[outer.name].real:g}, "
                f"{points[outer.name].imag:g}] m; expected two distinct points"
            )
    return Dyad(links, internal, externals, letters, branch)


def parallelogram_joint(linkage: Linkage, dyad: Dyad) -> Joint | None:
    """The revolute joint P between the links an RRR group hangs on that makes P B C D a parallelogram (Dyad), to
    a relative PARALLELOGRAM_TOLERANCE of its sides; None if there is none."""
    if dyad.kind != "RRR":
        return None
    (L1, L2), (E1, E2), internal = dyad.links, dyad.externals, dyad.internal
    K1, K2 = E1.other(L1), E2.other(L2)
    side1, side2 = (
        abs(linkage.link(link).points[internal.name] - linkage.link(link).points[outer.name])
        for link, outer in ((L1, E1), (L2, E2))
    )
    for joint in linkage.joints:
        if joint.kind == "revolute" and set(joint.links) == {K1, K2}:
            on_K1 = abs(linkage.link(K1).points[E1.name] - linkage.link(K1).points[joint.name])
            on_K2 = abs(linkage.link(K2).points[E2.name] - linkage.link(K2).points[joint.name])
            if (
                abs(on_K1 - side2) <= PARALLELOGRAM_TOLERANCE * side2
                and abs(on_K2 - side1) <= PARALLELOGRAM_TOLERANCE * side1
            ):
                return joint
    return None


def failure_message(group: Group, status: int, numbers: tuple[float, float, float], phi: float) -> str:
    """The message of a group that flat_poses.solve_poses could not solve at crank angle phi [rad] (its status and the
    numbers that explain it), naming the group, its links, the angle and why."""
    where = f"{group.name} (links {', '.join(group.links)})"
    at = f"at crank angle {math.degrees(phi):.3f} deg"
    first, second, third = numbers
    if status == flat_program.DEAD_POINT:
        return f"{where} is at a dead point {at}: its links are aligned and its velocity ratios infinite"
    if status == flat_program.GUIDES_PARALLEL:
        return f"{where} {at}: its two guides are parallel, so the group has no single position"
    assert isinstance(group, Dyad), f"{where}: status {status} is a dyad's (flat.place_group)"
    E1, E2 = group.externals
    if status == flat_program.RRR_APART:
        why = f"the distance {first:.6g} m between {E1.name} and {E2.name} is outside [{second:.6g}, {third:.6g}] m"
    elif status == flat_program.RRP_GUIDE_FAR:
        why = (
            f"the guide of {E2.name} passes {first:.6g} m from {E1.name}, farther than the link "
            f"{group.links[0]}'s {second:.6g} m"
        )
    else:
        why = f"the guide passes {first:.6g} m from its pivot but the pivots are {second:.6g} m apart"
    return f"{where} {at} cannot be assembled: {why}"


def packed(pose: Pose) -> list[float]:
    """A pose [r, theta, (r', theta', r'', theta'')] as flat.py's POSE_SIZE floats (missing derivatives: 0; then
    cos theta, sin theta)."""
    r, theta, dr, dtheta, ddr, ddtheta = list(pose) + [0j, 0.0, 0j, 0.0][: 6 - len(pose)]
    return [
        r.real,
        r.imag,
        theta,
        dr.real,
        dr.imag,
        dtheta,
        ddr.real,
        ddr.imag,
        ddtheta,
        math.cos(theta),
        math.sin(theta),
    ]


def _rows(linkage: Linkage, poses: dict[str, Pose], joint: Joint) -> list[dict[str, tuple[float, float, float]]]:
    """The partial derivatives of a joint's two constraint equations by each of its links' (x, y, theta)
    (flat_derivatives.joint_rows), as {link: (d/dx, d/dy, d/dtheta)} per equation."""
    a, b = joint.links
    # plain lists: flat_derivatives.joint_rows run as plain Python (a few µs)
    rows = flat_derivatives.joint_rows(
        flat_program.joint_record(linkage, joint, {a: 0, b: 1}), 0, packed(poses[a]) + packed(poses[b])
    )
    return [{a: tuple(rows[6 * r : 6 * r + 3]), b: tuple(rows[6 * r + 3 : 6 * r + 6])} for r in range(2)]
