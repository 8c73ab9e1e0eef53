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
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass

import numpy as np

from mech_regulator.mechanisms.linkage.model import REVOLUTE, Joint, Linkage, LinkageError

# A link's pose and its derivatives with respect to phi: [r, theta, r', theta', r'', theta''] (r complex [m]).
Pose = list

SUPPORTED_TYPES = ("RRR", "RRP", "RPR", "PRP", "RPP")
DEAD_POINT_CONDITION = 1e10   # condition of a group's equations beyond which its ratios count as infinite [-]


@dataclass(frozen=True)
class Dyad:
    """A class-II group: links (L1, L2), the internal joint between them, the external joints (of L1, of L2),
    its type (one of SUPPORTED_TYPES) and its branch (+1 or -1)."""

    links: tuple[str, str]
    internal: Joint
    externals: tuple[Joint, Joint]
    kind: str
    branch: int

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


def make_dyad(linkage: Linkage, links: tuple[str, str], internal: Joint, externals: tuple[Joint, Joint], branch: int
              ) -> Dyad:
    """The dyad of these links and joints in the stored order (PRR -> RRP, PPR -> RPP by swapping the ends);
    raises LinkageError for a PPP group (no position: its links can translate together) and for a link of an RRR
    group whose two joints are at one point (no direction)."""
    letters = externals[0].letter + internal.letter + externals[1].letter
    if letters in ("PRR", "PPR"):
        links, externals, letters = links[::-1], externals[::-1], letters[::-1]
    if letters not in SUPPORTED_TYPES:
        raise LinkageError(f"the group of links {list(links)} has joints {letters} "
                           f"({', '.join(j.name for j in (externals[0], internal, externals[1]))}); "
                           f"expected a class-II group of type {', '.join(SUPPORTED_TYPES)}")
    for link, outer in zip(links, externals):
        points = linkage.link(link).points
        if letters == "RRR" and points[outer.name] == points[internal.name]:
            raise LinkageError(f"the link {link} of the RRR group {internal.name} has its joints {outer.name} and "
                               f"{internal.name} at one point [{points[outer.name].real:g}, "
                               f"{points[outer.name].imag:g}] m; expected two distinct points")
    return Dyad(links, internal, externals, letters, branch)


def point_of(linkage: Linkage, poses: dict[str, Pose], link: str, point: str) -> complex:
    """Global position [m] of a link's point: r + p e^{i theta}."""
    r, theta = poses[link][0], poses[link][1]
    return r + linkage.link(link).points[point] * cmath.exp(1j * theta)


def _angle_across(joint: Joint, known: str, theta_known: float) -> float:
    """The angle [rad] of the link a prismatic joint joins to the link `known`: theta_slider = theta_guide + alpha."""
    return theta_known + joint.slider_angle if joint.links[0] == known else theta_known - joint.slider_angle


def _origin_line(linkage: Linkage, poses: dict[str, Pose], joint: Joint, unknown: str, theta_unknown: float
                 ) -> tuple[complex, complex]:
    """(c, w): the line c + s w (w unit) on which the origin r of `unknown` lies, that link having the angle
    theta_unknown and being joined by the prismatic `joint` to a known link.
    Slider unknown: its point must lie on the guide line G + t w -> r = G - p_s e^{i theta} + t w.
    Guide unknown: the slider's point S = r + (p_g + t u) e^{i theta} -> r = S - p_g e^{i theta} - t w."""
    guide, slider = joint.links
    u = cmath.exp(1j * joint.direction)
    if unknown == slider:
        w = u * cmath.exp(1j * poses[guide][1])
        return point_of(linkage, poses, guide, joint.name) - linkage.link(slider).points[joint.name] * cmath.exp(
            1j * theta_unknown), w
    w = u * cmath.exp(1j * theta_unknown)
    return point_of(linkage, poses, slider, joint.name) - linkage.link(guide).points[joint.name] * cmath.exp(
        1j * theta_unknown), w


