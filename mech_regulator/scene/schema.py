"""The scene format: one YAML file describing a machine, what acts on it, the scenario and the solver.

The pydantic models below are the single source of truth for the format: validation, the JSON
Schema (`mech-regulator schema`) and the key tables of `docs/scenes.md` all come from them.
Every field's description states its unit (SI unless the key name says `_deg`).

Conventions: the crank angle phi is measured counter-clockwise from the +x axis, the crank pin is
at `B = (R cos phi, R sin phi)`; positive moments turn the crank counter-clockwise (the working
direction); load values are resisting magnitudes unless a description says "signed".
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Discriminator, Field, Tag, model_validator

Positive = Annotated[float, Field(gt=0)]
NonNegative = Annotated[float, Field(ge=0)]


class SceneModel(BaseModel):
    """Base of every scene section: unknown keys, NaN and infinities are errors; ints pass as floats."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True, frozen=True)


def _check_table(angles_deg: list[float], values: list[float], period_deg: float, what: str) -> None:
    """Check a periodic table: equal lengths, strictly increasing angles inside one period."""
    if len(angles_deg) != len(values):
        raise ValueError(
            f"{what}: angle_deg has {len(angles_deg)} entries but the values have {len(values)}; "
            "expected one value per angle"
        )
    if any(b <= a for a, b in zip(angles_deg, angles_deg[1:])):
        raise ValueError(f"{what}: angle_deg = {angles_deg} must be strictly increasing")
    if angles_deg[-1] - angles_deg[0] >= period_deg:
        raise ValueError(
            f"{what}: angle_deg spans {angles_deg[-1] - angles_deg[0]} deg; "
            f"expected less than one period ({period_deg} deg)"
        )


# --------------------------------------------------------------------------------------------
# Machine: inertia and mechanism


class Flywheel(SceneModel):
    inertia: NonNegative = Field(description="moment of inertia of the flywheel about its own shaft [kg m^2]")
    ratio: float = Field(
        1.0,
        description="omega_flywheel / omega (gear ratio to the crank); the flywheel adds "
        "inertia * ratio^2 to the reduced inertia [-]",
    )


class Cylinder(SceneModel):
    """One cylinder of a multi-cylinder engine: its crank throw and its axis (bank) relative to cylinder 1."""

    throw_deg: float = Field(
        0.0,
        description="angle of this cylinder's crank throw ahead of cylinder 1's, counter-"
        "clockwise (the pin is at phi + throw) [deg]",
    )
    bank_deg: float = Field(
        0.0,
        description="direction of this cylinder's axis from +x (V engines); the piston "
        "moves on its own line at the same offset [deg]",
    )


class CrankSlider(SceneModel):
    """Crank–slider: crank pin B = R(cos phi, sin phi), slider on the line y = offset on the +x side."""

    type: Literal["crank_slider"]
    crank: Positive = Field(description="crank radius R [m]")
    rod: Positive = Field(description="connecting-rod length l [m]; must exceed crank + |offset|")
    offset: float = Field(0.0, description="offset e of the stroke line y = e (desaxe) [m]")
    crank_mass: NonNegative = Field(
        0.0, description="crank mass, used for its weight only (its inertia is in machine.inertia) [kg]"
    )
    crank_cg: float = Field(
        0.0, description="distance of the crank's centre of mass from the axis, towards the pin [m]"
    )
    rod_mass: NonNegative = Field(0.0, description="connecting-rod mass [kg]")
    rod_cg: NonNegative = Field(
        0.0, description="distance of the rod's centre of mass from the crank pin, along the rod [m]"
    )
    rod_inertia: NonNegative = Field(0.0, description="rod moment of inertia about its centre of mass [kg m^2]")
    slider_mass: NonNegative = Field(0.0, description="slider (piston) mass [kg]")
    cylinders: list[Cylinder] | None = Field(
        None,
        min_length=1,
        description="identical cylinders on one crankshaft "
        "(multi-cylinder engine), the first at throw_deg 0 and bank_deg 0; every "
        "length and mass above is per cylinder; none = one slider",
    )

    @model_validator(mode="after")
    def _assembles(self) -> CrankSlider:
        if self.cylinders and (self.cylinders[0].throw_deg != 0.0 or self.cylinders[0].bank_deg != 0.0):
            raise ValueError(
                f"cylinders[0] has throw_deg {self.cylinders[0].throw_deg:g} and bank_deg "
                f"{self.cylinders[0].bank_deg:g}: cylinder 1 is the reference (phi is its crank angle "
                "from its axis, +x), expected 0 and 0"
            )
        reach = self.crank + abs(self.offset)
        if self.rod <= reach:
            raise ValueError(
                f"rod = {self.rod} m is too short: the crank turns fully only if rod > crank + |offset| = {reach:g} m"
            )
        if self.rod_cg > self.rod:
            raise ValueError(
                f"rod_cg = {self.rod_cg} m lies beyond the rod (rod = {self.rod} m); expected 0 <= rod_cg <= rod"
            )
        return self


class FourBar(SceneModel):
    """Four-bar: crank a about A = (0, 0), coupler b, rocker c about D = frame * (cos th1, sin th1).

    Loop closure `a e^{i th2} + b e^{i th3} = d e^{i th1} + c e^{i th4}` with th2 = phi."""

    type: Literal["four_bar"]
    crank: Positive = Field(description="crank length a (A to B) [m]")
    coupler: Positive = Field(description="coupler length b (B to C) [m]")
    rocker: Positive = Field(description="rocker length c (D to C) [m]")
    frame: Positive = Field(description="frame length d (A to D) [m]")
    frame_angle_deg: float = Field(0.0, description="direction th1 of the frame line A->D from the +x axis [deg]")
    branch: Literal["open", "crossed"] = Field(
        "open",
        description="assembly branch: 'open' puts C to the right of the directed line D->B, 'crossed' to the left",
    )
    crank_mass: NonNegative = Field(0.0, description="crank mass, for its weight only [kg]")
    crank_cg: float = Field(0.0, description="distance of the crank's centre of mass from A towards B [m]")
    coupler_mass: NonNegative = Field(0.0, description="coupler mass [kg]")
    coupler_cg: float = Field(0.0, description="distance of the coupler's centre of mass from B towards C [m]")
    coupler_inertia: NonNegative = Field(0.0, description="coupler moment of inertia about its centre of mass [kg m^2]")
    rocker_mass: NonNegative = Field(0.0, description="rocker mass [kg]")
    rocker_cg: float = Field(0.0, description="distance of the rocker's centre of mass from D towards C [m]")
    rocker_inertia: NonNegative = Field(0.0, description="rocker moment of inertia about its centre of mass [kg m^2]")


