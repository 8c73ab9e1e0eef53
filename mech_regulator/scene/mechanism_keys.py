"""The scene's `machine.mechanism` keys: the crank-slider (and an engine's cylinders), the four-bar, the walking
beam and the general linkage with its links, joints, cams and output (scene/schema.py describes the format and its
conventions)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Discriminator, Field, Tag, model_validator

from mech_regulator.scene.key_types import NonNegative, Positive, SceneModel, check_table


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
        sizes = self.teeth or self.radii
        if self.type == "gear" and self.internal and sizes is not None and sizes[0] == sizes[1]:
            raise ValueError(f"an internal gear pair of equal gears {sizes}; expected a ring larger than its pinion")
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
        check_table(self.angle_deg, self.lift, 360.0, "law")
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
