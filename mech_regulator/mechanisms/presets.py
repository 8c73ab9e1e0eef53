"""The three preset mechanisms (crank–slider with its cylinders, four-bar, walking beam) built as general linkages
(their scene syntax stays as it was; docs/linkages.md).

`preset_linkage(mechanism)` turns a scene's `crank_slider`, `four_bar` or `walking_beam` (the geometry of
mechanism_geometry) into a mechanisms.linkage.Linkage whose reduction, point motions and joint reactions
(mechanisms.build_reduced, point_motions, build_kinetostatics) equal the presets' hand-written closed forms, kept as
the tests' reference (test/closed_forms.py), to rounding. Its conventions:

- The crank's own inertia belongs to machine.inertia (scene.mechanism_keys.CrankSlider.crank_mass: "for its weight only"):
  the crank link has the crank's mass m at its centre cg (so its weight moment m g . S' and the crank bearing's
  share of its inertia force m a_S are the preset's) and the moment of inertia -m cg^2 about that centre, so that
  its moment of inertia about the pivot, I_S + m cg^2, is zero: J_links has no crank term and the balancing moment
  of the kinetostatics leaves out m cg^2 epsilon, as the preset's does.
- The frame is the link named 'frame' (as a scene's linkage), the crank 'crank'; the crank turns about the origin.
- Joint names: the preset's (kinetostatics.CRANK_SLIDER_JOINTS, FOUR_BAR_JOINTS), so that a scene's
  `joint_friction.joints:` names the same joints. Each of their revolute joints lists the link farther from the
  frame first, so that its reaction (the force on its first link from its second) is the preset's F_ij, the force
  of the inner link i on the outer link j; its ratio (theta_first' - theta_second') is then the preset's relative
  speed for the bearings and its negative for the pins (joint friction reads |R| and |ratio| only). The walking
  beam keeps the paper's joint names.
- The preset's point names (mechanisms.point_motions) are the linkage's points of interest (`Linkage.points`):
  crank–slider B (crank pin) and C (wrist pin), four-bar B and C, walking beam A..E (its joints' names).
- The output q: the crank–slider's slider x (the guide's point on the frame at x = 0, its direction the cylinder
  axis), the four-bar's rocker angle (the output link), the walking beam's x_C (a massless Scotch yoke reads it,
  as config/scenes/walking_beam_linkage.yaml's does).
- A multi-cylinder engine: one crank with a pin per cylinder at its throw, a rod and a piston per cylinder, each
  piston's guide on the frame along its bank; joints `crank_pin_i`, `wrist_pin_i`, `guide_i` (i = 1..n), the
  linkage's output the first cylinder's guide (`guide_joints` gives them all in cylinder order).
"""

from __future__ import annotations

import cmath
import math
from dataclasses import replace

from mech_regulator.mechanisms import crank_slider, four_bar, kinetostatics, walking_beam
from mech_regulator.mechanisms.cam_laws import Segment, SegmentLaw, TableLaw
from mech_regulator.mechanisms.linkage import Joint, Link, Linkage, checked
from mech_regulator.mechanisms.linkage.cam import CamSpec
from mech_regulator.mechanisms.linkage.gears import GearMesh
from mech_regulator.scene import mechanism_keys

FRAME, CRANK = "frame", "crank"
CRANK_BEARING, CRANK_PIN, WRIST_PIN, GUIDE = kinetostatics.CRANK_SLIDER_JOINTS
_, _, ROCKER_PIN, ROCKER_BEARING = kinetostatics.FOUR_BAR_JOINTS


def _crank(points: dict[str, complex], mass: float, centre: complex) -> Link:
    """The crank link (its pivot at its origin, among `points`) with mass [kg] at `centre` [m] and no moment of
    inertia about its pivot: I_S = -m |centre|^2 (module docstring)."""
    return Link(
        CRANK,
        points,
        mass=mass,
        centre=centre,
        inertia=0.0 - mass * (centre.real * centre.real + centre.imag * centre.imag),
    )  # as the code writes it


def _revolute(name: str, outer: str, inner: str) -> Joint:
    """A revolute joint listing the link farther from the frame first (module docstring)."""
    return Joint(name, "revolute", (outer, inner))


def cylinder_names(count: int) -> list[tuple[str, str, str]]:
    """(crank pin, wrist pin, guide) joint names of each cylinder: the preset's for one cylinder, suffixed _1.._n
    for several."""
    if count == 1:
        return [(CRANK_PIN, WRIST_PIN, GUIDE)]
    return [(f"{CRANK_PIN}_{i}", f"{WRIST_PIN}_{i}", f"{GUIDE}_{i}") for i in range(1, count + 1)]