class WalkingBeam(SceneModel):
    """Eight-bar walking-beam transport mechanism (source 004, docs/linkages.md): a four-bar O1 A B O2 whose
    coupler point C drives, through two parallelograms, a shuttle bar C D in reciprocating translation.

    Crank O1A about O1 = (0, 0), A = crank e^{i phi}; rocker O2B about O2 = frame e^{i th1}; loop closure
    `a e^{i th2} + b e^{i th3} = d e^{i th1} + c e^{i th4}` with th2 = phi; C = A + p e^{i (th3 + delta)};
    O3 = O2 + s, E = B + s, D = C + s with the beam vector s = beam_length e^{i beta}. The output coordinate
    (for shuttle_* loads and the x_shuttle column) is the shuttle bar's horizontal position x_C."""

    type: Literal["walking_beam"]
    crank: Positive = Field(description="crank length a = O1A (paper's link 1) [m]")
    coupler: Positive = Field(
        description="coupler length b = AB (link 2, from the crank pin A to the rocker pin B) [m]"
    )
    rocker: Positive = Field(description="rocker length c = O2B (link 3), and of the parallel rocker O3E (link 5) [m]")
    frame: Positive = Field(description="frame length d = O1O2, crank pivot to rocker pivot [m]")
    frame_angle_deg: float = Field(0.0, description="direction th1 of the frame line O1->O2 from the +x axis [deg]")
    branch: Literal["open", "crossed"] = Field(
        "open",
        description="assembly branch of the four-bar: 'open' puts B to "
        "the right of the directed line O2->A, 'crossed' "
        "to the left",
    )
    coupler_point: Positive = Field(
        description="distance p = AC from the crank pin A to the coupler point C, where the shuttle bar is pinned [m]"
    )
    coupler_point_angle_deg: float = Field(
        0.0, description="angle delta from the line A->B to the line A->C, counter-clockwise [deg]"
    )
    beam_length: Positive = Field(
        description="length L of the shuttle bar CD, equal to O2O3 and BE (the parallelograms' long sides) [m]"
    )
    beam_angle_deg: float = Field(0.0, description="direction beta of O2->O3 (and C->D, B->E) from the +x axis [deg]")
    crank_mass: NonNegative = Field(0.0, description="crank mass, for its weight only [kg]")
    crank_cg: float = Field(0.0, description="distance of the crank's centre of mass from O1 towards A [m]")
    coupler_mass: NonNegative = Field(0.0, description="coupler (triangle ABC) mass [kg]")
    coupler_cg: NonNegative = Field(0.0, description="distance of the coupler's centre of mass from A [m]")
    coupler_cg_angle_deg: float = Field(
        0.0,
        description="angle from the line A->B to the line from A to the coupler's "
        "centre of mass, counter-clockwise [deg]",
    )
    coupler_inertia: NonNegative = Field(0.0, description="coupler moment of inertia about its centre of mass [kg m^2]")
    rocker_mass: NonNegative = Field(0.0, description="mass of each of the two rockers O2B and O3E [kg]")
    rocker_cg: float = Field(
        0.0, description="distance of each rocker's centre of mass from its pivot towards B (E) [m]"
    )
    rocker_inertia: NonNegative = Field(
        0.0, description="moment of inertia of each rocker about its centre of mass [kg m^2]"
    )
    tie_mass: NonNegative = Field(0.0, description="mass of the tie BE (link 4, translates with B) [kg]")
    side_mass: NonNegative = Field(0.0, description="mass of the side link ED (link 6, parallel to BC) [kg]")
    side_cg: float = Field(0.0, description="distance of the side link's centre of mass from E towards D [m]")
    side_inertia: NonNegative = Field(
        0.0, description="side link's moment of inertia about its centre of mass [kg m^2]"
    )
    shuttle_mass: NonNegative = Field(
        0.0, description="mass of the shuttle bar CD (link 7, translates with C) with what it carries [kg]"
    )


Point = Annotated[list[float], Field(min_length=2, max_length=2)]
MAX_LINKS = 60  # moving links of a linkage (a press or a loom has under 20): its analysis stays well under 1 s
MAX_LINK_POINTS = 50  # points of one link


class LinkageLink(SceneModel):
    """A moving link of a linkage: its points in its own coordinates, its mass and inertia."""

    points: dict[str, Point] = Field(
        min_length=1,
        max_length=MAX_LINK_POINTS,
        description="the link's points by name, [x, y] in its own "
        "coordinates: every joint of the link has its point "
        "of the joint's name; points of interest may be added [m]",
    )
    mass: NonNegative = Field(0.0, description="link mass [kg]")
    centre: Point = Field([0.0, 0.0], description="centre of mass [x, y] in the link's coordinates [m]")
    inertia: NonNegative = Field(0.0, description="moment of inertia about the centre of mass [kg m^2]")


class LinkageJoint(SceneModel):
    """A lower pair between two links (both have a point of the joint's name), or a gear pair (docs/linkages.md
    "Gears")."""

    type: Literal["revolute", "prismatic", "gear"] = Field(
        description="revolute: the two links' points coincide; prismatic: the second link's point slides on a line of "
        "the first; gear: the two links' gears mesh"
    )
    links: list[str] = Field(
        min_length=2, max_length=2, description="the two links ('frame' for the frame); prismatic: [guide, slider]"
    )
    direction_deg: float = Field(
        0.0,
        description="prismatic: direction of the guide line through the guide's point, "
        "in the guide's coordinates [deg]",
    )
    slider_angle_deg: float = Field(0.0, description="prismatic: the slider's angle minus the guide's (constant) [deg]")
    teeth: list[Annotated[int, Field(gt=0)]] | None = Field(
        None, min_length=2, max_length=2, description="gear: the tooth numbers of the two links' gears (or radii)"
    )
    radii: list[Annotated[float, Field(gt=0.0)]] | None = Field(
        None, min_length=2, max_length=2, description="gear: the pitch radii of the two links' gears [m]"
    )
    internal: bool = Field(False, description="gear: the larger gear is a ring with internal teeth")
    centres: list[str] | None = Field(
        None, min_length=2, max_length=2, description="gear: the names of the gears' centre points on the two links"
    )
    carrier: str = Field(
        "frame",
        description="gear: the link on which both centres stay (the arm of an epicyclic "
        "train; the frame for fixed axes)",
    )
    phase_deg: float = Field(
        0.0,
        description="gear: theta_b - theta_c - k (theta_a - theta_c) [deg]: the second "
        "link's angle when the first and the carrier are at 0",
    )

    @model_validator(mode="after")
    def _gear_keys(self) -> LinkageJoint:
        gear_keys = sorted(
            key
            for key in ("teeth", "radii", "centres", "internal", "carrier", "phase_deg")
            if getattr(self, key) != LinkageJoint.model_fields[key].default
        )
        if self.type != "gear" and gear_keys:
            raise ValueError(f"{gear_keys} belong to a gear; this joint is {self.type}")
        if self.type == "gear" and (self.centres is None or (self.teeth is None) == (self.radii is None)):
            raise ValueError("a gear needs centres (its two centre points) and exactly one of teeth and radii")
        if self.type == "gear" and self.internal and (self.teeth or self.radii)[0] == (self.teeth or self.radii)[1]:
            raise ValueError(
                f"an internal gear pair of equal gears {self.teeth or self.radii}; expected a ring larger "
                "than its pinion"
            )
        return self


class CamSegment(SceneModel):
    """One part of a cam's turn (docs/theory.md §5.7): the follower rises, dwells or returns by a law."""

    motion: Literal["rise", "dwell", "return"] = Field(description="rise (away from the cam), dwell or return")
    angle_deg: Positive = Field(description="the cam angle the segment takes [deg]; the segments fill 360 deg")
    law: Literal["uniform", "harmonic", "cycloidal", "polynomial_345"] | None = Field(
        None, description="rise and return: the normalised law (none for a dwell)"
    )
    lift: NonNegative = Field(
        0.0, description="rise and return: the follower's travel over the segment [m; rad for an oscillating follower]"
    )

    @model_validator(mode="after")
    def _complete(self) -> CamSegment:
        if self.motion == "dwell" and (self.law is not None or self.lift != 0.0):
            raise ValueError("a dwell segment takes no law and no lift")
        if self.motion != "dwell" and (self.law is None or self.lift <= 0.0):
            raise ValueError(
                f"a {self.motion} segment needs a law (uniform, harmonic, cycloidal, polynomial_345) and a lift > 0"
            )
        return self


class CamTable(SceneModel):
    """A follower's displacement over the cam's turn as a table (a periodic cubic spline through its points)."""

    angle_deg: list[float] = Field(
        min_length=4, max_length=3600, description="cam angles, strictly increasing within one turn [deg]"
    )
    lift: list[float] = Field(
        min_length=4,
        max_length=3600,
        description="the follower's displacement s >= 0 at each angle [m; rad oscillating]",
    )

    @model_validator(mode="after")
    def _table(self) -> CamTable:
        _check_table(self.angle_deg, self.lift, 360.0, "law")
        return self


def _law_form(value) -> str:
    """'segments' (a list) or 'table' (anything else): which form a cam's law is written in."""
    return "segments" if isinstance(value, (list, tuple)) else "table"


CamLaw = Annotated[
    Annotated[list[CamSegment], Tag("segments")] | Annotated[CamTable, Tag("table")], Discriminator(_law_form)
]


class FollowerSpring(SceneModel):
    """The spring that holds a follower on its cam, along the follower's travel."""

    stiffness: NonNegative = Field(description="[N/m; N m/rad for an oscillating follower]")
    preload: NonNegative = Field(description="its force at s = 0, on the base circle [N; N m oscillating]")


