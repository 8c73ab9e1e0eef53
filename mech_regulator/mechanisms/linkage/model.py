"""The data model of a planar linkage: links with their points, mass and inertia, and the joints between them.

Every link carries its own coordinates: its points (joints and points of interest) and its centre of mass are
given in them [m]. A link's pose is the position r [m] of its coordinate origin and the angle theta [rad] of its
x axis, so that its point p is at `P = r + p e^{i theta}` (complex numbers x + i y, y up). The frame's
coordinates are the global ones (its pose is r = 0, theta = 0). The driving crank turns about its revolute
joint with the frame with theta_crank = phi.

Joints (source 001's kinematic pairs):
- revolute (lower pair, class 5): the two links' points of the joint's name coincide;
- prismatic (lower pair, class 5): the slider link's point of the joint's name stays on the guide link's line
  through its own point of that name, of direction `direction` in the guide's coordinates, and the slider keeps
  the angle `slider_angle` to the guide: theta_slider = theta_guide + slider_angle;
- cam (higher pair, class 4): the contact of a cam (links[0], the crank) with its follower or the follower's roller
  (links[1]); its `cam` (linkage/cam.py's CamSpec) gives the follower's motion law and the contact; the follower is
  a group of its own (cam.CamFollower);
- gear (higher pair, class 4): a gear pair, its data in `gear` (gears.GearMesh: pitch radii or tooth numbers, the
  centres' points, the carrier).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from mech_regulator.mechanisms.linkage.cam import CamSpec
    from mech_regulator.mechanisms.linkage.gears import GearMesh

REVOLUTE, PRISMATIC, CAM = "revolute", "prismatic", "cam"
GEAR = "gear"


class LinkageError(ValueError):
    """A linkage that cannot be analysed or assembled; the message names the links, joints and crank angle."""


@dataclass(frozen=True)
class Link:
    """A rigid link: its points in its own coordinates [m], mass [kg], centre of mass [m, own coordinates],
    moment of inertia about the centre of mass [kg m^2]; roller_radius [m]: a roller turning about its one
    revolute joint (its spin is a passive freedom when it touches a cam)."""

    name: str
    points: dict[str, complex]
    mass: float = 0.0
    centre: complex = 0j
    inertia: float = 0.0
    roller_radius: float | None = None


@dataclass(frozen=True)
class Joint:
    """A joint named `name` between links[0] and links[1] (prismatic: links[0] is the guide, links[1] the slider);
    direction [rad]: the guide line's direction in the guide's coordinates; slider_angle [rad]: theta_slider -
    theta_guide; cam: a cam pair's linkage/cam.py CamSpec; gear: a gear pair's data (None for a lower pair)."""

    name: str
    kind: str
    links: tuple[str, str]
    direction: float = 0.0
    slider_angle: float = 0.0
    cam: CamSpec | None = None
    gear: GearMesh | None = None

    @property
    def letter(self) -> str:
        """R (revolute), P (prismatic), C (cam) or G (gear), the letters of a group's type (source 001)."""
        return {REVOLUTE: "R", PRISMATIC: "P", CAM: "C", GEAR: "G"}[self.kind]

    def other(self, link: str) -> str:
        """The link this joint joins to `link`."""
        return self.links[1] if self.links[0] == link else self.links[0]

    def gear_mesh(self) -> GearMesh:
        """The gear pair's data (`gear`); raises LinkageError naming the joint when it has none (not a gear pair)."""
        if self.gear is None:
            raise LinkageError(f"the joint '{self.name}' ({self.kind}) has no gear data; expected a gear pair")
        return self.gear


