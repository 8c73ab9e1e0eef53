"""Mechanisms: every mechanism is a planar linkage driven by its crank (docs/linkages.md).

A scene's `type: linkage` is its own linkage (the package linkage/: structural analysis, groups, kinematics and
kinetostatics); the three presets (`crank_slider` with its cylinders, `four_bar`, `walking_beam`; their modules hold
their geometry and closed-form kinematics, used for drawing and the engine's analysis) build one (presets.py).
`build_reduced` gives `reduced(phi) -> (J_links [kg m^2], dJ_links/dphi [kg m^2/rad], M_weight [N m], q, dq/dphi)`,
q being the output coordinate on which output-link loads act (slider x [m], rocker angle [rad], shuttle bar x_C [m],
a linkage's output: a slider's travel [m] or a link's angle [rad]; a multi-cylinder engine: the tuples of every
piston's x and x'), by the code generated from the linkage's groups (linkage/symbolic.py), the very code the fast
path compiles. `point_motions` gives the paths of the moving points for `mech-regulator kinematics`;
`build_kinetostatics` the joint reactions by groups (for joint friction).
"""

from __future__ import annotations

import math
from collections.abc import Callable

from mech_regulator.mechanisms import linkage, presets
from mech_regulator.mechanisms.linkage import symbolic
from mech_regulator.mechanisms.presets import mechanism_geometry
from mech_regulator.mechanisms.walking_beam import Motion
from mech_regulator.scene import mechanism_keys


def build_reduced(mechanism: mechanism_keys.Mechanism, gravity: tuple[float, float] | None):
    """The `reduced(phi)` closure of a scene's mechanism (gravity None: no weight moment is computed): the generated
    code of its linkage (linkage_of, linkage.symbolic), compiled as on the fast path; several outputs (a multi-cylinder
    engine's pistons): q and dq/dphi are the tuples of every piston's x and x' (engine.py)."""
    core, structure, outputs = linkage_of(mechanism)
    reduced = symbolic.make_reduced(core, structure, gravity, outputs)
    if len(outputs) <= 1:
        return reduced

    def multi_reduced(phi: float) -> tuple[float, float, float, tuple[float, ...], tuple[float, ...]]:
        J, dJ, weight, *travels = reduced(phi)
        return J, dJ, weight, tuple(travels[0::2]), tuple(travels[1::2])

    return multi_reduced


def linkage_of(mechanism: mechanism_keys.Mechanism) -> tuple[linkage.Linkage, linkage.Structure, tuple[str, ...]]:
    """The linkage a scene's mechanism is solved as (a preset's, presets.preset_linkage, or the scene's own), its
    structure, and the prismatic joints whose travels are its outputs (a multi-cylinder engine's piston guides in
    cylinder order; () : the linkage's own output)."""
    if isinstance(mechanism, mechanism_keys.Linkage):
        core, structure = mechanism_geometry(mechanism)
        return core, structure, ()
    core = presets.preset_linkage(mechanism)
    guides = (
        tuple(presets.guide_joints(mechanism))
        if isinstance(mechanism, mechanism_keys.CrankSlider) and mechanism.cylinders is not None
        else ()
    )
    return core, linkage.checked(core), guides


def cam_law_angles(mechanism: mechanism_keys.Mechanism) -> list[float]:
    """The crank angles [rad] in [0, 2 pi) where a cam follower's law changes piece (its s'' may jump there)."""
    if not isinstance(mechanism, mechanism_keys.Linkage):
        return []
    specs = [
        presets.cam_spec(joint) for joint in mechanism.joints.values() if isinstance(joint, mechanism_keys.CamJoint)
    ]
    return [float(angle) % (2.0 * math.pi) for spec in specs for angle in spec.law.kinks() + spec.start]


def cam_pairs_of(mechanism: mechanism_keys.Mechanism, gravity) -> list:
    """The linkage/cam.py CamPairs of a scene's mechanism (gravity (gx, gy) [m/s^2] or None); [] without cams."""
    if not isinstance(mechanism, mechanism_keys.Linkage):
        return []
    from mech_regulator.mechanisms.linkage.cam import cam_pairs

    core, structure = mechanism_geometry(mechanism)
    return cam_pairs(core, structure.groups, gravity)


def build_kinetostatics(mechanism: mechanism_keys.Mechanism, gravity: tuple[float, float] | None):
    """The `loads(phi, omega, Q)` closure of a scene's mechanism and its joint names: the kinetostatics by groups of
    its linkage (linkage_of, linkage.make_joint_loads); gravity None: the links are weightless."""
    core, structure, _ = linkage_of(mechanism)
    return linkage.make_joint_loads(core, structure, gravity)


def point_motions(mechanism: mechanism_keys.Mechanism) -> Callable[[float], dict[str, Motion]]:
    """`motions(phi) -> {point: (P [m], dP/dphi [m/rad], d2P/dphi2 [m/rad^2])}` of the moving points of a scene's
    mechanism, as complex numbers x + i y (velocity P' omega, acceleration P'' omega^2 + P' epsilon), from its linkage
    (linkage_of; linkage.kinematics.moving_points): a scene's linkage's joints off the frame and its points of
    interest; a preset's named points only (presets.py: crank–slider and four-bar B, C; walking beam A..E)."""
    core, structure, _ = linkage_of(mechanism)
    motions = linkage.make_point_motions(core, structure)
    if isinstance(mechanism, mechanism_keys.Linkage):
        return motions
    names = core.points
    return lambda phi: {name: motion for name, motion in motions(phi).items() if name in names}
