"""Structural analysis of a planar linkage (source 001, chapter 1): degrees of freedom and Assur groups.

Degrees of freedom: `W = 3 n - (2 p5 + p4 - R_repeated - R_redundant) - W_passive`, n the moving links, p5 the
lower pairs (revolute, prismatic), p4 the higher pairs (cam contacts, gear meshes), found where they occur:
- a repeated constraint: three links joined in a triangle by three prismatic joints (their relative rotation is
  forbidden twice), one each;
- a redundant constraint: a link joined by two revolute joints to links whose motion is already fixed, the
  distance of its two joints staying its own over the whole turn (the parallelogram's extra link), one each; an
  RRR group that is a parallelogram with the links it hangs on (groups.parallelogram_joint) is tried as the
  parallelogram (C = D + B - P), and stays one when a redundant link hangs on it: the redundant link keeps it a
  parallelogram through its change points (source 001, docs/theory.md §5.6), so it is solved as one there;
- a passive freedom: a roller that touches cams and turns about its one revolute joint, one each.

Decomposition: the frame and the driving crank are known; repeatedly, two unknown links joined to each other by
a lower pair and each by exactly one lower pair to known links form a class-II group (a dyad, groups.Dyad), taken
in order from the crank outward; a follower on the frame touching a known cam (directly or by its roller) is a cam
follower group (cam.CamFollower: zero freedom with its pair and its roller's passive spin); a gear link on one
revolute pivot meshing with a known gear is a group of its own (gears.GearGroup, 3 - 2 - 1 = 0). What remains
undecomposed is reported (a group of class III or higher, or another with a higher pair: not supported).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass

from mech_regulator.mechanisms.linkage import gears
from mech_regulator.mechanisms.linkage.cam import CamFollower, next_cam_follower
from mech_regulator.mechanisms.linkage.groups import Dyad, RedundantLink, make_dyad, parallelogram_joint
from mech_regulator.mechanisms.linkage.kinematics import make_solver, motion
from mech_regulator.mechanisms.linkage.model import CAM, GEAR, PRISMATIC, REVOLUTE, Linkage, LinkageError

REDUNDANCY_SAMPLES = 72  # crank angles over a turn at which a redundant link's distance is checked
REDUNDANCY_TOLERANCE = 1e-9  # relative change of that distance still called constant [-]


Group = Dyad | RedundantLink | CamFollower | gears.GearGroup
"""A group of the decomposition: a class-II group (Dyad), a redundant link, a cam follower or a gear."""


@dataclass(frozen=True)
class Structure:
    """The structural analysis of a linkage: counts, the constraints and freedoms found (each a description), the
    groups from the crank outward and what could not be decomposed (None when everything was)."""

    moving_links: int
    lower_pairs: int
    higher_pairs: int
    repeated: tuple[str, ...]
    redundant: tuple[str, ...]
    passive: tuple[str, ...]
    groups: tuple[Group, ...]
    undecomposed: str | None

    @property
    def freedom(self) -> int:
        """W = 3 n - (2 p5 + p4 - R_repeated - R_redundant) - W_passive (source 001, eq. 1.5)."""
        constraints = 2 * self.lower_pairs + self.higher_pairs - len(self.repeated) - len(self.redundant)
        return 3 * self.moving_links - constraints - len(self.passive)

    def formula(self) -> str:
        """The count written out, e.g. 'W = 3*3 - (2*4 + 0 - 0 - 0) - 0 = 1'."""
        return (
            f"W = 3*{self.moving_links} - (2*{self.lower_pairs} + {self.higher_pairs} - {len(self.repeated)} - "
            f"{len(self.redundant)}) - {len(self.passive)} = {self.freedom}"
        )

    def refusal(self) -> str | None:
        """Why this linkage cannot be driven by its one crank and solved group by group; None when it can."""
        if self.freedom != 1:
            return f"the linkage has {self.formula()}; expected W = 1 (one driving crank): " + (
                "it moves with more freedoms than the crank fixes"
                if self.freedom > 1
                else "it is a structure (or over-constrained): it cannot move"
            )
        if self.undecomposed is not None:
            return self.undecomposed
        return None

    def report(self) -> list[str]:
        """The analysis as text lines (the `structure` command prints them)."""
        lines = [
            f"moving links n = {self.moving_links}, lower pairs p5 = {self.lower_pairs}, higher pairs p4 = "
            f"{self.higher_pairs}",
            self.formula(),
        ]
        for title, found in (
            ("repeated constraint", self.repeated),
            ("redundant constraint", self.redundant),
            ("passive freedom", self.passive),
        ):
            lines += [f"{title}: {item}" for item in found]
        for number, group in enumerate(self.groups, start=1):
            if isinstance(group, Dyad):
                joints = ", ".join(f"{j.name} ({j.kind})" for j in group.joints)
                branch = (
                    f"the parallelogram {group.parallelogram.name} {group.externals[0].name} "
                    f"{group.internal.name} {group.externals[1].name} through its change points"
                    if group.parallelogram is not None
                    else f"branch {group.branch:+d}"
                )
                lines.append(
                    f"group {number}: class II, type {group.kind}, links {group.links[0]} + {group.links[1]}, "
                    f"joints {joints}, {branch}"
                )
            elif isinstance(group, gears.GearGroup):
                lines.append(
                    f"group {number}: gear {group.link} about {group.pivot.name}, mesh {group.mesh.name} with "
                    f"{group.driver} on {group.carrier}: ratio {group.ratio:+.6g}, pitch radii "
                    f"{abs(group.pitch[0]):.6g} and {abs(group.pitch[1]):.6g} m, {group.rate:+.6g} turns per "
                    "crank turn"
                )
            else:
                lines.append(
                    f"group {number}: {group.name} (links {' + '.join(group.links)}, joints "
                    f"{', '.join(f'{j.name} ({j.kind})' for j in group.joints)})"
                )
        if self.undecomposed is not None:
            lines.append(f"not decomposed: {self.undecomposed}")
        return lines


def analyse(linkage: Linkage) -> Structure:
    """The structural analysis of a linkage (module docstring); raises LinkageError for an inconsistent one."""
    linkage.check()
    moving = linkage.moving_links()
    lower = sum(1 for joint in linkage.joints if joint.kind in (REVOLUTE, PRISMATIC))
    higher = sum(1 for joint in linkage.joints if joint.kind in (CAM, GEAR))
    groups: list[Group] = []
    redundant: list[str] = []
    undecomposed = None
    if linkage.crank is not None:
        undecomposed = _decompose(linkage, linkage.crank, groups, redundant)
    return Structure(
        len(moving), lower, higher, _repeated(linkage), tuple(redundant), _passive(linkage), tuple(groups), undecomposed
    )


def _repeated(linkage: Linkage) -> tuple[str, ...]:
    """Triangles of three links joined pairwise by prismatic joints: one repeated constraint each."""
    prismatic = {frozenset(joint.links): joint.name for joint in linkage.joints if joint.kind == PRISMATIC}
    order = {link.name: index for index, link in enumerate(linkage.links)}
    trios = set()
    for first, second in itertools.combinations(prismatic, 2):  # two prismatic joints sharing a link ...
        joined = first | second
        if len(joined) == 3 and frozenset(joined - (first & second)) in prismatic:  # ... closed by a third
            trios.add(tuple(sorted(joined, key=order.__getitem__)))
    found = []
    for trio in sorted(trios, key=lambda names: [order[name] for name in names]):
        pairs = [frozenset(pair) for pair in itertools.combinations(trio, 2)]
        found.append(
            f"links {', '.join(trio)} form a triangle of prismatic joints "
            f"{', '.join(prismatic[pair] for pair in pairs)}: their relative rotation is constrained twice"
        )
    return tuple(found)


def _passive(linkage: Linkage) -> tuple[str, ...]:
    """Rollers on their one revolute joint whose other joints are cam contacts: one passive freedom each."""
    found = []
    for link in linkage.links:
        joints = linkage.joints_of(link.name)
        revolute = [joint for joint in joints if joint.kind == REVOLUTE]
        if (
            link.roller_radius is not None
            and len(revolute) == 1
            and len(joints) > 1
            and all(joint.kind == CAM for joint in joints if joint is not revolute[0])
        ):
            found.append(f"the roller {link.name} spins about {revolute[0].name} without moving anything else")
    return tuple(found)


def _decompose(linkage: Linkage, crank: str, groups: list[Group], redundant: list[str]) -> str | None:
    """Fill `groups` from the crank (the linkage's, named `crank`) outward and `redundant` with the redundant links
    found; return a description of the links that remain undecomposed, or None."""
    known = {linkage.frame, crank}
    rates = {linkage.frame: 0.0, crank: 1.0}  # turns per crank turn of the links whose angle is phi's
    while True:
        remaining = [name for name in linkage.moving_links() if name not in known]
        if not remaining:
            _keep_held_parallelograms(groups)
            fractional = gears.hanging_on_fractional_gears(linkage, groups)
            if fractional:
                raise LinkageError(
                    "; ".join(fractional) + "; expected gears that turn a whole number of times per "
                    "crank turn wherever a mechanism hangs on them"
                )
            return None
        group = (
            _next_dyad(linkage, known, remaining)
            or next_cam_follower(linkage, known)
            or gears.next_gear(linkage, known, rates, make_solver(linkage, groups))
            or _next_redundant_link(linkage, known, remaining, groups)
        )
        if isinstance(group, gears.GearGroup):
            rates[group.link] = group.rate
        if isinstance(group, Dyad):  # tried as the parallelogram it may be (module docstring)
            group = dataclasses.replace(group, parallelogram=parallelogram_joint(linkage, group))
        if group is None:
            joints = [j for j in linkage.joints if any(link in remaining for link in j.links)]
            letters = "".join(sorted(j.letter for j in joints))
            lower = sum(1 for j in joints if j.kind in (REVOLUTE, PRISMATIC))
            return (
                f"the links {remaining} with their joints {[f'{j.name} ({j.kind})' for j in joints]} form no "
                f"class-II group (n = {len(remaining)}, p5 = {lower}, p4 = {len(joints) - lower}, joints "
                f"{letters}): a group of class III or higher, or one with a higher pair, which is not supported"
            )
        groups.append(group)
        if isinstance(group, RedundantLink):
            redundant.append(
                f"the link {group.link} joins {group.joints[0].name} and {group.joints[1].name}, whose "
                "distance the rest of the linkage already keeps"
            )
        known.update(group.links)


def _keep_held_parallelograms(groups: list[Group]) -> None:
    """Turn back into a branch every parallelogram group on which no redundant link hangs (nothing holds it through
    its change points: there it could fold, so the assembly check refuses it if its crank reaches them)."""
    held = {
        link for group in groups if isinstance(group, RedundantLink) for joint in group.joints for link in joint.links
    }
    for k, group in enumerate(groups):
        if isinstance(group, Dyad) and group.parallelogram is not None and not held & set(group.links):
            groups[k] = dataclasses.replace(group, parallelogram=None)


def _next_dyad(linkage: Linkage, known: set[str], remaining: list[str]) -> Dyad | None:
    """The first two unknown links joined by a lower pair, each joined by exactly one lower pair (and nothing
    else) to known links."""
    unknown = set(remaining)
    order = {name: index for index, name in enumerate(remaining)}
    pairs = sorted(
        {tuple(sorted(joint.links, key=order.__getitem__)) for joint in linkage.joints if set(joint.links) <= unknown},
        key=lambda pair: (order[pair[0]], order[pair[1]]),
    )
    for first, second in pairs:
        between = [j for j in linkage.joints_of(first) if j.other(first) == second]
        outside = [[j for j in linkage.joints_of(link) if j.other(link) in known] for link in (first, second)]
        if len(between) == 1 and all(len(joints) == 1 for joints in outside):
            joints = [between[0], outside[0][0], outside[1][0]]
            if any(joint.kind in (CAM, GEAR) for joint in joints):
                continue
            return make_dyad(
                linkage,
                (first, second),
                between[0],
                (outside[0][0], outside[1][0]),
                linkage.branches.get(between[0].name, 1),
            )
    return None


def _next_redundant_link(
    linkage: Linkage, known: set[str], remaining: list[str], groups: list[Group]
) -> RedundantLink | None:
    """An unknown link with exactly two revolute joints, both to known links, whose two points stay at the link's
    own distance over the turn (REDUNDANCY_SAMPLES crank angles, REDUNDANCY_TOLERANCE)."""
    lower_groups = [group for group in groups if not isinstance(group, CamFollower)]  # placed by flat.py
    solved = {linkage.frame, linkage.crank}.union(*(group.links for group in lower_groups))
    solve_at = make_solver(linkage, lower_groups)
    for name in remaining:
        joints = linkage.joints_of(name)
        if len(joints) != 2 or any(j.kind != REVOLUTE or j.other(name) not in solved for j in joints):
            continue
        points = linkage.link(name).points
        own = abs(points[joints[1].name] - points[joints[0].name])
        for k in range(REDUNDANCY_SAMPLES):
            poses = solve_at(2.0 * math.pi * k / REDUNDANCY_SAMPLES, False)
            ends = [motion(poses[j.other(name)], linkage.link(j.other(name)).points[j.name])[0] for j in joints]
            if abs(abs(ends[1] - ends[0]) - own) > REDUNDANCY_TOLERANCE * max(own, 1e-300):
                break
        else:
            return RedundantLink(name, (joints[0], joints[1]))
    return None


def checked(linkage: Linkage) -> Structure:
    """The structure of a linkage that must be driven by its crank and solved group by group; raises LinkageError
    naming what was found otherwise (W != 1, an undecomposed group)."""
    structure = analyse(linkage)
    refusal = structure.refusal()
    if refusal is not None:
        raise LinkageError(refusal)
    return structure
