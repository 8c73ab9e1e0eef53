"""Mechanisms: kinematics of the linkage driven by the crank, and its reduced inertia and weight moment.

Each mechanism module gives a closed-form `make_reduced(geometry, gravity)` returning
`reduced(phi) -> (J_links [kg m^2], dJ_links/dphi [kg m^2/rad], M_weight [N m], q, dq/dphi)`,
q being the output coordinate on which output-link loads act (slider x [m], rocker angle [rad]);
a crank–slider with several cylinders (engine.py) returns the tuples of every piston's x and x'.
"""

from __future__ import annotations

import math

from mech_regulator.mechanisms import crank_slider, engine, four_bar
from mech_regulator.scene import schema


def build_reduced(mechanism: schema.Mechanism, gravity: tuple[float, float] | None):
    """The `reduced(phi)` closure of a scene's mechanism (gravity None: no weight moment is computed)."""
    if isinstance(mechanism, schema.CrankSlider):
        geometry = crank_slider.CrankSliderGeometry(**{k: getattr(mechanism, k)
                                                       for k in crank_slider.CrankSliderGeometry._fields})
        if mechanism.cylinders is not None:
            return engine.make_multi_reduced(geometry, [c.throw_deg for c in mechanism.cylinders],
                                             [c.bank_deg for c in mechanism.cylinders], gravity)
        return crank_slider.make_reduced(geometry, gravity)
    if isinstance(mechanism, schema.FourBar):
        fields = {k: getattr(mechanism, k) for k in four_bar.FourBarGeometry._fields
                  if k not in ("frame_angle", "branch_sign")}
        geometry = four_bar.FourBarGeometry(frame_angle=math.radians(mechanism.frame_angle_deg),
                                            branch_sign=four_bar.BRANCH_SIGN[mechanism.branch], **fields)
        return four_bar.make_reduced(geometry, gravity)
    raise TypeError(f"no kinematics for {type(mechanism).__name__}")