def guide_joints(mechanism: mechanism_keys.CrankSlider) -> list[str]:
    """The names of a crank–slider's piston guides (prismatic joints) in cylinder order: cylinder i's travel along
    its guide is its piston position x_i [m]."""
    count = len(mechanism.cylinders) if mechanism.cylinders is not None else 1
    return [guide for _, _, guide in cylinder_names(count)]


def crank_slider_linkage(
    g: crank_slider.CrankSliderGeometry, cylinders: list[mechanism_keys.Cylinder] | None = None
) -> Linkage:
    """A crank–slider (one or several cylinders) as a linkage: per cylinder i with throw tau_i and bank b_i, the
    crank pin at R e^{i tau_i} on the crank, a rod (crank pin at 0, wrist pin at l, centre rod_cg, mass and
    inertia) and a piston (a point mass at its wrist pin) on the frame's guide through e i e^{i b_i}, direction b_i:
    in the cylinder's own frame the piston runs on y = e and its travel is the preset's x at phi + tau_i - b_i
    (engine.py). The crank carries the crank mass once per cylinder, at the mean of its throws' centres
    cg e^{i tau_i} (its weight moment is the preset's sum over cylinders)."""
    cylinders = cylinders or [mechanism_keys.Cylinder()]
    throws = [cmath.exp(1j * math.radians(c.throw_deg)) for c in cylinders]
    frame, crank_points, links, joints = {CRANK_BEARING: 0j}, {CRANK_BEARING: 0j, "B": g.crank * throws[0]}, [], []
    names = cylinder_names(len(cylinders))
    for (pin, wrist, guide), cylinder, throw in zip(names, cylinders, throws):
        bank = math.radians(cylinder.bank_deg)
        suffix = pin[len(CRANK_PIN) :]
        rod, piston = "rod" + suffix, "piston" + suffix
        frame[guide] = g.offset * 1j * cmath.exp(1j * bank)
        crank_points[pin] = g.crank * throw
        links += [
            Link(rod, {pin: 0j, wrist: g.rod + 0j}, mass=g.rod_mass, centre=g.rod_cg + 0j, inertia=g.rod_inertia),
            Link(piston, {wrist: 0j, guide: 0j}, mass=g.slider_mass),
        ]
        joints += [
            _revolute(pin, rod, CRANK),
            _revolute(wrist, piston, rod),
            Joint(guide, "prismatic", (FRAME, piston), direction=bank, slider_angle=bank),
        ]
    links[1] = replace(links[1], points={**links[1].points, "C": 0j})
    crank = _crank(crank_points, len(cylinders) * g.crank_mass, g.crank_cg * sum(throws) / len(throws))
    return Linkage(
        links=(Link(FRAME, frame), crank, *links),
        joints=(_revolute(CRANK_BEARING, CRANK, FRAME), *joints),
        frame=FRAME,
        crank=CRANK,
        points=("B", "C"),
        output_joint=names[0][2],
    )


def four_bar_linkage(g: four_bar.FourBarGeometry) -> Linkage:
    """A four-bar as a linkage: crank (A at 0, B at a), coupler (B at 0, C at b), rocker (D at 0, C at c), D = d
    e^{i th1} on the frame; one RRR group whose branch is the preset's: +1 (C left of B->D) for 'open', -1 for
    'crossed'. Output: the rocker's angle."""
    return Linkage(
        links=(
            Link(FRAME, {CRANK_BEARING: 0j, ROCKER_BEARING: g.frame * cmath.exp(1j * g.frame_angle)}),
            _crank({CRANK_BEARING: 0j, CRANK_PIN: g.crank + 0j, "B": g.crank + 0j}, g.crank_mass, g.crank_cg + 0j),
            Link(
                "coupler",
                {CRANK_PIN: 0j, ROCKER_PIN: g.coupler + 0j},
                mass=g.coupler_mass,
                centre=g.coupler_cg + 0j,
                inertia=g.coupler_inertia,
            ),
            Link(
                "rocker",
                {ROCKER_BEARING: 0j, ROCKER_PIN: g.rocker + 0j, "C": g.rocker + 0j},
                mass=g.rocker_mass,
                centre=g.rocker_cg + 0j,
                inertia=g.rocker_inertia,
            ),
        ),
        joints=(
            _revolute(CRANK_BEARING, CRANK, FRAME),
            _revolute(CRANK_PIN, "coupler", CRANK),
            _revolute(ROCKER_PIN, "rocker", "coupler"),
            _revolute(ROCKER_BEARING, "rocker", FRAME),
        ),
        frame=FRAME,
        crank=CRANK,
        branches={ROCKER_PIN: -int(g.branch_sign)},
        points=("B", "C"),
        output_link="rocker",
        output_reference=four_bar.rocker_angle(
            0.0, g.crank, g.coupler, g.rocker, g.frame, g.frame_angle, g.branch_sign
        ),
    )