class CamJoint(SceneModel):
    """A cam pair (higher pair, docs/linkages.md "Cams"): the cam (the crank) and the link that touches it, the
    follower itself or its roller; the follower's motion law gives the profile."""

    type: Literal["cam"]
    links: list[str] = Field(
        min_length=2,
        max_length=2,
        description="[cam, follower or roller]; the follower is "
        "joined to the frame by one prismatic "
        "(translating) or revolute (oscillating) joint",
    )
    contact: Literal["knife_edge", "roller", "flat_face"] = Field(
        description="what touches the cam: the "
        "follower's point of the joint's name (knife edge; "
        "flat face: a face across its guide through it) or "
        "the roller"
    )
    roller_radius: Positive | None = Field(
        None,
        description="contact roller: the roller's radius [m] (the roller "
        "is links[1], on a revolute joint with its follower)",
    )
    base_radius: Positive = Field(description="the cam profile's least distance from its pivot [m]")
    law: CamLaw = Field(
        description="the follower's displacement s over the turn: a list of segments from "
        "start_deg, or a table {angle_deg, lift}"
    )
    start_deg: float = Field(0.0, description="the crank angle at which the law's first segment starts [deg]")
    spring: FollowerSpring | None = Field(None, description="the follower's spring (none: no spring)")

    @model_validator(mode="after")
    def _roller(self) -> CamJoint:
        if (self.contact == "roller") != (self.roller_radius is not None):
            raise ValueError("roller_radius is given exactly when contact is roller")
        return self


class LinkageOutput(SceneModel):
    """The output coordinate q on which output-link loads act: a prismatic joint's travel (slider_* loads) or a
    link's angle (rocker_* loads)."""

    joint: str | None = Field(
        None,
        description="a prismatic joint: q = its slider's travel along the guide direction from the guide's point [m]",
    )
    link: str | None = Field(None, description="a moving link: q = its angle [rad]")

    @model_validator(mode="after")
    def _one(self) -> LinkageOutput:
        if (self.joint is None) == (self.link is None):
            raise ValueError("output: give exactly one of joint (a prismatic joint's travel) and link (a link's angle)")
        return self


class Linkage(SceneModel):
    """A general planar linkage (docs/linkages.md): links with their points, joints, the driving crank. It must
    have one degree of freedom and decompose into the crank and class-II Assur groups (RRR, RRP, RPR, PRP, RPP),
    which are solved in closed form from the crank outward; a link with point p has it at r + p e^{i theta}."""

    type: Literal["linkage"]
    frame: dict[str, Point] = Field(
        min_length=1,
        max_length=MAX_LINK_POINTS,
        description="the frame's points by name, [x, y] in the global "
        "coordinates (the crank axis need not be at the origin) [m]",
    )
    links: dict[str, LinkageLink] = Field(min_length=1, max_length=MAX_LINKS, description="the moving links by name")
    joints: dict[str, Annotated[LinkageJoint | CamJoint, Field(discriminator="type")]] = Field(
        min_length=1, max_length=2 * MAX_LINKS, description="the joints by name"
    )
    crank: str = Field(
        description="the driving link: it turns with the crank angle phi about its revolute joint "
        "with the frame, theta_crank = phi; its mass and inertia count in J(phi)"
    )
    branches: dict[str, Literal[1, -1]] = Field(
        default_factory=dict,
        description="assembly branch of a group, by its "
        "internal joint: RRR +1 puts that joint left of the line from the outer "
        "joint of the group's link listed first in links to the other's; RRP +1 further along the guide; "
        "RPR +1 with the slider's pivot ahead of the guide's along the guide; "
        "an oscillating cam follower, by its cam pair: +1 with its contact "
        "point left of the line from its pivot to the cam's; default +1",
    )
    points: list[str] = Field(
        default_factory=list,
        description="points of interest (names of link points) whose motion `kinematics` reports besides the joints",
    )
    output: LinkageOutput | None = Field(
        None,
        description="output coordinate for slider_* (a prismatic joint) or "
        "rocker_* (a link) loads; none = no output loads",
    )

    @property
    def output_kind(self) -> str | None:
        """'slider' (output joint), 'rocker' (output link) or None: the loads the output takes."""
        return None if self.output is None else ("slider" if self.output.joint is not None else "rocker")

    @model_validator(mode="after")
    def _no_moving_frame(self) -> Linkage:
        if "frame" in self.links:
            raise ValueError("links has a link named 'frame'; that name is the frame's (give its points under frame:)")
        return self


Mechanism = Annotated[CrankSlider | FourBar | WalkingBeam | Linkage, Field(discriminator="type")]


# --------------------------------------------------------------------------------------------
# Drives (positive moments drive the crank)


class ConstantDrive(SceneModel):
    type: Literal["constant"]
    torque: float = Field(description="driving moment M_d on the crank, signed [N m]")


class LinearMotor(SceneModel):
    """Motor with a linear characteristic M = stall_torque * (1 - omega / no_load_speed)."""

    type: Literal["linear_motor"]
    stall_torque: Positive = Field(description="starting (stall) moment M0 at omega = 0 [N m]")
    no_load_speed: Positive = Field(description="speed omega0 at which the moment falls to zero [rad/s]")


class _TorqueTable(SceneModel):
    """Periodic table of a moment over the crank angle, linear between points."""

    angle_deg: list[float] = Field(min_length=2, description="crank angles of the table points [deg]")
    torque: list[float] = Field(min_length=2, description="driving moment at each angle, signed [N m]")
    period_deg: Positive = Field(
        360.0, description="period of the table in crank angle (720 for a four-stroke cycle) [deg]"
    )

    @model_validator(mode="after")
    def _table(self) -> _TorqueTable:
        _check_table(self.angle_deg, self.torque, self.period_deg, "torque table")
        return self


class TableDrive(_TorqueTable):
    """Periodic table of the driving moment over the crank angle, linear between points."""

    type: Literal["table"]


class Engine(SceneModel):
    """Gas force of an engine cylinder acting on the slider of a crank–slider: F_x = -p(angle) * area."""

    type: Literal["engine"]
    bore: Positive = Field(description="cylinder bore; the piston area is pi bore^2 / 4 [m]")
    angle_deg: list[float] = Field(
        min_length=2,
        description="cycle angles of the indicator-diagram points, 0 = a top dead centre at the start of intake [deg]",
    )
    pressure: list[float] = Field(min_length=2, description="gauge gas pressure at each cycle angle [Pa]")
    cycle_deg: Literal[360.0, 720.0] = Field(
        720.0, description="length of the working cycle: 720 four-stroke, 360 two-stroke [deg]"
    )
    phase_deg: float = Field(0.0, description="cycle angle (of cylinder 1) at crank angle phi = 0 [deg]")
    firing_order: list[int] | None = Field(
        None,
        description="multi-cylinder engine: the order in which the cylinders "
        "fire, e.g. [1, 3, 4, 2]; each fires at its first top "
        "dead centre after the previous one [-]",
    )
    firing_deg: list[float] | None = Field(
        None,
        description="multi-cylinder engine, instead of firing_order: each "
        "cylinder's firing delay after cylinder 1, the first 0; "
        "its cycle angle is cylinder 1's at phi - delay [deg]",
    )

    @model_validator(mode="after")
    def _table(self) -> Engine:
        _check_table(self.angle_deg, self.pressure, self.cycle_deg, "engine pressure")
        if self.firing_order is not None and self.firing_deg is not None:
            raise ValueError("give either firing_order or firing_deg, not both")
        return self


Drive = Annotated[ConstantDrive | LinearMotor | TableDrive | Engine, Field(discriminator="type")]


# --------------------------------------------------------------------------------------------
# Loads


class ConstantLoad(SceneModel):
    type: Literal["constant"]
    torque: NonNegative = Field(
        description="resisting moment M_c, acting against the working direction: moment = -torque [N m]"
    )


class ViscousLoad(SceneModel):
    type: Literal["viscous"]
    coefficient: NonNegative = Field(description="viscous coefficient c on the crank: moment = -c omega [N m s/rad]")


class FanLoad(SceneModel):
    type: Literal["fan"]
    coefficient: NonNegative = Field(description="fan coefficient k: moment = -k omega |omega| [N m s^2/rad^2]")


class TableLoad(_TorqueTable):
    """Periodic table of the resisting moment over the crank angle, linear between points."""

    type: Literal["table"]
    torque: list[float] = Field(min_length=2, description="resisting moment at each angle: moment = -torque [N m]")