def _lines_meet(c1: complex, w1: complex, c2: complex, w2: complex, where: str) -> complex:
    """Intersection of the lines c1 + s w1 and c2 + t w2: `s = Im((c2 - c1) conj w2) / Im(w1 conj w2)`."""
    cross = (w1 * w2.conjugate()).imag
    if abs(cross) < 1e-12:
        raise LinkageError(f"{where}: its two guides are parallel, so the group has no single position")
    return c1 + w1 * ((c2 - c1) * w2.conjugate()).imag / cross


def _pin(linkage: Linkage, poses: dict[str, Pose], link: str, point: str, at: complex, theta: float) -> None:
    """Set the pose of `link` with angle theta (taken in (-pi, pi]) and its point `point` at `at`:
    r = at - p e^{i theta}."""
    theta = math.remainder(theta, 2.0 * math.pi)
    poses[link] = [at - linkage.link(link).points[point] * cmath.exp(1j * theta), theta]


def _swing(linkage: Linkage, poses: dict[str, Pose], link: str, pivot: str, tip: str, P: complex, T: complex
           ) -> None:
    """Set the pose of `link` whose point `pivot` is at P and point `tip` at T (|T - P| its own distance)."""
    points = linkage.link(link).points
    theta = cmath.phase(T - P) - cmath.phase(points[tip] - points[pivot])
    _pin(linkage, poses, link, pivot, P, theta)


def place(linkage: Linkage, group: Dyad | RedundantLink, poses: dict[str, Pose], phi: float) -> None:
    """Add to `poses` the positions (r, theta) of the group's links, the links it joins being known (module
    docstring); raises LinkageError naming the group and the crank angle phi [rad] where it cannot assemble."""
    where = f"{group.name} (links {', '.join(group.links)}) at crank angle {math.degrees(phi):.3f} deg"
    if isinstance(group, RedundantLink):
        first, second = group.joints
        _swing(linkage, poses, group.link, first.name, second.name,
               point_of(linkage, poses, first.other(group.link), first.name),
               point_of(linkage, poses, second.other(group.link), second.name))
        return
    (L1, L2), (E1, E2), Ji, sigma = group.links, group.externals, group.internal, group.branch
    K1, K2 = E1.other(L1), E2.other(L2)
    p1, p2 = linkage.link(L1).points, linkage.link(L2).points
    kind = group.kind
    if kind in ("RRR", "RRP"):
        B = point_of(linkage, poses, K1, E1.name)
        l1 = abs(p1[Ji.name] - p1[E1.name])
        if kind == "RRR":
            D = point_of(linkage, poses, K2, E2.name)
            l2 = abs(p2[Ji.name] - p2[E2.name])
            v = D - B
            f = abs(v)
            cos_B = (l1 * l1 + f * f - l2 * l2) / (2.0 * l1 * f) if f > 0.0 else math.inf
            if not -1.0 <= cos_B <= 1.0:
                raise LinkageError(f"{where} cannot be assembled: the distance {f:.6g} m between {E1.name} and "
                                   f"{E2.name} is outside [{abs(l1 - l2):.6g}, {l1 + l2:.6g}] m")
            C = B + l1 * cmath.exp(1j * (cmath.phase(v) + sigma * math.acos(cos_B)))
            _swing(linkage, poses, L2, E2.name, Ji.name, D, C)
        else:
            theta2 = _angle_across(E2, K2, poses[K2][1])
            c, w = _origin_line(linkage, poses, E2, L2, theta2)
            m = c + p2[Ji.name] * cmath.exp(1j * theta2) - B
            along = (m * w.conjugate()).real
            discriminant = along * along - abs(m) ** 2 + l1 * l1
            if discriminant < 0.0:
                raise LinkageError(f"{where} cannot be assembled: the guide of {E2.name} passes "
                                   f"{math.sqrt(abs(m) ** 2 - along * along):.6g} m from {E1.name}, farther than "
                                   f"the link {L1}'s {l1:.6g} m")
            C = m + B + w * (-along + sigma * math.sqrt(discriminant))
            _pin(linkage, poses, L2, Ji.name, C, theta2)
        _swing(linkage, poses, L1, E1.name, Ji.name, B, C)
        return
    if kind == "RPR":
        guide, slider = Ji.links
        outer = {L1: E1, L2: E2}
        pivot_g, pivot_s = outer[guide].name, outer[slider].name
        Pg = point_of(linkage, poses, outer[guide].other(guide), pivot_g)
        Ps = point_of(linkage, poses, outer[slider].other(slider), pivot_s)
        pg, ps = linkage.link(guide).points, linkage.link(slider).points
        u = cmath.exp(1j * Ji.direction)
        # The line's offset from the pivots, in the guide's coordinates: h = Im((p_g[pivot] - p_g[J]
        # + (p_s[J] - p_s[pivot]) e^{i alpha}) conj u).
        h = ((pg[pivot_g] - pg[Ji.name] + (ps[Ji.name] - ps[pivot_s]) * cmath.exp(1j * Ji.slider_angle))
             * u.conjugate()).imag
        rho = abs(Ps - Pg)
        if rho < abs(h) or rho == 0.0:
            raise LinkageError(f"{where} cannot be assembled: the guide passes {abs(h):.6g} m from its pivot but the "
                               f"pivots are {rho:.6g} m apart")
        a = math.asin(-h / rho)
        theta_g = cmath.phase(Ps - Pg) - cmath.phase(u) - (a if sigma > 0 else math.pi - a)
        _pin(linkage, poses, guide, pivot_g, Pg, theta_g)
        _pin(linkage, poses, slider, pivot_s, Ps, theta_g + Ji.slider_angle)
        return
    theta2 = _angle_across(E2, K2, poses[K2][1])
    if kind == "PRP":
        theta1 = _angle_across(E1, K1, poses[K1][1])
        c1, w1 = _origin_line(linkage, poses, E1, L1, theta1)
        c2, w2 = _origin_line(linkage, poses, E2, L2, theta2)
        C = _lines_meet(c1 + p1[Ji.name] * cmath.exp(1j * theta1), w1, c2 + p2[Ji.name] * cmath.exp(1j * theta2), w2,
                        where)
        _pin(linkage, poses, L1, Ji.name, C, theta1)
        _pin(linkage, poses, L2, Ji.name, C, theta2)
        return
    # RPP: L1 pinned at B with the angle its prismatic internal joint gives it from L2's.
    theta1 = _angle_across(Ji, L2, theta2)
    _pin(linkage, poses, L1, E1.name, point_of(linkage, poses, K1, E1.name), theta1)
    c1, w1 = _origin_line(linkage, poses, Ji, L2, theta2)
    c2, w2 = _origin_line(linkage, poses, E2, L2, theta2)
    poses[L2] = [_lines_meet(c1, w1, c2, w2, where), theta2]


