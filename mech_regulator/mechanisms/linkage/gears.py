"""Gear pairs in a planar linkage (docs/theory.md §5.5, docs/linkages.md "Gears"): the mesh's data, its group (one
gear link on one revolute pivot, turned by a mesh with a known link: 3 - 2 - 1 = 0) and the checks that make it one.

A gear pair between links a and b meshes at the pitch point P = O_a + rho_a u = O_b + rho_b u, O the gears' centres,
u = (O_b - O_a) / |O_b - O_a| and rho the signed pitch radii: external rho_a = r_a, rho_b = -r_b; internal with b the
ring rho_a = -r_a, rho_b = -r_b; internal with a the ring rho_a = r_a, rho_b = r_b, so that the centre distance is
d = rho_a - rho_b. Rolling without slip at P (the velocities of P as a point of a and of b agree along t = i u)
integrates, the centres staying d apart, to `rho_a (theta_a - psi) = rho_b (theta_b - psi) + const`, psi the angle of
the line of centres; on a carrier c, the link on which both centres stay (the frame for fixed axes), psi - theta_c
is constant and this is Willis' formula `theta_b - theta_c = (rho_a / rho_b) (theta_a - theta_c) + phase`: the ratio
-r_a/r_b of an external pair, +r_a/r_b of an internal one. Tooth numbers give the ratio; the pitch radii then follow
from the centre distance, r = d z / (z_a + z_b) (external) or d z / |z_a - z_b| (internal).

The group: the unknown gear link L turns about its pivot (a revolute joint with a known link K, at L's gear centre)
and meshes with a known link G; its angle `theta_L = theta_c + k (theta_G - theta_c) + phase_L` (k = rho_G / rho_L)
needs the angles of G and c as continuous functions of phi, so G and c must be the frame, the crank or gears placed
before: every such angle is then `rate phi + constant`, and the link's `rate` (its turns per crank turn) is known
when the group is found. A gear whose rate is not a whole number does not repeat each crank turn; a linkage hung on
it would not either (the package assumes it does), so such a gear may carry only its pivot and gear meshes.
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass

from mech_regulator.mechanisms.linkage.model import GEAR, REVOLUTE, Joint, Linkage, LinkageError

CENTRE_TOLERANCE = 1e-6  # relative mismatch of the centre distance and the given pitch radii still accepted [-]
STEADY_TOLERANCE = 1e-9  # relative change of the centre distance (and of psi - theta_c, rad) over the turn [-]
WHOLE_TOLERANCE = 1e-9  # distance of a gear's turns per crank turn from a whole number still called whole [-]
CHECK_SAMPLES = 72  # crank angles over a turn at which the centres are checked


@dataclass(frozen=True)
class GearMesh:
    """A gear pair's data: `teeth` (z_a, z_b) or `radii` (r_a, r_b) [m] (exactly one), `internal` (one of them a
    ring with internal teeth: the larger), `centres` (the names of the gear centres' points on link a and on link
    b), the carrier link (None: the frame) and `phase` [rad]: theta_b - theta_c - k (theta_a - theta_c)."""

    centres: tuple[str, str]
    teeth: tuple[int, int] | None = None
    radii: tuple[float, float] | None = None
    internal: bool = False
    carrier: str | None = None
    phase: float = 0.0

    def signed_radii(self, distance: float) -> tuple[float, float]:
        """(rho_a, rho_b) [m] (module docstring) for centres `distance` [m] apart: the given radii, or from the
        tooth numbers r = d z / (z_a +- z_b)."""
        if self.radii is not None:
            r_a, r_b = self.radii
        else:
            assert self.teeth is not None  # exactly one of teeth and radii
            z_a, z_b = self.teeth
            r_a, r_b = (distance * z / (abs(z_a - z_b) if self.internal else z_a + z_b) for z in (z_a, z_b))
        if not self.internal:
            return r_a, -r_b
        return (r_a, r_b) if r_a > r_b else (-r_a, -r_b)


@dataclass(frozen=True)
class GearGroup:
    """The group of one gear link: `link` turning about `pivot` (a revolute joint with a known link), meshing by
    `mesh` with `driver` on `carrier`, its signed pitch radii (rho_a, rho_b) [m] of the mesh's links a, b, its
    phase_L [rad] and `rate`, its turns per crank turn [-] (module docstring)."""

    link: str
    pivot: Joint
    mesh: Joint
    driver: str
    carrier: str
    pitch: tuple[float, float]
    phase: float
    rate: float
    kind: str = "gear"

    @property
    def name(self) -> str:
        """The group's name: 'gear group' and its mesh."""
        return f"gear group {self.mesh.name}"

    @property
    def links(self) -> tuple[str]:
        return (self.link,)

    @property
    def joints(self) -> tuple[Joint, Joint]:
        return (self.pivot, self.mesh)

    @property
    def ratio(self) -> float:
        """k = (theta_L - theta_c)' / (theta_G - theta_c)' = rho_G / rho_L [-]."""
        rho_a, rho_b = self.pitch
        return rho_a / rho_b if self.mesh.links[1] == self.link else rho_b / rho_a


def carrier_of(linkage: Linkage, mesh: Joint) -> str:
    """The carrier of a gear mesh: the link named, else the frame."""
    return mesh.gear_mesh().carrier or linkage.frame