class CuttingLoad(SceneModel):
    """On-off technological load (the lathe of docs/theory.md §3.6): -torque inside the intervals, 0 outside."""

    type: Literal["cutting"]
    torque: NonNegative = Field(description="resisting moment while cutting, F r [N m]")
    intervals_deg: list[list[float]] = Field(
        min_length=1, description="crank-angle intervals [start, end) in which the tool cuts, within one period [deg]"
    )
    period_deg: Positive = Field(360.0, description="period of the cutting pattern [deg]")

    @model_validator(mode="after")
    def _intervals(self) -> CuttingLoad:
        flat = []
        for interval in self.intervals_deg:
            if len(interval) != 2 or interval[1] <= interval[0]:
                raise ValueError(f"intervals_deg entry {interval} must be [start, end] with end > start")
            flat += interval
        if any(b < a for a, b in zip(flat, flat[1:])) or flat[-1] - flat[0] > self.period_deg:
            raise ValueError(
                f"intervals_deg = {self.intervals_deg} must be sorted, not overlap, and lie within "
                f"one period ({self.period_deg} deg)"
            )
        return self


class SliderConstant(SceneModel):
    type: Literal["slider_constant", "shuttle_constant"]
    force: float = Field(
        description="constant force along +x on the slider, or on the shuttle bar of a walking beam, signed [N]"
    )


class RockerConstant(SceneModel):
    type: Literal["rocker_constant"]
    torque: float = Field(description="constant moment on the rocker, counter-clockwise positive, signed [N m]")


class OutputViscous(SceneModel):
    type: Literal["slider_viscous", "rocker_viscous", "shuttle_viscous"]
    coefficient: NonNegative = Field(
        description="viscous coefficient on the slider, -c v [N s/m], on the rocker, "
        "-c omega_rocker [N m s/rad], or on the shuttle bar's horizontal "
        "motion, -c v_x [N s/m]"
    )


class OutputSpring(SceneModel):
    type: Literal["slider_spring", "rocker_spring", "shuttle_spring"]
    stiffness: NonNegative = Field(
        description="spring stiffness on the slider, -k (x - x0) [N/m], on the rocker, "
        "-k (theta4 - theta0) [N m/rad], or on the shuttle bar, horizontal, "
        "-k (x_C - x0) [N/m]"
    )
    free_position: float = Field(
        0.0, description="free slider (or shuttle point C) position x0 [m], or free rocker angle theta0 [rad]"
    )


class SliderTable(SceneModel):
    """Force on the slider tabulated over its position, linear between points, constant beyond the ends."""

    type: Literal["slider_table"]
    position: list[float] = Field(min_length=2, description="slider positions x, strictly increasing [m]")
    force: list[float] = Field(min_length=2, description="signed force along +x at each position [N]")

    @model_validator(mode="after")
    def _table(self) -> SliderTable:
        if len(self.position) != len(self.force):
            raise ValueError(
                f"slider_table: {len(self.position)} positions but {len(self.force)} forces; "
                "expected one force per position"
            )
        if any(b <= a for a, b in zip(self.position, self.position[1:])):
            raise ValueError(f"slider_table: position = {self.position} must be strictly increasing")
        return self


Load = Annotated[
    ConstantLoad
    | ViscousLoad
    | FanLoad
    | TableLoad
    | CuttingLoad
    | SliderConstant
    | RockerConstant
    | OutputViscous
    | OutputSpring
    | SliderTable,
    Field(discriminator="type"),
]


DrivenLoad = Annotated[
    ConstantLoad
    | ViscousLoad
    | FanLoad
    | TableLoad
    | SliderConstant
    | RockerConstant
    | OutputViscous
    | OutputSpring
    | SliderTable,
    Field(discriminator="type"),
]
BranchLoad = Annotated[ConstantLoad | ViscousLoad | FanLoad, Field(discriminator="type")]

# The mechanism a load on its output (type slider_*, rocker_*, shuttle_*) needs.
OUTPUT_MECHANISM = {"slider": "crank_slider", "rocker": "four_bar", "shuttle": "walking_beam"}


def _check_loads_fit(loads: list, mechanism: Mechanism | None, key: str, owner: str) -> None:
    """Raise ValueError for a load on a mechanism's output whose mechanism (OUTPUT_MECHANISM) the owner (the
    machine or its driven part) does not have; key prefixes the scene keys named ('' or 'driven.')."""
    kind = mechanism.type if mechanism is not None else None
    for index, load in enumerate(loads):
        prefix = load.type.split("_")[0]
        needed = OUTPUT_MECHANISM.get(prefix)
        if needed is None or kind == needed or (kind == "linkage" and mechanism.output_kind == prefix):
            continue
        if kind == "linkage":
            has = {None: "no output", "slider": "output.joint", "rocker": "output.link"}[mechanism.output_kind]
            wanted = {"slider": "output.joint (a prismatic joint)", "rocker": "output.link"}.get(prefix)
            raise ValueError(
                f"{key}loads[{index}] type '{load.type}' acts on the {prefix}: the linkage needs "
                f"{key}mechanism.{wanted or f'type: {needed}'} (it has {has})"
            )
        raise ValueError(
            f"{key}loads[{index}] type '{load.type}' acts on the {prefix}: it needs "
            f"{key}mechanism.type: {needed} ({owner} has {kind or 'no mechanism'})"
        )


class Branch(SceneModel):
    """A branch of a branched drive (docs/theory.md §7.4): a working member driven from the
    driven part's main shaft through a ratio i_1n, with its own inertia and resisting moments on its shaft."""

    name: str = Field(
        pattern=r"^[A-Za-z_][A-Za-z0-9_]*$",
        description="name of the branch, used in the output columns M_section_<name> (letters, digits, _)",
    )
    inertia: Positive = Field(
        description="moment of inertia I_n of everything beyond the branch's section, reduced "
        "to the branch's shaft [kg m^2]"
    )
    ratio: Positive = Field(
        description="ratio i_1n = omega_main / omega_n from the main shaft to the branch's shaft; "
        "the branch adds I_n / i_1n^2 to the main shaft's inertia [-]"
    )
    loads: list[BranchLoad] = Field(
        default_factory=list,
        description="resisting moments on the branch's shaft, of "
        "its speed omega_n = omega_driven / i_1n "
        "(constant, viscous, fan)",
    )


class DrivenPart(SceneModel):
    """The driven part of a two-mass machine (docs/theory.md §7.1): a rotor with its own resisting moments,
    turning at omega_driven, angle phi_driven = phi - twist, optionally with a mechanism on its shaft (then
    I2(phi_driven) = inertia + the links' reduced inertia), and branches; the scenario's external load acts on
    it. Its constant loads and the external load are Coulomb resistances: they oppose the motion and, at rest,
    hold the part up to their sum (it breaks away when the moment passed to it exceeds them)."""

    inertia: Positive = Field(
        description="constant part of the moment of inertia I2 of the driven part, reduced to the crank shaft [kg m^2]"
    )
    mechanism: Mechanism | None = Field(
        None,
        description="linkage driven by the driven shaft (its crank angle is "
        "phi_driven); adds its links' reduced inertia and weight "
        "(machine.gravity)",
    )
    loads: list[DrivenLoad] = Field(
        default_factory=list,
        description="resisting moments on the driven part, read "
        "at phi_driven and omega_driven (constant, "
        "viscous, fan, table in phi_driven, and "
        "slider/rocker loads of its mechanism)",
    )
    branches: list[Branch] = Field(
        default_factory=list,
        description="working members driven from the driven part's shaft (a branched drive), each with its ratio",
    )

    @model_validator(mode="after")
    def _loads_fit_mechanism(self) -> DrivenPart:
        names = [branch.name for branch in self.branches]
        repeated = sorted({name for name in names if names.count(name) > 1})
        if repeated:
            raise ValueError(f"branches: the name(s) {repeated} appear more than once; expected distinct names")
        _check_loads_fit(self.loads, self.mechanism, "driven.", "the driven part")
        return self


class CouplingCharacteristic(SceneModel):
    """Nonlinear elastic characteristic M_m(twist) of a coupling: a table, linear between points; beyond the
    table the end segments continue (the coupling keeps its end stiffness)."""

    twist: list[float] = Field(
        min_length=2,
        description="twists phi - phi_driven of the table points, strictly increasing, with a point at 0 [rad]",
    )
    moment: list[float] = Field(
        min_length=2,
        description="elastic moment the coupling passes at each twist, strictly increasing, 0 at twist 0 [N m]",
    )

    @model_validator(mode="after")
    def _elastic(self) -> CouplingCharacteristic:
        if len(self.twist) != len(self.moment):
            raise ValueError(
                f"characteristic: twist has {len(self.twist)} entries but moment has "
                f"{len(self.moment)}; expected one moment per twist"
            )
        if any(b <= a for a, b in zip(self.twist, self.twist[1:])):
            raise ValueError(f"characteristic: twist = {self.twist} rad must be strictly increasing")
        if 0.0 not in self.twist or self.moment[self.twist.index(0.0)] != 0.0:
            raise ValueError(
                f"characteristic: twist = {self.twist} rad, moment = {self.moment} N m; expected the "
                "point twist 0 -> moment 0 (an untwisted coupling passes no moment)"
            )
        falls = [i for i, (a, b) in enumerate(zip(self.moment, self.moment[1:])) if b <= a]
        if falls:
            i = falls[0]
            raise ValueError(
                f"characteristic: moment does not rise from twist {self.twist[i]} to {self.twist[i + 1]} "
                f"rad ({self.moment[i]} -> {self.moment[i + 1]} N m); expected a strictly increasing "
                "moment (positive stiffness everywhere: a falling characteristic has no stable "
                "equilibrium)"
            )
        return self