def _rows(linkage: Linkage, poses: dict[str, Pose], joint: Joint) -> list[dict[str, tuple[float, float, float]]]:
    """The partial derivatives of a joint's constraint equations by each of its links' (x, y, theta).
    Revolute, `r_a + q_a - r_b - q_b = 0` (q = p e^{i theta}): two rows, its real and imaginary parts.
    Prismatic (guide g, slider s): the line `Im(d conj w) = 0`, d = P_s - P_g, w = u e^{i theta_g}, and the angle
    `theta_s - theta_g - alpha = 0`."""
    a, b = joint.links
    qa = linkage.link(a).points[joint.name] * cmath.exp(1j * poses[a][1])
    qb = linkage.link(b).points[joint.name] * cmath.exp(1j * poses[b][1])
    if joint.kind == REVOLUTE:
        return [{a: (1.0, 0.0, -qa.imag), b: (-1.0, 0.0, qb.imag)},
                {a: (0.0, 1.0, qa.real), b: (0.0, -1.0, -qb.real)}]
    w = cmath.exp(1j * (joint.direction + poses[a][1]))
    d = poses[b][0] + qb - poses[a][0] - qa
    return [{a: (w.imag, -w.real, -((qa + d) * w.conjugate()).real), b: (-w.imag, w.real, (qb * w.conjugate()).real)},
            {a: (0.0, 0.0, -1.0), b: (0.0, 0.0, 1.0)}]