def walking_beam_linkage(g: walking_beam.WalkingBeamGeometry) -> Linkage:
    """Source 004's eight-bar as a linkage (joints by the paper's names, walking_beam.py): the four-bar O1 A B O2
    (an RRR group, branch as four_bar_linkage's), the parallelogram O2 B E O3 (tie B E, second rocker O3 E: RRR)
    and B C D E (side link E D, shuttle bar C D: RRR), n = 7, p5 = 10, W = 1, and a massless Scotch yoke reading
    x_C (a block pinned at C in the yoke's vertical slot, the yoke on the frame's horizontal guide X through the
    origin: an RPP group whose travel is x_C). The tie, side link and shuttle carry second points Bt, Es and Cp at
    B, E and C (a joint's point has its name). The parallelograms' branches are those that close them (E = B + s,
    D = C + s) at phi = 0: the side of the outer joints' line the internal joint lies on; they cannot change while
    the parallelograms do not flatten (scene.mechanism_keys.WalkingBeam refuses that)."""
    s, bc = walking_beam.beam(g), walking_beam.side(g)
    O2 = g.frame * cmath.exp(1j * g.frame_angle)
    at_zero = walking_beam.solve(0.0, g)[1]
    B, C = at_zero["B"][0], at_zero["C"][0]

    def side_of(start: complex, end: complex, point: complex) -> int:
        return 1 if ((end - start).conjugate() * (point - start)).imag > 0 else -1

    coupler_point = g.coupler_point * cmath.exp(1j * g.coupler_point_angle)
    return Linkage(
        links=(
            Link(FRAME, {"O1": 0j, "O2": O2, "O3": O2 + s, "X": 0j}),
            _crank({"O1": 0j, "A": g.crank + 0j}, g.crank_mass, g.crank_cg + 0j),
            Link(
                "coupler",
                {"A": 0j, "B": g.coupler + 0j, "C": coupler_point},
                mass=g.coupler_mass,
                centre=g.coupler_cg * cmath.exp(1j * g.coupler_cg_angle),
                inertia=g.coupler_inertia,
            ),
            Link(
                "rocker",
                {"O2": 0j, "B": g.rocker + 0j, "Bt": g.rocker + 0j},
                mass=g.rocker_mass,
                centre=g.rocker_cg + 0j,
                inertia=g.rocker_inertia,
            ),
            Link("tie", {"Bt": 0j, "E": s, "Es": s}, mass=g.tie_mass),
            Link(
                "rocker5",
                {"O3": 0j, "E": g.rocker + 0j},
                mass=g.rocker_mass,
                centre=g.rocker_cg + 0j,
                inertia=g.rocker_inertia,
            ),
            Link(
                "side", {"Es": 0j, "D": bc}, mass=g.side_mass, centre=g.side_cg * bc / abs(bc), inertia=g.side_inertia
            ),
            Link("shuttle", {"C": 0j, "D": s, "Cp": 0j}, mass=g.shuttle_mass),
            Link("block", {"Cp": 0j, "slot": 0j}),
            Link("yoke", {"slot": 0j, "X": 0j}),
        ),
        joints=(
            Joint("O1", "revolute", (FRAME, CRANK)),
            Joint("A", "revolute", (CRANK, "coupler")),
            Joint("B", "revolute", ("coupler", "rocker")),
            Joint("O2", "revolute", (FRAME, "rocker")),
            Joint("Bt", "revolute", ("rocker", "tie")),
            Joint("E", "revolute", ("tie", "rocker5")),
            Joint("O3", "revolute", (FRAME, "rocker5")),
            Joint("Es", "revolute", ("tie", "side")),
            Joint("D", "revolute", ("side", "shuttle")),
            Joint("C", "revolute", ("coupler", "shuttle")),
            Joint("Cp", "revolute", ("shuttle", "block")),
            Joint("slot", "prismatic", ("yoke", "block"), direction=math.pi / 2),
            Joint("X", "prismatic", (FRAME, "yoke")),
        ),
        frame=FRAME,
        crank=CRANK,
        branches={"B": -int(g.branch_sign), "E": side_of(B, O2 + s, B + s), "D": side_of(B + s, C, C + s)},
        points=tuple("ABCDE"),
        output_joint="X",
    )