class Coupling(SceneModel):
    """Elastic coupling between the crank (driving part) and the driven part: it passes the moment
    M_m = M_elastic(twist) + damping * (omega - omega_driven), twist = phi - phi_driven, with M_elastic =
    stiffness * twist (linear) or the tabulated characteristic."""

    stiffness: Positive | None = Field(
        None, description="torsional stiffness k of a linear coupling; give this or characteristic [N m/rad]"
    )
    characteristic: CouplingCharacteristic | None = Field(
        None, description="nonlinear elastic characteristic M_elastic(twist); give this or stiffness"
    )
    damping: NonNegative = Field(0.0, description="torsional damping c of the coupling [N m s/rad]")
    driven: DrivenPart = Field(description="the driven part")

    @model_validator(mode="after")
    def _one_characteristic(self) -> Coupling:
        if (self.stiffness is None) == (self.characteristic is None):
            given = "both" if self.stiffness is not None else "neither"
            raise ValueError(
                f"coupling: {given} of stiffness and characteristic given; expected exactly one "
                "(stiffness [N m/rad] for a linear coupling, characteristic {twist, moment} for a "
                "nonlinear one)"
            )
        return self


class Journal(SceneModel):
    """A revolute joint's journal: its friction moment is M_f = lambda_p f' r |R| (docs/theory.md §6.2)."""

    radius: Positive = Field(description="journal (pin) radius r [m]")
    fit: Literal["clearance", "new", "run_in"] = Field(
        "clearance",
        description="pressure distribution over the "
        "journal: 'clearance' (lambda_p = 1), "
        "'new' close fit (pi/2), 'run_in' "
        "(4/pi) [-]",
    )


class Journals(SceneModel):
    """The revolute joints that have friction, by name; a joint left out turns without friction."""

    crank_bearing: Journal | None = Field(None, description="the crank's bearing A in the frame (both mechanisms)")
    crank_pin: Journal | None = Field(None, description="the crank pin B between crank and rod / coupler")
    wrist_pin: Journal | None = Field(None, description="crank_slider: the wrist pin C between rod and slider")
    rocker_pin: Journal | None = Field(None, description="four_bar: the pin C between coupler and rocker")
    rocker_bearing: Journal | None = Field(None, description="four_bar: the rocker's bearing D in the frame")


class ThrustCollar(SceneModel):
    """An annular thrust collar on the crank shaft carrying an axial load."""

    inner_radius: NonNegative = Field(description="inner radius r1 of the bearing ring [m]")
    outer_radius: Positive = Field(description="outer radius r2 of the bearing ring [m]")
    axial_load: NonNegative = Field(description="axial load Q on the collar [N]")
    state: Literal["new", "run_in"] = Field(
        "run_in",
        description="'new' (uniform pressure): M_f = 2/3 f Q (r2^3 - "
        "r1^3)/(r2^2 - r1^2); 'run_in' (uniform wear): "
        "M_f = f Q (r1 + r2)/2 [-]",
    )

    @model_validator(mode="after")
    def _ring(self) -> ThrustCollar:
        if self.inner_radius >= self.outer_radius:
            raise ValueError(
                f"thrust_collar: inner_radius = {self.inner_radius} m must be smaller than outer_radius "
                f"= {self.outer_radius} m"
            )
        return self


class JointFriction(SceneModel):
    """Coulomb friction in the joints, from the joint reactions of the kinetostatic analysis at every step
    (docs/theory.md §6.5; docs/joint_friction.md)."""

    coefficient: Positive = Field(description="coefficient of sliding friction f of the joints and the collar [-]")
    joints: Journals = Field(default_factory=Journals, description="the revolute joints with friction")
    journals: dict[str, Journal] = Field(
        default_factory=dict, description="linkage: its revolute joints with friction, by the joint's name"
    )
    guide: NonNegative = Field(
        0.0,
        description="crank_slider: coefficient of sliding friction of the slider on its "
        "guide, force f |N|; linkage: of every prismatic joint; 0 = none [-]",
    )
    thrust_collar: ThrustCollar | None = Field(None, description="optional thrust collar on the crank shaft")


JOINTS_OF = {
    "crank_slider": ("crank_bearing", "crank_pin", "wrist_pin"),
    "four_bar": ("crank_bearing", "crank_pin", "rocker_pin", "rocker_bearing"),
}
# Mechanisms whose kinetostatics is not built: only a thrust_collar can have friction.
NO_KINETOSTATICS = ("walking_beam", "multi-cylinder crank_slider")


class Clutch(SceneModel):
    """Friction (Coulomb) clutch between the crank side (machine.inertia, the motor of machine.drive) and the
    driven part: slipping it passes +-kinetic_torque (the sign of the slip); stuck, the two turn together and
    it passes the moment that keeps them together, as long as that stays within +-static_torque."""

    static_torque: Positive = Field(description="largest moment the stuck clutch can pass (static friction) [N m]")
    kinetic_torque: Positive = Field(
        description="moment the slipping clutch passes (kinetic friction); at most static_torque [N m]"
    )
    driven: DrivenPart = Field(description="the driven part (the working machine) behind the clutch")

    @model_validator(mode="after")
    def _kinetic_below_static(self) -> Clutch:
        if self.kinetic_torque > self.static_torque:
            raise ValueError(
                f"kinetic_torque = {self.kinetic_torque} N m exceeds static_torque = "
                f"{self.static_torque} N m; expected kinetic_torque <= static_torque"
            )
        if self.driven.mechanism is not None:
            raise ValueError(
                f"clutch.driven.mechanism ({self.driven.mechanism.type}): a driven part behind a clutch "
                "has no angle of its own in the state (only omega_driven), so it cannot carry a "
                "mechanism; expected a rotor (drop driven.mechanism, or use machine.coupling)"
            )
        for index, load in enumerate(self.driven.loads):
            if load.type not in ("constant", "viscous", "fan"):
                raise ValueError(
                    f"clutch.driven.loads[{index}] type '{load.type}' reads the driven part's angle, "
                    "which a driven part behind a clutch does not have; expected constant, viscous or "
                    "fan (angle-dependent driven loads need machine.coupling)"
                )
        return self