def _quadratic_terms(linkage: Linkage, poses: dict[str, Pose], joint: Joint) -> tuple[float, float]:
    """The terms of a joint's twice-differentiated constraints quadratic in the first derivatives (gamma).
    Revolute: `-theta_a'^2 q_a + theta_b'^2 q_b`. Prismatic line: `Im((theta_g'^2 q_g - theta_s'^2 q_s) conj w)
    - 2 theta_g' Re(d' conj w)`, d' = r_s' + i theta_s' q_s - r_g' - i theta_g' q_g (the term -theta_g'^2 Im(d conj w)
    vanishes on the line); the angle: 0."""
    a, b = joint.links
    ra, ta, dra, dta = poses[a][:4]
    rb, tb, drb, dtb = poses[b][:4]
    qa = linkage.link(a).points[joint.name] * cmath.exp(1j * ta)
    qb = linkage.link(b).points[joint.name] * cmath.exp(1j * tb)
    if joint.kind == REVOLUTE:
        gamma = -dta * dta * qa + dtb * dtb * qb
        return gamma.real, gamma.imag
    w = cmath.exp(1j * (joint.direction + ta))
    dd = drb + 1j * dtb * qb - dra - 1j * dta * qa
    line = ((dta * dta * qa - dtb * dtb * qb) * w.conjugate()).imag - 2.0 * dta * (dd * w.conjugate()).real
    return line, 0.0


def differentiate(linkage: Linkage, group: Dyad | RedundantLink, poses: dict[str, Pose], phi: float) -> None:
    """Extend the poses of the group's links with their first and second derivatives with respect to phi, from
    `A u' = -K k'` and `A u'' = -K k'' - gamma` (module docstring); the known links' poses must carry theirs.
    A redundant link's four equations are consistent and of rank three: solved by least squares (exactly).
    Raises LinkageError at a dead point of the group (A singular: the ratios are infinite; _inverse)."""
    unknown, joints = group.links, group.joints
    columns = {link: 3 * index for index, link in enumerate(unknown)}
    rows, known_first, known_second = [], [], []
    for joint in joints:
        for partials in _rows(linkage, poses, joint):
            row = [0.0] * (3 * len(unknown))
            first = second = 0.0
            for link, (px, py, pt) in partials.items():
                if link in columns:
                    column = columns[link]
                    row[column], row[column + 1], row[column + 2] = px, py, pt
                else:
                    r, _, dr, dt, ddr, ddt = poses[link]
                    first += px * dr.real + py * dr.imag + pt * dt
                    second += px * ddr.real + py * ddr.imag + pt * ddt
            rows.append(row)
            known_first.append(first)
            known_second.append(second)
    inverse = _inverse(np.array(rows), group, phi)
    velocity = inverse @ -np.array(known_first)
    for link, column in columns.items():
        poses[link][2:] = [complex(velocity[column], velocity[column + 1]), velocity[column + 2]]
    gamma = [term for joint in joints for term in _quadratic_terms(linkage, poses, joint)]
    acceleration = inverse @ (-np.array(known_second) - np.array(gamma))
    for link, column in columns.items():
        poses[link][4:] = [complex(acceleration[column], acceleration[column + 1]), acceleration[column + 2]]


def _inverse(A: np.ndarray, group, phi: float) -> np.ndarray:
    """The inverse of A (a redundant link's 4 x 3 A: its pseudo-inverse, exact on its consistent equations),
    refusing an A whose condition |A|_max |A^-1|_max exceeds DEAD_POINT_CONDITION (a dead point)."""
    inverse = np.linalg.pinv(A) if A.shape[0] != A.shape[1] else _checked_inverse(A)
    if inverse is None or np.abs(inverse).max() * np.abs(A).max() > DEAD_POINT_CONDITION:
        raise LinkageError(f"{group.name} (links {', '.join(group.links)}) is at a dead point at crank angle "
                           f"{math.degrees(phi):.3f} deg: its links are aligned and its velocity ratios infinite")
    return inverse


def _checked_inverse(A: np.ndarray) -> np.ndarray | None:
    """np.linalg.inv(A), or None for an exactly singular A."""
    try:
        return np.linalg.inv(A)
    except np.linalg.LinAlgError:
        return None