def next_gear(linkage: Linkage, known: set[str], rates: dict[str, float], solve_at) -> GearGroup | None:
    """The first unknown link meshing by a gear with a known link of known rate (`rates`: the frame, the crank and
    the gears placed so far), whose only other joint with known links is one revolute pivot at its gear centre, on a
    carrier of known rate; its pitch radii from the centres' distance at phi = 0, checked steady over the turn
    (solve_at: the poses of the groups found so far, kinematics.make_solver). Raises LinkageError for a mesh whose
    centres do not keep their distance or turn with the carrier, given radii that do not fit the distance, or a
    gear driven by a link whose angle is not a gear's, the crank's or the frame's."""
    for name in linkage.moving_links():
        if name in known:
            continue
        joints = [joint for joint in linkage.joints_of(name) if joint.other(name) in known]
        meshes = [joint for joint in joints if joint.kind == GEAR]
        others = [joint for joint in joints if joint.kind != GEAR]
        if len(meshes) != 1 or len(others) != 1 or others[0].kind != REVOLUTE:
            continue
        mesh, pivot = meshes[0], others[0]
        driver, carrier = mesh.other(name), carrier_of(linkage, mesh)
        for role, link in (("driven by", driver), ("on the carrier", carrier)):
            if link not in rates:
                raise LinkageError(
                    f"the gear {name} (mesh {mesh.name}) is {role} {link}, whose angle is not the "
                    "frame's, the crank's or another gear's; expected a gear meshing with the frame, "
                    "the crank or a gear, on such a carrier"
                )
        gear = mesh.gear_mesh()
        own_centre = linkage.link(name).points[gear.centres[mesh.links.index(name)]]
        if own_centre != linkage.link(name).points[pivot.name]:
            raise LinkageError(
                f"the gear {name} turns about {pivot.name} but its centre for the mesh {mesh.name} is "
                f"elsewhere; expected its centre point at its pivot {pivot.name}"
            )
        pitch = _pitch(linkage, mesh, pivot, name, solve_at)
        k = pitch[0] / pitch[1] if mesh.links[1] == name else pitch[1] / pitch[0]
        phase = gear.phase if mesh.links[1] == name else -gear.phase * k
        rate = rates[carrier] + k * (rates[driver] - rates[carrier])
        return GearGroup(name, pivot, mesh, driver, carrier, pitch, phase, rate)
    return None


def _pitch(linkage: Linkage, mesh: Joint, pivot: Joint, name: str, solve_at) -> tuple[float, float]:
    """The mesh's signed pitch radii, its centres' distance and their line's angle to the carrier checked at
    CHECK_SAMPLES crank angles (the gear `name`'s centre is its pivot's point on the link it turns about)."""
    from mech_regulator.mechanisms.linkage.kinematics import motion

    carrier, gear = carrier_of(linkage, mesh), mesh.gear_mesh()
    distances, turns = [], []
    for k in range(CHECK_SAMPLES):
        poses = solve_at(2.0 * math.pi * k / CHECK_SAMPLES, False)
        centres = []
        for link, centre in zip(mesh.links, gear.centres):
            on, point = (
                (pivot.other(name), linkage.link(pivot.other(name)).points[pivot.name])
                if link == name
                else (link, linkage.link(link).points[centre])
            )
            centres.append(motion(poses[on], point)[0])
        line = centres[1] - centres[0]
        distances.append(abs(line))
        turns.append(cmath.phase(line) - poses[carrier][1])
    distance = distances[0]
    drift = max(abs(cmath.phase(cmath.exp(1j * (turn - turns[0])))) for turn in turns)
    if (
        distance == 0.0
        or max(abs(d - distance) for d in distances) > STEADY_TOLERANCE * distance
        or drift > STEADY_TOLERANCE
    ):
        raise LinkageError(
            f"the gear mesh {mesh.name} ({mesh.links[0]}, {mesh.links[1]}): its centres "
            f"{', '.join(gear.centres)} are {min(distances):.6g} to {max(distances):.6g} m apart "
            f"and their line turns {drift:.3g} rad against the carrier {carrier} over the turn; "
            "expected centres a steady distance apart on the carrier (name it: carrier)"
        )
    rho_a, rho_b = gear.signed_radii(distance)
    if abs(rho_a - rho_b - distance) > CENTRE_TOLERANCE * distance:
        raise LinkageError(
            f"the gear mesh {mesh.name}: pitch radii {abs(rho_a):g} and {abs(rho_b):g} m "
            f"({'internal' if gear.internal else 'external'}) need the centres "
            f"{abs(rho_a - rho_b):g} m apart, but they are {distance:.6g} m apart"
        )
    return rho_a, rho_b


def hanging_on_fractional_gears(linkage: Linkage, groups) -> list[str]:
    """Gears whose turns per crank turn are not whole and that carry another joint than their pivot and their
    meshes (module docstring), each named with its rate and that joint."""
    found = []
    for group in groups:
        if not isinstance(group, GearGroup) or abs(group.rate - round(group.rate)) <= WHOLE_TOLERANCE:
            continue
        carried = [joint.name for joint in linkage.joints_of(group.link) if joint.kind != GEAR and joint != group.pivot]
        if carried:
            found.append(
                f"the gear {group.link} turns {group.rate:.6g} times per crank turn and carries "
                f"{', '.join(carried)}: what hangs on it would not repeat each crank turn"
            )
    return found