class Machine(SceneModel):
    """The machine reduced to its driving link (the crank)."""

    inertia: NonNegative = Field(
        description="constant part J0 of the reduced inertia about the crank axis (rotor, "
        "gears, a preset's crank; a linkage's crank counts in its link) [kg m^2]"
    )
    flywheel: Flywheel | None = Field(None, description="optional flywheel; adds inertia * ratio^2")
    gravity: list[float] | None = Field(
        None,
        min_length=2,
        max_length=2,
        description="gravity vector [gx, gy] in the mechanism plane; weights of the "
        "links become reduced moments [m/s^2]",
    )
    mechanism: Mechanism | None = Field(None, description="linkage driven by the crank; without one J is constant")
    drive: Drive | None = Field(None, description="driving moment M_d")
    loads: list[Load] = Field(default_factory=list, description="resisting moments and forces M_c")
    coupling: Coupling | None = Field(
        None,
        description="optional elastic coupling to a driven part (two-mass "
        "machine); the external load then acts on the driven part",
    )
    joint_friction: JointFriction | None = Field(
        None, description="optional friction in the mechanism's joints and a thrust collar (the most expensive effect)"
    )
    clutch: Clutch | None = Field(
        None,
        description="optional friction clutch to a driven part (motor and working "
        "machine); the external load then acts on the driven part",
    )

    def analysed_mechanism(self) -> tuple[Mechanism | None, bool]:
        """The mechanism whose kinematics and structure the commands analyse and the recording draws, and whether
        it is the driven part's: the machine's own, else the one behind a coupling, else None."""
        if self.mechanism is None and self.coupling is not None and self.coupling.driven.mechanism is not None:
            return self.coupling.driven.mechanism, True
        return self.mechanism, False

    @model_validator(mode="after")
    def _effects_fit_mechanism(self) -> Machine:
        kind = self.mechanism.type if self.mechanism is not None else None
        _check_loads_fit(self.loads, self.mechanism, "", "the machine")
        if isinstance(self.drive, Engine) and kind != "crank_slider":
            raise ValueError(
                f"drive type 'engine' pushes a piston: it needs mechanism.type: crank_slider "
                f"(the machine has {kind or 'no mechanism'})"
            )
        self._cylinders_fit_effects()
        flywheel = self.flywheel.inertia * self.flywheel.ratio**2 if self.flywheel else 0.0
        if self.inertia + flywheel <= 0 and self.mechanism is None:
            raise ValueError("the machine has no inertia: give machine.inertia > 0 or a flywheel")
        if self.joint_friction is not None:
            several = kind == "crank_slider" and self.mechanism.cylinders is not None
            _check_joint_friction(self.joint_friction, "multi-cylinder crank_slider" if several else kind)
            if kind == "linkage":
                _check_linkage_journals(self.joint_friction, self.mechanism)
        if self.joint_friction is not None and self.clutch is not None:
            raise ValueError(
                "machine.joint_friction with machine.clutch: the joint friction solves the crank's own "
                "equation, which a stuck clutch joins to the driven part; expected one of them"
            )
        if self.coupling is not None and self.clutch is not None:
            raise ValueError(
                "machine.coupling and machine.clutch are both set; the driven part sits behind one of "
                "them: expected either an elastic coupling or a friction clutch"
            )
        return self

    def _cylinders_fit_effects(self) -> None:
        """Several cylinders: forces on "the slider" are ambiguous (refused); firing keys need cylinders (that the
        firing fits the crankshaft is the mechanisms' check, mechanisms/checks.py)."""
        cylinders = self.mechanism.cylinders if isinstance(self.mechanism, CrankSlider) else None
        engine = self.drive if isinstance(self.drive, Engine) else None
        if cylinders is None:
            if engine is not None and (engine.firing_order or engine.firing_deg):
                raise ValueError("drive.firing_order / firing_deg need several cylinders: add mechanism.cylinders")
            return
        for index, load in enumerate(self.loads):
            if load.type.startswith("slider"):
                raise ValueError(
                    f"loads[{index}] type '{load.type}' acts on the slider, but the crank–slider has "
                    f"{len(cylinders)} cylinders (mechanism.cylinders): expected loads on the crank "
                    "(constant, viscous, fan, table, cutting)"
                )


def _check_linkage_journals(friction: JointFriction, linkage: Linkage) -> None:
    """A linkage's journals must name its revolute joints and its guide friction needs a prismatic joint (that its
    joint reactions are determinate is the mechanisms' check, mechanisms/checks.py)."""
    revolute = [name for name, joint in linkage.joints.items() if joint.type == "revolute"]
    foreign = [name for name in friction.journals if name not in revolute]
    if foreign:
        raise ValueError(
            f"joint_friction.journals names {foreign}, which are not revolute joints of the linkage; "
            f"expected some of {revolute}"
        )
    if friction.guide > 0.0 and len(revolute) == len(linkage.joints):
        raise ValueError(f"joint_friction.guide = {friction.guide}: the linkage has no prismatic joint to slide in")


def _check_joint_friction(friction: JointFriction, kind: str | None) -> None:
    """The joints named must exist in the mechanism, and something must have friction."""
    if friction.journals and kind != "linkage":
        raise ValueError(
            f"joint_friction.journals names {sorted(friction.journals)}: journals by joint name are a "
            f"linkage's (the machine has {kind or 'no mechanism'}); expected joint_friction.joints"
        )
    named = [name for name in Journals.model_fields if getattr(friction.joints, name) is not None]
    foreign = [name for name in named if name not in JOINTS_OF.get(kind, ())]
    if foreign:
        if kind in NO_KINETOSTATICS:
            expected = (
                f"none: the joint reactions of a {kind} are not computed (kinetostatics exists for a "
                "single crank_slider, the four_bar and a linkage); only a thrust_collar can have friction"
            )
        elif kind is None:
            expected = "none (a machine without a mechanism can only have a thrust_collar)"
        elif kind == "linkage":
            expected = "none: a linkage's journals are joint_friction.journals, by the names of its joints"
        else:
            expected = f"some of {list(JOINTS_OF[kind])}"
        raise ValueError(
            f"joint_friction.joints names {foreign}, which the machine's mechanism ({kind or 'none'}) "
            f"does not have; expected {expected}"
        )
    if friction.guide > 0.0 and kind not in ("crank_slider", "linkage"):
        raise ValueError(
            f"joint_friction.guide = {friction.guide}: only a crank_slider has a guide, or a linkage "
            f"its prismatic joints (the machine has {kind or 'no mechanism'})"
        )
    if not named and not friction.journals and friction.guide == 0.0 and friction.thrust_collar is None:
        raise ValueError("joint_friction has no joints, no guide and no thrust_collar: expected at least one of them")


# --------------------------------------------------------------------------------------------
# Governor (docs/theory.md §8): a centrifugal sensor whose sleeve sets the throttle, directly
# through a valve or indirectly through a pilot valve and a servo-motor. M_d = throttle * M_drive.


class SleeveSpring(SceneModel):
    stiffness: NonNegative = Field(
        description="spring rate k; the spring pushes the sleeve down with k (z - free_position) [N/m]"
    )
    free_position: float = Field(0.0, description="sleeve position z at which the spring is relaxed [m]")


class LinearValve(SceneModel):
    """Throttle linear in the sleeve position between two positions, clipped to 0..1."""

    type: Literal["linear"] = "linear"
    open_at: float = Field(description="sleeve position with the valve fully open, throttle 1 [m]")
    closed_at: float = Field(description="sleeve position with the valve closed, throttle 0 [m]")

    @model_validator(mode="after")
    def _distinct(self) -> LinearValve:
        if self.open_at == self.closed_at:
            raise ValueError(f"open_at = closed_at = {self.open_at} m; expected two different sleeve positions")
        return self


class TableValve(SceneModel):
    """Throttle as a table over the sleeve position, linear between points, held constant beyond them."""

    type: Literal["table"]
    sleeve: list[float] = Field(min_length=2, description="sleeve positions, strictly increasing [m]")
    throttle: list[float] = Field(
        min_length=2, description="throttle at each sleeve position, 0 (closed) to 1 (open) [-]"
    )

    @model_validator(mode="after")
    def _table(self) -> TableValve:
        if len(self.sleeve) != len(self.throttle):
            raise ValueError(
                f"sleeve has {len(self.sleeve)} entries but throttle has {len(self.throttle)}; "
                "expected one throttle value per sleeve position"
            )
        if any(b <= a for a, b in zip(self.sleeve, self.sleeve[1:])):
            raise ValueError(f"sleeve = {self.sleeve} must be strictly increasing")
        if any(not 0.0 <= value <= 1.0 for value in self.throttle):
            raise ValueError(f"throttle = {self.throttle}; expected values between 0 and 1")
        return self


def _valve_type(value) -> str | None:
    return value.get("type", "linear") if isinstance(value, dict) else getattr(value, "type", None)


Valve = Annotated[
    Annotated[LinearValve, Tag("linear")] | Annotated[TableValve, Tag("table")], Discriminator(_valve_type)
]


class _CentrifugalSensor(SceneModel):
    """What every centrifugal sensor has (governors/sensor.py): two balls, a sleeve with its spring, damping and
    friction, a spindle ratio and the sleeve's stroke between hard stops."""

    ball_mass: Positive = Field(description="mass m of each of the two balls [kg]")
    sleeve_mass: NonNegative = Field(0.0, description="sleeve mass M; 0 = Watt's governor [kg]")
    spring: SleeveSpring | None = Field(None, description="optional spring on the sleeve")
    damping: NonNegative = Field(0.0, description="viscous damping on the sleeve, force c z' [N s/m]")
    friction: NonNegative = Field(0.0, description="Coulomb (kinetic) friction force on the moving sleeve [N]")
    static_friction: NonNegative | None = Field(
        None, description="friction force the sleeve must overcome to start moving; none = friction [N]"
    )
    ratio: Positive = Field(1.0, description="spindle speed / crank speed [-]")
    stroke: list[float] = Field(
        [0.01, 0.08],
        min_length=2,
        max_length=2,
        description="sleeve travel [z_low, z_high] between inelastic hard stops [m]",
    )
    gravity: Positive = Field(9.81, description="gravity along the spindle [m/s^2]")

    @model_validator(mode="after")
    def _friction(self) -> _CentrifugalSensor:
        if self.static_friction is not None and self.static_friction < self.friction:
            raise ValueError(
                f"static_friction = {self.static_friction} N is below friction = {self.friction} N; "
                "expected static_friction >= friction"
            )
        return self


