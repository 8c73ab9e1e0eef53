"""Mechanisms: kinematics of the linkage driven by the crank, and its reduced inertia and weight moment.

Each mechanism module gives a closed-form `make_reduced(geometry, gravity)` returning
`reduced(phi) -> (J_links [kg m^2], dJ_links/dphi [kg m^2/rad], M_weight [N m], q, dq/dphi)`,
q being the output coordinate on which output-link loads act (slider x [m], rocker angle [rad],
shuttle bar x_C [m], a linkage's output: a slider's travel [m] or a link's angle [rad]); a crank–slider with
several cylinders (engine.py) returns the tuples of every piston's x and x'. A general linkage (`type: linkage`,
the package linkage/) is analysed structurally and solved group by group. `point_motions` gives the paths of the moving joints for `mech-regulator kinematics`;
`build_kinetostatics` gives the joint reactions of the single crank–slider, the four-bar and a linkage (for joint
friction).
"""

from __future__ import annotations

import cmath
import math
from typing import Callable

from mech_regulator.mechanisms import crank_slider, engine, four_bar, kinetostatics, linkage, walking_beam
from mech_regulator.mechanisms.walking_beam import Motion, arm
from mech_regulator.scene import schema


def build_reduced(mechanism: schema.Mechanism, gravity: tuple[float, float] | None):
    """The `reduced(phi)` closure of a scene's mechanism (gravity None: no weight moment is computed)."""
    if isinstance(mechanism, schema.Linkage):
        core, structure = mechanism_geometry(mechanism)
        return linkage.make_reduced(core, structure, gravity)
    geometry = mechanism_geometry(mechanism)
    if isinstance(mechanism, schema.CrankSlider) and mechanism.cylinders is not None:
        return engine.make_multi_reduced(geometry, [c.throw_deg for c in mechanism.cylinders],
                                         [c.bank_deg for c in mechanism.cylinders], gravity)
    module = {schema.CrankSlider: crank_slider, schema.FourBar: four_bar, schema.WalkingBeam: walking_beam}
    return module[type(mechanism)].make_reduced(geometry, gravity)


def build_kinetostatics(mechanism: schema.Mechanism, gravity: tuple[float, float] | None):
    """The `loads(phi, omega, Q)` closure of a scene's mechanism (mechanisms.kinetostatics) and its joint
    names (a linkage's: its joints', linkage.make_joint_loads); gravity None: the links are weightless."""
    geometry = mechanism_geometry(mechanism)
    if isinstance(mechanism, schema.Linkage):
        return linkage.make_joint_loads(*geometry, gravity)
    gravity = gravity if gravity is not None else (0.0, 0.0)
    if isinstance(geometry, crank_slider.CrankSliderGeometry):
        return kinetostatics.crank_slider_kinetostatics(geometry, gravity), kinetostatics.CRANK_SLIDER_JOINTS
    return kinetostatics.four_bar_kinetostatics(geometry, gravity), kinetostatics.FOUR_BAR_JOINTS


def mechanism_geometry(mechanism: schema.Mechanism):
    """The geometry NamedTuple (lengths [m], angles [rad], masses [kg], inertias [kg m^2]) of a scene's mechanism;
    a linkage's: its mechanisms.linkage.Linkage and Structure (validated by the scene: W = 1, class-II groups)."""
    if isinstance(mechanism, schema.Linkage):
        core = mechanism.core()
        return core, linkage.checked(core)
    if isinstance(mechanism, schema.CrankSlider):
        return crank_slider.CrankSliderGeometry(**{k: getattr(mechanism, k)
                                                   for k in crank_slider.CrankSliderGeometry._fields})
    if isinstance(mechanism, schema.FourBar):
        fields = {k: getattr(mechanism, k) for k in four_bar.FourBarGeometry._fields
                  if k not in ("frame_angle", "branch_sign")}
        return four_bar.FourBarGeometry(frame_angle=math.radians(mechanism.frame_angle_deg),
                                        branch_sign=four_bar.BRANCH_SIGN[mechanism.branch], **fields)
    if isinstance(mechanism, schema.WalkingBeam):
        return walking_beam.geometry_from_scene(mechanism)
    raise TypeError(f"no kinematics for {type(mechanism).__name__}")


def point_motions(mechanism: schema.Mechanism) -> Callable[[float], dict[str, Motion]]:
    """`motions(phi) -> {point: (P [m], dP/dphi [m/rad], d2P/dphi2 [m/rad^2])}` of the moving joints of a
    scene's mechanism, as complex numbers x + i y (velocity P' omega, acceleration P'' omega^2 + P' epsilon).

    Crank–slider: crank pin B = R e^{i phi}, slider C = x + i e (x, x', x'' of `crank_slider.slider_kinematics`).
    Four-bar: crank pin B = a e^{i phi}, rocker pin C = d e^{i th1} + c e^{i th4} (`four_bar.link_angles`).
    Walking beam: A, B, C, D, E of `walking_beam.solve` (the paper's names).
    Linkage: its joints off the frame and its points of interest (`linkage.kinematics.moving_points`).
    """
    if isinstance(mechanism, schema.Linkage):
        return linkage.make_point_motions(*mechanism_geometry(mechanism))
    if isinstance(mechanism, schema.CrankSlider):
        R, rod, e = mechanism.crank, mechanism.rod, mechanism.offset

        def crank_slider_motions(phi: float) -> dict[str, Motion]:
            x, dx, ddx, *_ = crank_slider.slider_kinematics(phi, R, rod, e)
            return {"B": arm((0j, 0j, 0j), R, phi, 1.0, 0.0), "C": (complex(x, e), complex(dx), complex(ddx))}

        return crank_slider_motions
    if isinstance(mechanism, schema.FourBar):
        a, b, c, d = mechanism.crank, mechanism.coupler, mechanism.rocker, mechanism.frame
        th1, sign = math.radians(mechanism.frame_angle_deg), four_bar.BRANCH_SIGN[mechanism.branch]

        def four_bar_motions(phi: float) -> dict[str, Motion]:
            _, _, _, th4, dth4, ddth4 = four_bar.link_angles(phi, a, b, c, d, th1, sign)
            return {"B": arm((0j, 0j, 0j), a, phi, 1.0, 0.0),
                    "C": arm((d * cmath.exp(1j * th1), 0j, 0j), c, th4, dth4, ddth4)}

        return four_bar_motions
    geometry = walking_beam.geometry_from_scene(mechanism)
    return lambda phi: walking_beam.solve(phi, geometry)[1]