def linkage_core(mechanism: mechanism_keys.Linkage) -> Linkage:
    """The mechanisms.linkage.Linkage of a scene's linkage entry (the frame is the link named 'frame')."""

    def complex_points(points: dict[str, list[float]]) -> dict[str, complex]:
        return {name: complex(*xy) for name, xy in points.items()}

    rollers = {joint.links[1]: joint.roller_radius for joint in mechanism.joints.values() if joint.type == "cam"}
    links = (Link("frame", complex_points(mechanism.frame)),) + tuple(
        Link(name, complex_points(link.points), link.mass, complex(*link.centre), link.inertia, rollers.get(name))
        for name, link in mechanism.links.items()
    )
    joints = tuple(
        Joint(name, joint.type, (joint.links[0], joint.links[1]), cam=cam_spec(joint))
        if isinstance(joint, mechanism_keys.CamJoint)
        else Joint(
            name,
            joint.type,
            (joint.links[0], joint.links[1]),
            math.radians(joint.direction_deg),
            math.radians(joint.slider_angle_deg),
            gear=_gear_mesh(joint),
        )
        for name, joint in mechanism.joints.items()
    )
    output = mechanism.output or mechanism_keys.LinkageOutput.model_construct(joint=None, link=None)
    return Linkage(
        links,
        joints,
        "frame",
        mechanism.crank,
        dict(mechanism.branches),
        tuple(mechanism.points),
        output.joint,
        output.link,
    )


def cam_spec(joint: mechanism_keys.CamJoint) -> CamSpec:
    """The linkage/cam.py CamSpec of a scene's cam pair: its law (segments or a table, angles in rad), contact, base
    radius [m], start angle [rad] and spring (stiffness, preload; 0 without one)."""
    if isinstance(joint.law, mechanism_keys.CamTable):
        law: TableLaw | SegmentLaw = TableLaw([math.radians(a) for a in joint.law.angle_deg], joint.law.lift)
    else:
        law = SegmentLaw(
            tuple(
                Segment(part.motion, math.radians(part.angle_deg), part.law or "uniform", part.lift)
                for part in joint.law
            )
        )
    spring = joint.spring or mechanism_keys.FollowerSpring(stiffness=0.0, preload=0.0)
    return CamSpec(
        law, joint.contact, joint.base_radius, math.radians(joint.start_deg), spring.stiffness, spring.preload
    )


def _gear_mesh(joint: mechanism_keys.LinkageJoint) -> GearMesh | None:
    """The gear pair of a scene's linkage joint (None for a lower pair)."""
    if joint.type != "gear":
        return None
    assert joint.centres is not None  # mechanism_keys.LinkageJoint: a gear has its two centres
    return GearMesh(
        (joint.centres[0], joint.centres[1]),
        (joint.teeth[0], joint.teeth[1]) if joint.teeth else None,
        (joint.radii[0], joint.radii[1]) if joint.radii else None,
        joint.internal,
        joint.carrier,
        math.radians(joint.phase_deg),
    )


def mechanism_geometry(mechanism: mechanism_keys.Mechanism):
    """The geometry NamedTuple (lengths [m], angles [rad], masses [kg], inertias [kg m^2]) of a scene's mechanism;
    a linkage's: its mechanisms.linkage.Linkage and Structure (validated by the scene: W = 1, class-II groups)."""
    if isinstance(mechanism, mechanism_keys.Linkage):
        core = linkage_core(mechanism)
        return core, checked(core)
    if isinstance(mechanism, mechanism_keys.CrankSlider):
        return crank_slider.CrankSliderGeometry(
            **{k: getattr(mechanism, k) for k in crank_slider.CrankSliderGeometry._fields}
        )
    if isinstance(mechanism, mechanism_keys.FourBar):
        fields = {
            k: getattr(mechanism, k)
            for k in four_bar.FourBarGeometry._fields
            if k not in ("frame_angle", "branch_sign")
        }
        return four_bar.FourBarGeometry(
            frame_angle=math.radians(mechanism.frame_angle_deg),
            branch_sign=four_bar.BRANCH_SIGN[mechanism.branch],
            **fields,
        )
    if isinstance(mechanism, mechanism_keys.WalkingBeam):
        return walking_beam.geometry_from_scene(mechanism)
    raise TypeError(f"no kinematics for {type(mechanism).__name__}")


def preset_linkage(
    mechanism: mechanism_keys.CrankSlider | mechanism_keys.FourBar | mechanism_keys.WalkingBeam,
) -> Linkage:
    """The linkage of a scene's preset mechanism (module docstring): its reduction, point motions and joint
    reactions equal the preset's."""
    if isinstance(mechanism, mechanism_keys.CrankSlider):
        return crank_slider_linkage(mechanism_geometry(mechanism), mechanism.cylinders)
    if isinstance(mechanism, mechanism_keys.FourBar):
        return four_bar_linkage(mechanism_geometry(mechanism))
    if isinstance(mechanism, mechanism_keys.WalkingBeam):
        return walking_beam_linkage(mechanism_geometry(mechanism))
    raise TypeError(
        f"no preset linkage for {type(mechanism).__name__}; expected a crank_slider, four_bar or walking_beam"
    )
