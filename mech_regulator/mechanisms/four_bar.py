"""Four-bar linkage by complex algebra (docs/theory.md §5.4, source 004).

Loop closure `a e^{i th2} + b e^{i th3} = d e^{i th1} + c e^{i th4}` with the crank angle th2 = phi,
crank pivot A at the origin and rocker pivot D = d e^{i th1}. The position is solved in closed form
from the triangle B C D (B = a e^{i phi}); the branch is a fixed sign, so it can never flip while the
linkage stays assemblable. Derivatives are taken with respect to phi (kinematic transfer functions).
"""

from __future__ import annotations

import cmath
import math
from typing import NamedTuple


class FourBarGeometry(NamedTuple):
    """Lengths [m], frame angle [rad], branch sign, masses [kg], inertias [kg m^2] (scene.mechanism_keys.FourBar)."""

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


def rocker_angle(phi: float, a: float, b: float, c: float, d: float, th1: float, branch_sign: float) -> float:
    """The rocker angle th4 [rad] at crank angle phi: with p = B - D, f = |p|, `th4 = arg p + sign * acos((c^2 + f^2 -
    b^2) / (2 c f))`, arg p taken continuous around the direction D->A (link_angles); raises ValueError where the loop
    cannot close."""
    B = a * cmath.exp(1j * phi)
    p = B - d * cmath.exp(1j * th1)
    f = abs(p)
    cos_gamma = (c * c + f * f - b * b) / (2.0 * c * f) if f > 0.0 else math.inf  # B on D: no triangle
    if not -1.0 <= cos_gamma <= 1.0:
        raise ValueError(f"four-bar cannot be assembled at crank angle {math.degrees(phi):.3f} deg")
    # arg p measured from the direction D->A, where it stays within (-pi/2, pi/2) while the crank is
    # shorter than the frame: th4 is then continuous (no 2 pi jump when the rocker points along -x).
    towards_A = th1 + math.pi
    return towards_A + cmath.phase(p * cmath.exp(-1j * towards_A)) + branch_sign * math.acos(cos_gamma)


def link_angles(
    phi: float, a: float, b: float, c: float, d: float, th1: float, branch_sign: float
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
    th4 = rocker_angle(phi, a, b, c, d, th1, branch_sign)
    C = d * cmath.exp(1j * th1) + c * cmath.exp(1j * th4)
    th3 = cmath.phase(C - B)
    sin34 = math.sin(th3 - th4)
    dth3 = a * math.sin(th4 - phi) / (b * sin34)
    dth4 = a * math.sin(phi - th3) / (-c * sin34)
    e3, e4 = cmath.exp(1j * th3), cmath.exp(1j * th4)
    r = B + b * dth3 * dth3 * e3 - c * dth4 * dth4 * e4
    ddth3 = -(r / e4).real / (b * sin34)
    ddth4 = (r / e3).real / (-c * sin34)
    return th3, dth3, ddth3, th4, dth4, ddth4


def unassemblable_crank_ranges(a: float, b: float, c: float, d: float, th1: float) -> list[tuple[float, float]]:
    """Crank-angle intervals [rad] (closed, toggles included) where the loop cannot close.

    With psi = phi - th1, `|B - D|^2 = a^2 + d^2 - 2 a d cos psi` must lie strictly inside
    `((b - c)^2, (b + c)^2)`; on the boundary the coupler and rocker are aligned and the velocity
    ratios are infinite. Returns an empty list for a crank that turns fully.
    """
    ranges = []
    cos_far = (a * a + d * d - (b + c) ** 2) / (2.0 * a * d)  # |B - D| >= b + c  <=>  cos psi <= cos_far
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
