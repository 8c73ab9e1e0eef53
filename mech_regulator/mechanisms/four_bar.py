"""Four-bar linkage by complex algebra (physics.md section 6, source 004).

Loop closure `a e^{i th2} + b e^{i th3} = d e^{i th1} + c e^{i th4}` with the crank angle th2 = phi,
crank pivot A at the origin and rocker pivot D = d e^{i th1}. The position is solved in closed form
from the triangle B C D (B = a e^{i phi}); the branch is a fixed sign, so it can never flip while the
linkage stays assemblable. Derivatives are taken with respect to phi (kinematic transfer functions).
"""

from __future__ import annotations

import cmath
import math
from typing import Callable, NamedTuple


class FourBarGeometry(NamedTuple):
    """Lengths [m], frame angle [rad], branch sign, masses [kg], inertias [kg m^2] (scene.schema.FourBar)."""

    crank: float
    coupler: float
    rocker: float
    frame: float
    frame_angle: float
    branch_sign: float  # -1: open (C right of D->B), +1: crossed
    crank_mass: float
    crank_cg: float
    coupler_mass: float
    coupler_cg: float
    coupler_inertia: float
    rocker_mass: float
    rocker_cg: float
    rocker_inertia: float


BRANCH_SIGN = {"open": -1.0, "crossed": 1.0}


def link_angles(phi: float, a: float, b: float, c: float, d: float, th1: float, branch_sign: float
                ) -> tuple[float, ...]:
    """Coupler and rocker angles with their first two derivatives with respect to phi.

    Position: with p = B - D, f = |p|, the rocker angle is `th4 = arg p + sign * acos((c^2 + f^2 - b^2) / (2 c f))`,
    arg p taken continuous around the direction D->A.
    Velocity ratios (source 004): `th3' = a sin(th4 - th2) / (b sin(th3 - th4))`,
    `th4' = a sin(th2 - th3) / (c sin(th4 - th3))`. Second derivatives from the twice-differentiated loop
    `i b th3'' e^{i th3} - i c th4'' e^{i th4} = a e^{i th2} + b th3'^2 e^{i th3} - c th4'^2 e^{i th4} =: r`:
    `th3'' = -Re(r e^{-i th4}) / (b sin(th3 - th4))`, `th4'' = Re(r e^{-i th3}) / (c sin(th4 - th3))`.
    Returns (th3, th3', th3'', th4, th4', th4''); raises ValueError where the loop cannot close.
    """
    B = a * cmath.exp(1j * phi)
    D = d * cmath.exp(1j * th1)
    p = B - D
    f = abs(p)
    cos_gamma = (c * c + f * f - b * b) / (2.0 * c * f) if f > 0.0 else math.inf  # B on D: no triangle
    if not -1.0 <= cos_gamma <= 1.0:
        raise ValueError(f"four-bar cannot be assembled at crank angle {math.degrees(phi):.3f} deg")
    # arg p measured from the direction D->A, where it stays within (-pi/2, pi/2) while the crank is
    # shorter than the frame: th4 is then continuous (no 2 pi jump when the rocker points along -x).
    towards_A = th1 + math.pi
    th4 = towards_A + cmath.phase(p * cmath.exp(-1j * towards_A)) + branch_sign * math.acos(cos_gamma)
    C = D + c * cmath.exp(1j * th4)
    th3 = cmath.phase(C - B)
    sin34 = math.sin(th3 - th4)
    dth3 = a * math.sin(th4 - phi) / (b * sin34)
    dth4 = a * math.sin(phi - th3) / (-c * sin34)
    e3, e4 = cmath.exp(1j * th3), cmath.exp(1j * th4)
    r = B + b * dth3 * dth3 * e3 - c * dth4 * dth4 * e4
    ddth3 = -(r / e4).real / (b * sin34)
    ddth4 = (r / e3).real / (-c * sin34)
    return th3, dth3, ddth3, th4, dth4, ddth4


