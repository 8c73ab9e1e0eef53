"""Mechanisms: kinematics of the linkage driven by the crank, and its reduced inertia and weight moment.

Each mechanism module gives a closed-form `make_reduced(geometry, gravity)` returning
`reduced(phi) -> (J_links [kg m^2], dJ_links/dphi [kg m^2/rad], M_weight [N m], q, dq/dphi)`,
q being the output coordinate on which output-link loads act (slider x [m], rocker angle [rad]).
`kinetostatics` gives the joint reactions of both mechanisms (for joint friction).
"""

from __future__ import annotations

import math

from mech_regulator.mechanisms import crank_slider, four_bar, kinetostatics
from mech_regulator.scene import schema


def build_reduced(mechanism: schema.Mechanism, gravity: tuple[float, float] | None):
    """The `reduced(phi)` closure of a scene's mechanism (gravity None: no weight moment is computed)."""
    geometry = mechanism_geometry(mechanism)
    module = crank_slider if isinstance(geometry, crank_slider.CrankSliderGeometry) else four_bar
    return module.make_reduced(geometry, gravity)


def build_kinetostatics(mechanism: schema.Mechanism, gravity: tuple[float, float] | None):
    """The `loads(phi, omega, Q)` closure of a scene's mechanism (mechanisms.kinetostatics) and its joint
    names; gravity None: the links are weightless."""
    geometry = mechanism_geometry(mechanism)
    gravity = gravity if gravity is not None else (0.0, 0.0)
    if isinstance(geometry, crank_slider.CrankSliderGeometry):
        return kinetostatics.crank_slider_kinetostatics(geometry, gravity), kinetostatics.CRANK_SLIDER_JOINTS
    return kinetostatics.four_bar_kinetostatics(geometry, gravity), kinetostatics.FOUR_BAR_JOINTS


def mechanism_geometry(mechanism: schema.Mechanism):
    """The geometry NamedTuple (lengths [m], angles [rad], masses [kg], inertias [kg m^2]) of a scene's mechanism."""
    if isinstance(mechanism, schema.CrankSlider):
        return crank_slider.CrankSliderGeometry(**{k: getattr(mechanism, k)
                                                   for k in crank_slider.CrankSliderGeometry._fields})
    if isinstance(mechanism, schema.FourBar):
        fields = {k: getattr(mechanism, k) for k in four_bar.FourBarGeometry._fields
                  if k not in ("frame_angle", "branch_sign")}
        return four_bar.FourBarGeometry(frame_angle=math.radians(mechanism.frame_angle_deg),
                                        branch_sign=four_bar.BRANCH_SIGN[mechanism.branch], **fields)
    raise TypeError(f"no kinematics for {type(mechanism).__name__}")