@dataclass(frozen=True)
class Linkage:
    """A planar linkage: links (the frame among them), joints, the frame's and the crank's names (crank None: no
    driving link, for the structural count only), the assembly branch (+1 or -1) of each group named by its
    internal joint (a group not named takes +1), the points of interest (names of link points whose motion is
    reported) and the output: a prismatic joint (q = the slider's travel along the guide [m]) or a link (q = its
    angle [rad], reported within pi of output_reference [rad], so that a rocker swinging across +-pi stays
    continuous), or None."""

    links: tuple[Link, ...]
    joints: tuple[Joint, ...]
    frame: str
    crank: str | None
    branches: dict[str, int] = field(default_factory=dict)
    points: tuple[str, ...] = ()
    output_joint: str | None = None
    output_link: str | None = None
    output_reference: float = 0.0

    _by_name: dict[str, Link] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_by_name", {link.name: link for link in self.links})

    def link(self, name: str) -> Link:
        """The link named `name`."""
        try:
            return self._by_name[name]
        except KeyError:
            raise LinkageError(f"no link named '{name}'; the links are {[link.name for link in self.links]}") from None

    def joint(self, name: str) -> Joint:
        """The joint named `name`."""
        for joint in self.joints:
            if joint.name == name:
                return joint
        raise LinkageError(f"no joint named '{name}'; the joints are {[joint.name for joint in self.joints]}")

    def moving_links(self) -> list[str]:
        """Names of the links other than the frame."""
        return [link.name for link in self.links if link.name != self.frame]

    def joints_of(self, link: str) -> list[Joint]:
        """The joints that touch `link`."""
        return [joint for joint in self.joints if link in joint.links]

    def check(self) -> None:
        """Raise LinkageError for a joint naming an unknown link or joining a link to itself, a joint point a link
        lacks, a crank that is not pivoted on the frame, or a point of interest / output that does not exist."""
        names = [link.name for link in self.links]
        if self.frame not in names:
            raise LinkageError(f"the frame '{self.frame}' is not among the links {names}")
        for joint in self.joints:
            for link in joint.links:
                if link not in names:
                    raise LinkageError(
                        f"joint '{joint.name}' names the link '{link}', which does not exist; expected one of {names}"
                    )
            if joint.links[0] == joint.links[1]:
                raise LinkageError(
                    f"joint '{joint.name}' joins the link '{joint.links[0]}' to itself; expected two different links"
                )
            if joint.kind == GEAR:
                gear = joint.gear_mesh()
                if gear.carrier is not None and gear.carrier not in names:
                    raise LinkageError(
                        f"gear '{joint.name}' names the carrier '{gear.carrier}', which does not "
                        f"exist; expected one of {names}"
                    )
                for link, centre in zip(joint.links, gear.centres):
                    if centre not in self.link(link).points:
                        raise LinkageError(
                            f"gear '{joint.name}' names the centre '{centre}' on the link '{link}', "
                            f"which has only {sorted(self.link(link).points)}"
                        )
            elif joint.kind != CAM:
                for link in joint.links:
                    if joint.name not in self.link(link).points:
                        raise LinkageError(
                            f"joint '{joint.name}' ({joint.kind}) needs the point '{joint.name}' on the "
                            f"link '{link}', which has only {sorted(self.link(link).points)}"
                        )
        if self.crank is not None:
            if self.crank not in names or self.crank == self.frame:
                raise LinkageError(f"the crank '{self.crank}' must be a moving link, one of {self.moving_links()}")
            pivots = [j for j in self.joints_of(self.crank) if j.kind == REVOLUTE and self.frame in j.links]
            if len(pivots) != 1:
                raise LinkageError(
                    f"the crank '{self.crank}' must turn about one revolute joint with the frame "
                    f"'{self.frame}'; it has {len(pivots)}"
                )
        for point in self.points:
            if not any(point in link.points for link in self.links if link.name != self.frame):
                raise LinkageError(f"the point of interest '{point}' is on no moving link")
        if self.output_joint is not None and self.joint(self.output_joint).kind != PRISMATIC:
            raise LinkageError(
                f"the output joint '{self.output_joint}' is {self.joint(self.output_joint).kind}; "
                "expected a prismatic joint (its travel is the output coordinate)"
            )
        if self.output_link is not None and self.output_link not in self.moving_links():
            raise LinkageError(f"the output link '{self.output_link}' is not a moving link {self.moving_links()}")

    def driving_crank(self) -> str:
        """The crank's name; raises LinkageError when the linkage has none (one built for the structural count only)."""
        if self.crank is None:
            raise LinkageError("the linkage has no crank; expected a driving link turning with the crank angle phi")
        return self.crank

    def crank_pivot(self) -> Joint:
        """The revolute joint of the crank with the frame."""
        return next(j for j in self.joints_of(self.driving_crank()) if j.kind == REVOLUTE and self.frame in j.links)
