"""Crank–slider kinematics in closed form and its reduced inertia and weight moment.

Geometry (docs/scenes.md, "Conventions"): crank of radius R about the origin, crank pin
`B = R (cos phi, sin phi)`, slider C on the line y = e at
`x = R cos phi + sqrt(l^2 - (e - R sin phi)^2)` (the assembly with the slider on the +x side),
rod angle theta = atan2(e - R sin phi, x - R cos phi). All derivatives are taken with respect to phi
(kinematic transfer functions): velocities are these times omega.
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple


class CrankSliderGeometry(NamedTuple):
    """Lengths [m], masses [kg] and inertias [kg m^2] of a crank–slider (see scene.schema.CrankSlider)."""

    crank: float
    rod: float
    offset: float
    crank_mass: float
    crank_cg: float
    rod_mass: float
    rod_cg: float
    rod_inertia: float
    slider_mass: float


def slider_kinematics(phi: float, crank: float, rod: float, offset: float) -> tuple[float, ...]:
    """Slider position and rod angle with their first two derivatives with respect to phi.

    With `s = e - R sin phi` and `w = sqrt(l^2 - s^2)` (the rod's projection on the stroke line):
    `x = R cos phi + w`, `theta = atan2(s, w)`, `theta' = s'/w`.
    Returns (x [m], x' [m/rad], x'' [m/rad^2], theta [rad], theta' [-], theta'' [1/rad]).
    """
    sin_phi, cos_phi = math.sin(phi), math.cos(phi)
    s = offset - crank * sin_phi
    ds = -crank * cos_phi
    dds = crank * sin_phi
    w = math.sqrt(rod * rod - s * s)
    dw = -s * ds / w
    ddw = -(ds * ds + s * dds + dw * dw) / w
    dtheta = ds / w
    ddtheta = (dds * w - ds * dw) / (w * w)
    return (crank * cos_phi + w, -crank * sin_phi + dw, -crank * cos_phi + ddw,
            math.atan2(s, w), dtheta, ddtheta)


def make_reduced(geometry: CrankSliderGeometry, gravity: tuple[float, float] | None
                 ) -> Callable[[float], tuple[float, float, float, float, float]]:
    """Build `reduced(phi) -> (J_links, dJ_links/dphi, M_weight, x, x')` for this crank–slider.

    J_links = m_rod |S'|^2 + J_rod theta'^2 + m_slider x'^2 (physics.md section 1), with the rod's
    centre S = B + rho (C - B), rho = rod_cg / l; dJ/dphi = 2 m_rod S'.S'' + 2 J_rod theta' theta''
    + 2 m_slider x' x''. M_weight = g . sum_k m_k S_k' (zero and not computed without gravity).
    The crank's own inertia belongs to the machine's constant inertia.
    """
    R, l, e = geometry.crank, geometry.rod, geometry.offset
    rho = geometry.rod_cg / l
    m_rod, J_rod, m_slider = geometry.rod_mass, geometry.rod_inertia, geometry.slider_mass
    m_crank_r = geometry.crank_mass * geometry.crank_cg
    gx, gy = gravity if gravity is not None else (0.0, 0.0)
    with_weight = gravity is not None and (gx != 0.0 or gy != 0.0)

    def reduced(phi: float) -> tuple[float, float, float, float, float]:
        x, dx, ddx, _theta, dtheta, ddtheta = slider_kinematics(phi, R, l, e)
        sin_phi, cos_phi = math.sin(phi), math.cos(phi)
        # S' = (1 - rho) B' + rho C',  B' = R(-sin, cos), C' = (x', 0); likewise S''.
        dSx = -(1.0 - rho) * R * sin_phi + rho * dx
        dSy = (1.0 - rho) * R * cos_phi
        ddSx = -(1.0 - rho) * R * cos_phi + rho * ddx
        ddSy = -(1.0 - rho) * R * sin_phi
        J = m_rod * (dSx * dSx + dSy * dSy) + J_rod * dtheta * dtheta + m_slider * dx * dx
        dJ = 2.0 * (m_rod * (dSx * ddSx + dSy * ddSy) + J_rod * dtheta * ddtheta + m_slider * dx * ddx)
        weight = 0.0
        if with_weight:
            weight = (gx * (-m_crank_r * sin_phi + m_rod * dSx + m_slider * dx)
                      + gy * (m_crank_r * cos_phi + m_rod * dSy))
        return J, dJ, weight, x, dx

    return reduced


def dead_centres(crank: float, rod: float, offset: float) -> tuple[float, float]:
    """Crank angles [rad] of the outer (x max) and inner (x min) dead centres.

    At both, crank and rod are collinear: outer `phi = asin(e / (l + R))`, inner
    `phi = pi + asin(e / (l - R))` (source 002's alpha1 and alpha2 in this geometry).
    """
    return math.asin(offset / (rod + crank)), math.pi + math.asin(offset / (rod - crank))


def stroke(crank: float, rod: float, offset: float) -> float:
    """Piston stroke [m]: `S = sqrt((l + R)^2 - e^2) - sqrt((l - R)^2 - e^2)` (source 002, eq. 1-10)."""
    return math.sqrt((rod + crank) ** 2 - offset ** 2) - math.sqrt((rod - crank) ** 2 - offset ** 2)