class _CentrifugalGovernor(_CentrifugalSensor):
    """Porter-type centrifugal sensor: two balls on arms of length l (links equal to the arms), sleeve rise
    z = 2 l (1 - cos a); Watt's governor is sleeve_mass 0, a spring-loaded one adds a spring."""

    arm_length: Positive = Field(description="arm (and link) length l [m]")

    @model_validator(mode="after")
    def _sensor(self) -> _CentrifugalGovernor:
        low, high = self.stroke
        if not 0.0 < low < high < 2.0 * self.arm_length:
            raise ValueError(
                f"stroke = {self.stroke} m; expected 0 < z_low < z_high < 2 arm_length = {2 * self.arm_length:g} m "
                "(at z = 0 the arms hang along the spindle and the balls have no lever to lift the sleeve; at "
                "z = 2 arm_length the arms are horizontal)"
            )
        return self


class DirectGovernor(_CentrifugalGovernor):
    """Direct action: the sleeve moves the regulating element (valve) itself."""

    type: Literal["direct"]
    valve: Valve = Field(description="throttle as a function of the sleeve position")


def _check_throttle_travel(travel: list[float]) -> None:
    """A travel [low, high] in throttle must lie within 0..1 with low < high."""
    low, high = travel
    if not 0.0 <= low < high <= 1.0:
        raise ValueError(f"travel = {travel}; expected 0 <= low < high <= 1 (throttle)")


class Servo(SceneModel):
    """Hydraulic servo-motor: piston speed proportional to the pilot-valve opening."""

    gain: Positive = Field(description="servo speed per pilot-valve opening: throttle' = -gain * opening [1/(m s)]")
    max_speed: Positive | None = Field(None, description="largest servo speed; none = unlimited [1/s]")
    dead_band: NonNegative = Field(0.0, description="pilot-valve overlap: openings smaller than this move nothing [m]")
    travel: list[float] = Field(
        [0.0, 1.0],
        min_length=2,
        max_length=2,
        description="servo travel [low, high] in throttle, between hard stops, within 0..1 [-]",
    )

    @model_validator(mode="after")
    def _travel(self) -> Servo:
        _check_throttle_travel(self.travel)
        return self


class Feedback(SceneModel):
    """Feedback from the servo to the pilot valve: none (hunts), rigid (droop) or isodromic (astatic)."""

    type: Literal["none", "rigid", "isodromic"] = Field("none", description="kind of feedback")
    gain: NonNegative = Field(0.0, description="pilot-valve shift per unit of servo travel, rho [m]")
    time_constant: Positive | None = Field(None, description="isodromic dashpot time constant T_i [s]")
    reference: float | None = Field(
        None,
        description="rigid feedback: servo position at which the pilot is neutral "
        "at pilot_neutral; none = the throttle that balances the "
        "initial load at the set speed [-]",
    )

    @model_validator(mode="after")
    def _complete(self) -> Feedback:
        if self.type != "none" and self.gain <= 0.0:
            raise ValueError(f"feedback type '{self.type}' needs gain > 0 (got {self.gain}) [m]")
        if self.type == "isodromic" and self.time_constant is None:
            raise ValueError("feedback type 'isodromic' needs time_constant (the dashpot's T_i) [s]")
        return self


class IndirectGovernor(_CentrifugalGovernor):
    """Indirect action: the sleeve moves a pilot valve; a servo-motor moves the regulating element.
    Pilot opening = z - pilot_neutral + feedback; the servo position is the throttle."""

    type: Literal["indirect"]
    pilot_neutral: float = Field(
        description="sleeve position at which the pilot valve is closed; sets the speed the governor holds [m]"
    )
    servo: Servo = Field(description="the servo-motor")
    feedback: Feedback = Field(default_factory=Feedback, description="feedback from the servo to the pilot valve")

    @model_validator(mode="after")
    def _pilot_in_stroke(self) -> IndirectGovernor:
        low, high = self.stroke
        if not low < self.pilot_neutral < high:
            raise ValueError(
                f"pilot_neutral = {self.pilot_neutral} m lies outside the stroke {self.stroke} m; "
                "expected a sleeve position strictly inside it"
            )
        return self


class HartnellGovernor(_CentrifugalSensor):
    """Direct action of a spring-loaded Hartnell sensor (governors/hartnell.py): two bell cranks pivoted at
    pivot_radius on the turning frame, each with a ball on its ball arm (upright at z = 0) and its sleeve arm
    (horizontal at z = 0) under the sleeve, which rises z = sleeve_arm sin theta; the spring pushes it down."""

    type: Literal["hartnell"]
    ball_arm: Positive = Field(description="length a of the bell crank's arm to the ball's centre [m]")
    sleeve_arm: Positive = Field(description="length b of the bell crank's arm to the sleeve [m]")
    pivot_radius: Positive = Field(description="radius r0 of the bell cranks' pivots from the spindle's axis [m]")
    spring: SleeveSpring = Field(description="the spring that pushes the sleeve down")
    stroke: list[float] = Field(
        min_length=2,
        max_length=2,
        description="sleeve travel [z_low, z_high] between inelastic hard stops, from the "
        "position with both arms square to the spindle [m]",
    )
    valve: Valve = Field(description="throttle as a function of the sleeve position")

    @model_validator(mode="after")
    def _sensor(self) -> HartnellGovernor:
        low, high = self.stroke
        if not -self.sleeve_arm < low < high < self.sleeve_arm:
            raise ValueError(
                f"stroke = {self.stroke} m; expected -sleeve_arm < z_low < z_high < sleeve_arm = "
                f"{self.sleeve_arm:g} m (at +-sleeve_arm the sleeve arms stand along the spindle)"
            )
        if self.pivot_radius <= self.ball_arm:
            raise ValueError(
                f"pivot_radius = {self.pivot_radius} m; expected more than ball_arm = {self.ball_arm} m "
                "(the balls would reach the spindle's axis)"
            )
        theta = math.asin(low / self.sleeve_arm)
        spring = self.spring.stiffness * (low - self.spring.free_position)
        pull = self.sleeve_arm * (
            self.sleeve_mass * self.gravity + spring
        ) - 2.0 * self.ball_mass * self.gravity * self.ball_arm * math.tan(theta)
        if pull <= 0.0:
            raise ValueError(
                f"spring = {self.spring.stiffness} N/m free at {self.spring.free_position} m does not "
                f"hold the sleeve down at its low stop z = {low} m against the balls' weights; expected "
                "sleeve_arm (sleeve_mass g + k (z_low - free_position)) > 2 ball_mass g ball_arm "
                "tan(theta_low)"
            )
        return self


class PIGovernor(SceneModel):
    """Electronic PI speed governor (governors/pi.py): it measures the crank speed and sets the throttle valve with
    throttle = x + gain (set_speed - omega) / set_speed within the travel, x' = gain e / integral_time."""

    type: Literal["pi"]
    set_speed: Positive = Field(description="crank speed the governor holds [rad/s]")
    gain: Positive = Field(
        description="proportional gain K_p: throttle per relative speed error (omega_s - omega) / omega_s [-]"
    )
    integral_time: Positive = Field(
        description="integral time T_i: x' = K_p e / T_i; also the anti-windup's tracking time on the valve's stops [s]"
    )
    travel: list[float] = Field(
        [0.0, 1.0], min_length=2, max_length=2, description="valve travel [low, high] in throttle, within 0..1 [-]"
    )

    @model_validator(mode="after")
    def _travel(self) -> PIGovernor:
        _check_throttle_travel(self.travel)
        return self


Governor = Annotated[DirectGovernor | IndirectGovernor | HartnellGovernor | PIGovernor, Field(discriminator="type")]


# --------------------------------------------------------------------------------------------
# Scenario and solver


