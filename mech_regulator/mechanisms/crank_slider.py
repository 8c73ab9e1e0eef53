"""Crank–slider kinematics in closed form (the preset builds a linkage: presets.py).

Geometry (docs/scenes.md, "Conventions"): crank of radius R about the origin, crank pin
`B = R (cos phi, sin phi)`, slider C on the line y = e at
`x = R cos phi + sqrt(l^2 - (e - R sin phi)^2)` (the assembly with the slider on the +x side),
rod angle theta = atan2(e - R sin phi, x - R cos phi). All derivatives are taken with respect to phi
(kinematic transfer functions): velocities are these times omega.
"""

from __future__ import annotations

import math
from typing import NamedTuple


class CrankSliderGeometry(NamedTuple):
    """Lengths [m], masses [kg] and inertias [kg m^2] of a crank–slider (see scene.mechanism_keys.CrankSlider)."""

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
    return (crank * cos_phi + w, -crank * sin_phi + dw, -crank * cos_phi + ddw, math.atan2(s, w), dtheta, ddtheta)


def dead_centres(crank: float, rod: float, offset: float) -> tuple[float, float]:
    """Crank angles [rad] of the outer (x max) and inner (x min) dead centres.

    At both, crank and rod are collinear: outer `phi = asin(e / (l + R))`, inner
    `phi = pi + asin(e / (l - R))` (source 002's alpha1 and alpha2 in this geometry).
    """
    return math.asin(offset / (rod + crank)), math.pi + math.asin(offset / (rod - crank))


def stroke(crank: float, rod: float, offset: float) -> float:
    """Piston stroke [m]: `S = sqrt((l + R)^2 - e^2) - sqrt((l - R)^2 - e^2)` (source 002, eq. 1-10)."""
    return math.sqrt((rod + crank) ** 2 - offset**2) - math.sqrt((rod - crank) ** 2 - offset**2)
