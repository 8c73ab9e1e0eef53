"""Eight-bar walking-beam transport mechanism of source 004 (docs/theory.md §5.4), in closed form.

Names follow the paper (its figure 3): crank O1A (link 1, length a) about O1 at the origin, coupler
A B C (link 2: AB = b, coupler point C at AC = p, angle delta from AB to AC), rocker O2B (link 3,
length c) about O2 = d e^{i th1}. The four-bar loop `a e^{i th2} + b e^{i th3} = d e^{i th1} + c e^{i th4}`
(th2 = phi) is solved by `four_bar.link_angles` (there its points are named A = O1, B = A, C = B, D = O2).

The parallelograms copy the coupler motion onto the shuttle bar: O3 = O2 + s with the beam vector
s = L e^{i beta}; rocker O3E (link 5) stays parallel to O2B, so the tie B E (link 4) translates and
E = B + s; the side link E D (link 6) stays parallel to B C, so the shuttle bar C D (link 7) translates
with D = C + s. Every point of the shuttle bar moves along the coupler curve of C, shifted.

Point motions are given as (P, dP/dphi, d2P/dphi2) complex numbers (kinematic transfer functions): at
crank speed omega and acceleration epsilon, v = P' omega and a = P'' omega^2 + P' epsilon.
"""

from __future__ import annotations

import cmath
import math
from typing import NamedTuple

from mech_regulator.mechanisms.four_bar import BRANCH_SIGN, link_angles

Motion = tuple[complex, complex, complex]  # (P [m], dP/dphi [m/rad], d2P/dphi2 [m/rad^2])


class WalkingBeamGeometry(NamedTuple):
    """Lengths [m], angles [rad], branch sign, masses [kg], inertias [kg m^2] (scene.mechanism_keys.WalkingBeam)."""

    crank: float
    coupler: float
    rocker: float
    frame: float
    frame_angle: float
    branch_sign: float
    coupler_point: float
    coupler_point_angle: float
    beam_length: float
    beam_angle: float
    crank_mass: float = 0.0
    crank_cg: float = 0.0
    coupler_mass: float = 0.0
    coupler_cg: float = 0.0
    coupler_cg_angle: float = 0.0
    coupler_inertia: float = 0.0
    rocker_mass: float = 0.0
    rocker_cg: float = 0.0
    rocker_inertia: float = 0.0
    tie_mass: float = 0.0
    side_mass: float = 0.0
    side_cg: float = 0.0
    side_inertia: float = 0.0
    shuttle_mass: float = 0.0


def geometry_from_scene(spec) -> WalkingBeamGeometry:
    """The geometry of a scene's `type: walking_beam` mechanism (scene.mechanism_keys.WalkingBeam): its keys, with the
    `_deg` angles in radians and the branch as a sign."""
    fields = type(spec).model_fields
    values = {key: getattr(spec, key) for key in WalkingBeamGeometry._fields if key in fields}
    values.update({key[: -len("_deg")]: math.radians(getattr(spec, key)) for key in fields if key.endswith("_deg")})
    return WalkingBeamGeometry(branch_sign=BRANCH_SIGN[spec.branch], **values)


def arm(base: Motion, length: float, angle: float, rate: float, rate2: float) -> Motion:
    """Motion of P = base + length e^{i angle} for a link angle with d angle/dphi = rate, d2 angle/dphi2 = rate2:
    `P' = base' + i length rate e^{i angle}`, `P'' = base'' + length (i rate2 - rate^2) e^{i angle}`."""
    direction = length * cmath.exp(1j * angle)
    return (base[0] + direction, base[1] + 1j * rate * direction, base[2] + complex(-rate * rate, rate2) * direction)


def side(geometry: WalkingBeamGeometry) -> complex:
    """The side B->C of the coupler triangle in the coupler's frame (AB along +x): p e^{i delta} - b [m];
    its length is that of the side link E D and its argument the angle from AB to BC."""
    return geometry.coupler_point * cmath.exp(1j * geometry.coupler_point_angle) - geometry.coupler


def beam(geometry: WalkingBeamGeometry) -> complex:
    """The beam vector s = O3 - O2 = E - B = D - C = L e^{i beta} [m]."""
    return geometry.beam_length * cmath.exp(1j * geometry.beam_angle)


def _loop_points(
    phi: float, geometry: WalkingBeamGeometry, O2: complex
) -> tuple[tuple[float, ...], Motion, Motion, Motion]:
    """Link angles of `four_bar.link_angles` and the motions of A, B, C at crank angle phi [rad] (see `solve`),
    the rocker pivot O2 [m] given."""
    g = geometry
    angles = link_angles(phi, g.crank, g.coupler, g.rocker, g.frame, g.frame_angle, g.branch_sign)
    th3, dth3, ddth3, th4, dth4, ddth4 = angles
    A = arm((0j, 0j, 0j), g.crank, phi, 1.0, 0.0)
    B = arm((O2, 0j, 0j), g.rocker, th4, dth4, ddth4)
    C = arm(A, g.coupler_point, th3 + g.coupler_point_angle, dth3, ddth3)
    return angles, A, B, C


def solve(phi: float, geometry: WalkingBeamGeometry) -> tuple[tuple[float, ...], dict[str, Motion]]:
    """Link angles (th3, th3', th3'', th4, th4', th4'') of `four_bar.link_angles` and the motions of the
    moving points A, B, C, D, E at crank angle phi [rad].

    A = a e^{i phi}; B = O2 + c e^{i th4}; C = A + p e^{i (th3 + delta)}; E = B + s; D = C + s, s constant
    (so E, D have the derivatives of B, C). Raises ValueError where the four-bar cannot close.
    """
    angles, A, B, C = _loop_points(phi, geometry, geometry.frame * cmath.exp(1j * geometry.frame_angle))
    s = beam(geometry)
    return angles, {"A": A, "B": B, "C": C, "D": (C[0] + s, C[1], C[2]), "E": (B[0] + s, B[1], B[2])}


def change_point(geometry: WalkingBeamGeometry, samples: int = 720) -> str | None:
    """Where a parallelogram flattens over a turn, or None.

    The parallelogram O2 B E O3 flattens when the rocker lies along the beam, sin(th4 - beta) = 0; B C D E when
    the coupler side BC does, sin(th3 + arg BC - beta) = 0. There the parallelogram can fold into an
    antiparallelogram and the shuttle's motion is no longer determined. Returns a description of the first
    flattening found among `samples` crank angles (a sign change or |sin| < 1e-3), with the swing of the link.
    """
    g = geometry
    side_angle = cmath.phase(side(g))
    phis = [2.0 * math.pi * k / samples for k in range(samples + 1)]
    angles = [link_angles(phi, g.crank, g.coupler, g.rocker, g.frame, g.frame_angle, g.branch_sign) for phi in phis]
    for name, link, offset, index in (
        ("O2-B-E-O3", "rocker O2B", 0.0, 3),
        ("B-C-D-E", "coupler side BC", side_angle, 0),
    ):
        sines = [math.sin(a[index] + offset - g.beam_angle) for a in angles]
        for k in range(samples):
            if abs(sines[k]) < 1e-3 or sines[k] * sines[k + 1] < 0.0:
                directions = [math.degrees(math.remainder(a[index] + offset, 2.0 * math.pi)) for a in angles]
                return (
                    f"the parallelogram {name} flattens near crank angle {math.degrees(phis[k]):.1f} deg: the "
                    f"{link} (directions {min(directions):.1f} to {max(directions):.1f} deg over a turn) lies "
                    f"along the beam direction {math.degrees(g.beam_angle):g} deg"
                )
    return None