def make_centre_motions(geometry: FourBarGeometry) -> Callable[[float], tuple[tuple[float, ...], tuple[complex, ...]]]:
    """Build `motions(phi) -> ((th3, th3', th3'', th4, th4', th4''), (e^{i phi}, e^{i th3}, e^{i th4}, S3', S3'',
    S4', S4''))`: the link angles of `link_angles` and the derivatives with respect to phi of the centres of mass
    `S3 = B + u3 e^{i th3}` (coupler) and `S4 = D + u4 e^{i th4}` (rocker) [m/rad, m/rad^2]:
    `S3' = i a e^{i phi} + i u3 th3' e^{i th3}`, `S3'' = -a e^{i phi} + u3 (i th3'' - th3'^2) e^{i th3}`,
    `S4' = i u4 th4' e^{i th4}`, `S4'' = u4 (i th4'' - th4'^2) e^{i th4}`."""
    g = geometry
    a, b, c, d, th1, sign = g.crank, g.coupler, g.rocker, g.frame, g.frame_angle, g.branch_sign
    u3, u4 = g.coupler_cg, g.rocker_cg

    def motions(phi: float) -> tuple[tuple[float, ...], tuple[complex, ...]]:
        angles = link_angles(phi, a, b, c, d, th1, sign)
        th3, dth3, ddth3, th4, dth4, ddth4 = angles
        e2, e3, e4 = cmath.exp(1j * phi), cmath.exp(1j * th3), cmath.exp(1j * th4)
        return angles, (e2, e3, e4, 1j * (a * e2 + u3 * dth3 * e3), -a * e2 + u3 * complex(-dth3 * dth3, ddth3) * e3,
                        1j * u4 * dth4 * e4, u4 * complex(-dth4 * dth4, ddth4) * e4)

    return motions


def make_reduced(geometry: FourBarGeometry, gravity: tuple[float, float] | None
                 ) -> Callable[[float], tuple[float, float, float, float, float]]:
    """Build `reduced(phi) -> (J_links, dJ_links/dphi, M_weight, th4, th4')` for this four-bar.

    With the centres' derivatives S3', S3'', S4', S4'' of `make_centre_motions`:
    `J_links = m3 |S3'|^2 + J3 th3'^2 + m4 |S4'|^2 + J4 th4'^2`, `dJ = 2 sum (m Re(conj(S') S'') + J th' th'')`,
    `M_weight = g . sum_k m_k S_k'` (physics.md section 1). The output coordinate is the rocker angle.
    """
    g = geometry
    m3, J3, m4, J4 = g.coupler_mass, g.coupler_inertia, g.rocker_mass, g.rocker_inertia
    m2r = g.crank_mass * g.crank_cg
    gravity_c = complex(*gravity) if gravity is not None else 0j
    with_weight = gravity_c != 0j
    motions = make_centre_motions(geometry)

    def reduced(phi: float) -> tuple[float, float, float, float, float]:
        (_, dth3, ddth3, th4, dth4, ddth4), (e2, _, _, dS3, ddS3, dS4, ddS4) = motions(phi)
        J = m3 * abs(dS3) ** 2 + J3 * dth3 * dth3 + m4 * abs(dS4) ** 2 + J4 * dth4 * dth4
        dJ = 2.0 * (m3 * (dS3.conjugate() * ddS3).real + J3 * dth3 * ddth3
                    + m4 * (dS4.conjugate() * ddS4).real + J4 * dth4 * ddth4)
        weight = 0.0
        if with_weight:
            weight = (gravity_c.conjugate() * (m2r * 1j * e2 + m3 * dS3 + m4 * dS4)).real
        return J, dJ, weight, th4, dth4

    return reduced


def unassemblable_crank_ranges(a: float, b: float, c: float, d: float, th1: float) -> list[tuple[float, float]]:
    """Crank-angle intervals [rad] (closed, toggles included) where the loop cannot close.

    With psi = phi - th1, `|B - D|^2 = a^2 + d^2 - 2 a d cos psi` must lie strictly inside
    `((b - c)^2, (b + c)^2)`; on the boundary the coupler and rocker are aligned and the velocity
    ratios are infinite. Returns an empty list for a crank that turns fully.
    """
    ranges = []
    cos_far = (a * a + d * d - (b + c) ** 2) / (2.0 * a * d)   # |B - D| >= b + c  <=>  cos psi <= cos_far
    cos_near = (a * a + d * d - (b - c) ** 2) / (2.0 * a * d)  # |B - D| <= |b - c|  <=>  cos psi >= cos_near
    if cos_far >= 1.0 or cos_near <= -1.0:
        return [(th1 - math.pi, th1 + math.pi)]
    if cos_far >= -1.0:
        half = math.acos(cos_far)
        ranges.append((th1 + half, th1 + 2.0 * math.pi - half))
    if cos_near <= 1.0:
        half = math.acos(cos_near)
        ranges.append((th1 - half, th1 + half))
    return ranges