class InitialState(SceneModel):
    phi: float = Field(0.0, description="initial crank angle [rad]")
    omega: float = Field(0.0, description="initial crank speed [rad/s]")
    sleeve: float | None = Field(
        None,
        description="initial governor sleeve position z, at rest; none = the "
        "equilibrium position at the initial speed [m]",
    )
    servo: float | None = Field(
        None,
        description="initial servo-motor position (throttle, indirect governor); none = "
        "the throttle that balances the initial load at the initial speed [-]",
    )
    twist: float | None = Field(
        None,
        description="initial twist phi - phi_driven of the coupling, driven part turning "
        "at omega; none = the static twist that carries the driven part's "
        "loads at the initial speed [rad]",
    )
    omega_driven: float | None = Field(
        None, description="initial speed of the driven part (behind a coupling or a clutch); none = omega [rad/s]"
    )


class LoadEvent(SceneModel):
    """A change of the external load moment (opposing motion) at a time, as a step or a linear ramp."""

    time: NonNegative = Field(description="time at which the change starts [s]")
    torque: float = Field(description="new external load moment reached at time + ramp; moment = -torque [N m]")
    ramp: NonNegative = Field(0.0, description="duration of a linear ramp to the new value; 0 = step [s]")


class Scenario(SceneModel):
    initial: InitialState = Field(default_factory=InitialState, description="initial state of the crank")
    duration: Positive = Field(description="simulated time [s]")
    external_load: float = Field(
        0.0, description="external load moment at t = 0, opposing motion: moment = -value [N m]"
    )
    load_events: list[LoadEvent] = Field(default_factory=list, description="changes of the external load in time")

    @model_validator(mode="after")
    def _events_in_order(self) -> Scenario:
        end_previous = 0.0
        for index, event in enumerate(self.load_events):
            if event.time < end_previous:
                raise ValueError(
                    f"load_events[{index}].time = {event.time} s starts before the previous change ends "
                    f"({end_previous} s); expected events in time order that do not overlap"
                )
            end_previous = event.time + event.ramp
            if end_previous > self.duration:
                raise ValueError(
                    f"load_events[{index}] ends at {end_previous} s, after the scenario's duration {self.duration} s"
                )
        return self


DEFAULT_EXCHANGE_STEP = 0.02  # [s] run's exchange step unless a scene sets solver.exchange_step (docs/ros.md, "Speed")


class Solver(SceneModel):
    method: Literal["RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA", "RK4", "Rosenbrock23", "energy"] = Field(
        "DOP853",
        description="scipy.integrate method (adaptive, in time), RK4 (fixed step in time), Rosenbrock23 (the "
        "stiff method of the fast path only) or energy (the textbook energy method, fixed step "
        "in phi)",
    )
    path: Literal["auto", "reference", "fast"] = Field(
        "auto",
        description="auto: a command (simulate, sweep, flywheel, run, the nodes) runs the fast path where it "
        "covers the scene and is compiled on this machine, else the reference path with a "
        "one-line note (a first run starts compiling it in the background; run compiles it "
        "first); the library's "
        "simulate() runs auto on the reference path. reference: the pure-Python right-hand side "
        "stepped by scipy; fast: the scene's right-hand side compiled by numba (cached on disk) "
        "and stepped by compiled RK45, DOP853, RK4 or Rosenbrock23 (docs/speed.md)",
    )
    rtol: Positive = Field(1e-8, description="relative tolerance of the adaptive methods [-]")
    atol: Positive = Field(
        1e-10, description="absolute tolerance of the adaptive methods, on phi [rad] and omega [rad/s]"
    )
    max_step: Positive | None = Field(None, description="largest step of the adaptive methods; none = unlimited [s]")
    step: Positive = Field(1e-4, description="time step of RK4 [s]")
    phi_step_deg: Positive = Field(1.0, description="crank-angle step of the energy method [deg]")
    sample_rate: Positive = Field(1000.0, description="rate of the output samples (dense output) [Hz]")
    exchange_step: float = Field(
        DEFAULT_EXCHANGE_STEP,
        ge=1e-6,
        le=1.0,
        description=(
            "simulation time between the exchanges of the lockstep co-simulation (`run`, the ROS nodes), unless "
            "--exchange-step says otherwise: its error falls with it, its speed grows with it (docs/ros.md) [s]"
        ),
    )

    @model_validator(mode="after")
    def _method_on_path(self) -> Solver:
        if self.method == "Rosenbrock23" and self.path == "reference":
            raise ValueError(
                "solver.method 'Rosenbrock23' runs only on the compiled fast path; expected solver.path: "
                "fast, or a method of the reference path (RK45, RK23, DOP853, Radau, BDF, LSODA, RK4, "
                "energy)"
            )
        return self


class Analysis(SceneModel):
    steady_tolerance: Positive = Field(
        1e-4,
        description="steady when omega at the start of successive dynamic periods "
        "differs by less than this fraction of omega_m [-]",
    )
    settling_band: Positive = Field(
        0.002,
        description="a load change has settled once the cycle-mean speed stays "
        "within this fraction of the new steady speed [-]",
    )
    permitted_delta: Positive | None = Field(
        None,
        description="coefficient of speed fluctuation "
        "(omega_max - omega_min) / omega_m that the machine's class "
        "permits [-], e.g. 0.0125 (1/80) for an engine driving a "
        "generator; recordings draw the band omega_set (1 +- "
        "delta / 2) around the set speed",
    )


class Scene(SceneModel):
    """A complete scene: machine, scenario, solver and analysis settings."""

    name: str | None = Field(None, description="short name of the scene, used in outputs")
    description: str | None = Field(None, description="free text describing the scene")
    machine: Machine = Field(description="the machine reduced to its crank")
    governor: Governor | None = Field(None, description="centrifugal speed governor; its throttle scales the drive")
    scenario: Scenario = Field(description="initial state, duration and load changes")
    solver: Solver = Field(default_factory=Solver, description="integration method and accuracy")
    analysis: Analysis = Field(default_factory=Analysis, description="settings of the post-run analysis")

    @model_validator(mode="after")
    def _governed(self) -> Scene:
        initial = self.scenario.initial
        if self.machine.coupling is None and initial.twist is not None:
            raise ValueError("scenario.initial.twist is set but the machine has no coupling")
        if self.machine.coupling is None and self.machine.clutch is None and initial.omega_driven is not None:
            raise ValueError(
                "scenario.initial.omega_driven is set but the machine has no driven part (no coupling and no clutch)"
            )
        if self.machine.clutch is not None and self.solver.method == "energy":
            raise ValueError(
                "solver.method 'energy' steps one crank angle; a machine with a clutch has two masses: "
                "use a method in time (DOP853, RK45, RK23, Radau, BDF, LSODA or RK4)"
            )
        if self.machine.coupling is not None and self.solver.method == "energy":
            raise ValueError(
                "solver.method 'energy' steps one crank angle; a machine with a coupling has two "
                "masses: use a method in time (Radau or BDF for a stiff coupling, else DOP853)"
            )
        if self.governor is None:
            for key in ("sleeve", "servo"):
                if getattr(initial, key) is not None:
                    raise ValueError(f"scenario.initial.{key} is set but the scene has no governor")
            return self
        if self.machine.drive is None:
            raise ValueError("the governor scales the driving moment, but machine.drive is missing")
        if self.solver.method == "energy":
            raise ValueError(
                "solver.method 'energy' integrates the machine alone in phi; a governed scene needs a "
                "method in time (DOP853, RK45, RK23, Radau, BDF, LSODA or RK4)"
            )
        if self.governor.type == "pi":
            for key in ("sleeve", "servo"):
                if getattr(initial, key) is not None:
                    raise ValueError(
                        f"scenario.initial.{key} is set but the governor is 'pi' (it has no sleeve and "
                        "no servo-motor: the integral part starts where the throttle balances the load)"
                    )
            return self
        low, high = self.governor.stroke
        if initial.sleeve is not None and not low <= initial.sleeve <= high:
            raise ValueError(
                f"scenario.initial.sleeve = {initial.sleeve} m lies outside the governor's stroke "
                f"{self.governor.stroke} m"
            )
        if initial.servo is not None:
            if self.governor.type != "indirect":
                raise ValueError(
                    f"scenario.initial.servo is set but the governor is '{self.governor.type}' (it has no servo-motor)"
                )
            low, high = self.governor.servo.travel
            if not low <= initial.servo <= high:
                raise ValueError(
                    f"scenario.initial.servo = {initial.servo} lies outside the servo travel "
                    f"{self.governor.servo.travel}"
                )
        return self
