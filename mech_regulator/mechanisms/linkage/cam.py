"""Cam pairs of a linkage (docs/theory.md §5.7, docs/linkages.md "Cams"): the follower group, its motion by the law,
the synthesised profile, pressure angle, radius of curvature, the follower's share of J(phi), its spring, the
contact force and the speed at which the follower jumps. Pure numpy: no ROS, no Rerun.

A cam pair (model.Joint of kind CAM, its `cam` a CamSpec) joins a cam link turning about a frame pivot (the crank)
to the link that touches it: the follower itself (knife edge, flat face) or a roller (a link with roller_radius on
one revolute joint with the follower: a passive freedom). The follower is joined to the frame by one lower pair:
prismatic (translating: a rise moves it along the guide's direction, which must point away from the cam; any
offset) or revolute (oscillating: a rise turns it away from the cam). With its roller it is a group of zero
freedom (3 - 2 - 1 for the follower, + 3 - 2 - 1 for a roller and its passive spin): CamFollower, placed by the law
s(theta), theta = phi - start the cam angle from the law's start.

The follower's contact point (knife tip, roller centre) runs on the pitch curve: at s = 0 it is at the pitch radius
R = base_radius + roller_radius from the cam's pivot O; translating, P = C0 + (d0 + s) u; oscillating,
P = Q + l e^{i (psi0 + sigma s)} (Q the pivot, l the arm, sigma = +1 or -1 the sense that leaves the cam). Relative
to the cam (turning at theta' = 1) the pitch point moves as T = P' - i (P - O), T2 = P'' - 2 i P' - (P - O) (global
axes; in the cam's coordinates these turn by e^{-i phi}); the contact normal is n = i T / |T| (outward), the
pressure angle alpha the angle between n and the follower's path dP/ds, `tan alpha = |T . v| / |T x v|`, the pitch
curve's radius of curvature `rho_p = -|T|^3 / (T x T2)` (positive where convex) and the profile's rho_p - r_roller:
a roller larger than rho_p undercuts the profile, which is refused. A flat face (translating, face across the guide)
touches at `K = O + (R + s) u - i s' u` with the profile's radius R + s + s'' (refused where negative: a cusp) and
alpha = 0.

Follower dynamics along s (its mass moves with s' per radian of crank: M = m_follower + m_roller translating,
M = I_Q of the follower + m_roller l^2 + I_roller oscillating; the roller turns with its follower: its spin
relative to it is the passive freedom, left out):
J_f = M s'^2, dJ_f/dphi = 2 M s' s''; the spring (stiffness k, preload F0 along s) acts on the crank as
-(F0 + k s) s'; the contact must push along s with `Q_c = M (s'' omega^2 + s' epsilon) + F0 + k s - G_s` (G_s the
weight along s), the contact force N = Q_c / (n . dP/ds). Contact is lost where Q_c < 0: at steady speed first at
`omega_jump = min over s'' < 0 of sqrt((F0 + k s - G_s) / (-M s''))`.
"""

from __future__ import annotations

import cmath
import dataclasses
import math
from dataclasses import dataclass
from typing import TypedDict

import numpy as np

from mech_regulator.mechanisms.cam_laws import TWO_PI, MotionLaw
from mech_regulator.mechanisms.linkage.model import CAM, PRISMATIC, REVOLUTE, Joint, Linkage, LinkageError

SAMPLES = 3600  # cam angles over a turn at which the profile is checked (every 0.1 deg)
KINK_APPROACH = 1e-9  # a law's segment ends are also checked this close before them [rad]


@dataclass(frozen=True)
class CamSpec:
    """What a cam pair says besides its links: the follower's motion law, the contact (knife_edge, roller or flat_face), the cam's base
    circle radius [m] (its profile's least distance from its pivot), the crank angle [rad] at which the law's
    theta = 0, and the follower's spring along s: stiffness [N/m or N m/rad] and preload [N or N m] at s = 0."""

    law: MotionLaw
    contact: str
    base_radius: float
    start: float = 0.0
    stiffness: float = 0.0
    preload: float = 0.0


@dataclass(frozen=True)
class CamFollower:
    """A cam follower group: the follower link, its roller (or None), the follower's lower pair with the frame
    (guide), the cam pair and the roller's revolute joint (or None); at_base: (sigma, the follower's travel d0 [m]
    (translating; sigma 1) or angle theta0 [rad] (oscillating) at s = 0), as flat_program.encode writes them into the
    cam record (follower_zero; filled in by next_cam_follower)."""

    follower: str
    roller: str | None
    guide: Joint
    pair: Joint
    roller_joint: Joint | None
    kind: str = "cam follower"
    at_base: tuple[float, float] = (1.0, 0.0)

    @property
    def name(self) -> str:
        return f"cam follower {self.follower} (cam pair {self.pair.name})"

    @property
    def links(self) -> tuple[str, ...]:
        return (self.follower,) if self.roller is None else (self.follower, self.roller)

    @property
    def joints(self) -> tuple[Joint, ...]:
        return (self.guide, self.pair) + ((self.roller_joint,) if self.roller_joint is not None else ())


def next_cam_follower(linkage: Linkage, known: set[str]) -> CamFollower | None:
    """The first cam pair whose cam is known and whose follower (through its roller, if any) is joined by exactly
    one lower pair to the frame and to nothing else known; raises LinkageError for a cam pair it cannot take (the
    cam not the crank, a roller not on one revolute joint, a follower not on the frame)."""
    for pair in linkage.joints:
        if pair.kind != CAM or pair.links[0] not in known or pair.links[1] in known:
            continue
        cam, toucher = pair.links
        if cam != linkage.crank:
            raise LinkageError(
                f"the cam pair {pair.name}'s cam '{cam}' is not the crank '{linkage.crank}'; only a cam "
                "on the crank is supported (list the cam first in links: [cam, follower])"
            )
        roller, roller_joint, follower = None, None, toucher
        if linkage.link(toucher).roller_radius is not None:
            others = [j for j in linkage.joints_of(toucher) if j is not pair]
            if len(others) != 1 or others[0].kind != REVOLUTE:
                raise LinkageError(
                    f"the roller '{toucher}' of the cam pair {pair.name} has the joints "
                    f"{[j.name for j in others]} besides it; expected one revolute joint with its "
                    "follower"
                )
            roller, roller_joint, follower = toucher, others[0], others[0].other(toucher)
        lower = [j for j in linkage.joints_of(follower) if j.kind != CAM and j is not roller_joint]
        if len(lower) != 1 or linkage.frame not in lower[0].links:
            raise LinkageError(
                f"the follower '{follower}' of the cam pair {pair.name} has the lower pairs "
                f"{[j.name for j in lower]} besides its roller; expected exactly one, with the frame "
                "(prismatic: translating, revolute: oscillating)"
            )
        guide = lower[0]
        if guide.kind == PRISMATIC and guide.links[0] != linkage.frame:
            raise LinkageError(
                f"the follower '{follower}''s guide {guide.name} lists it first; expected links: "
                f"[{linkage.frame}, {follower}] (guide, slider)"
            )
        group = CamFollower(follower, roller, guide, pair, roller_joint)
        if pair.cam is None:  # a structure alone (no law): nothing to place
            return group
        return dataclasses.replace(group, at_base=follower_zero(linkage, group))
    return None


@dataclass(frozen=True)
class FollowerMotion:
    """A follower's motion at crank angles phi: s, s', s'' (the law), its contact point P, P', P'' [m, m/rad,
    m/rad^2], the path direction dP/ds, and the follower's angle theta_f with its phi-derivatives."""

    s: np.ndarray
    ds: np.ndarray
    dds: np.ndarray
    P: np.ndarray
    dP: np.ndarray
    ddP: np.ndarray
    along: np.ndarray
    theta: np.ndarray
    dtheta: np.ndarray


class CamNumbers(TypedDict):
    """A cam pair's checks over the turn (CamPair.numbers): names, lift [m or rad], angles [deg], the profile's least
    radius of curvature [m] and the jump speed [rad/s] (None: none found)."""

    pair: str
    follower: str
    contact: str
    motion: str
    lift: float
    pressure_angle_max_deg: float
    pressure_angle_max_at_deg: float
    least_radius: float | None
    least_radius_at_deg: float | None
    jump_speed: float | None
    jump_at_deg: float | None


class CamPair:
    """The geometry and dynamics of one cam follower group (module docstring) in a linkage; raises LinkageError
    for a follower that cannot touch the base circle, an oscillating flat face, a profile that would be undercut or
    cusped (naming the crank angle; `check` False: the profile is not checked), a point the contact needs that the
    follower lacks."""

    def __init__(self, linkage: Linkage, group: CamFollower, gravity: tuple[float, float] | None, check: bool = True):
        self.group = group
        assert group.pair.cam is not None  # a cam pair carries its CamSpec (presets.cam_spec)
        self.spec: CamSpec = group.pair.cam
        spec = self.spec
        self.translating = group.guide.kind == PRISMATIC
        roller_link = linkage.link(group.roller) if group.roller is not None else None
        self.roller_radius = 0.0
        if roller_link is not None:
            assert roller_link.roller_radius is not None  # next_cam_follower takes a link with a roller_radius
            self.roller_radius = roller_link.roller_radius
        if (spec.contact == "roller") != (roller_link is not None):
            raise LinkageError(
                f"the cam pair {group.pair.name} has contact {spec.contact} but touches the link "
                f"'{group.pair.links[1]}', which is {'a' if roller_link else 'not a'} roller; expected "
                "contact: roller exactly when the touching link has a roller_radius"
            )
        if spec.contact == "flat_face" and not self.translating:
            raise LinkageError(
                f"the cam pair {group.pair.name}: a flat face on an oscillating follower is not "
                "supported yet; expected a knife_edge or roller contact, or a translating follower"
            )
        follower = linkage.link(group.follower)
        contact_name = group.roller_joint.name if group.roller_joint is not None else group.pair.name
        if contact_name not in follower.points:
            raise LinkageError(
                f"the follower '{group.follower}' needs the point '{contact_name}' (its "
                f"{'roller centre' if group.roller else 'contact point'}); it has only "
                f"{sorted(follower.points)}"
            )
        frame = linkage.link(linkage.frame).points
        self.centre = frame[linkage.crank_pivot().name]
        self.pitch_radius = spec.base_radius + self.roller_radius
        self.contact_local = follower.points[contact_name]
        self.guide_local = follower.points[group.guide.name]
        self.gravity = complex(*gravity) if gravity is not None else 0j
        roller_mass = roller_link.mass if roller_link is not None else 0.0
        self.follower_mass, self.follower_inertia, self.follower_centre = (
            follower.mass,
            follower.inertia,
            follower.centre,
        )
        self.roller_mass = roller_mass
        if self.translating:
            self.slider_angle = group.guide.slider_angle
            turn = cmath.exp(1j * self.slider_angle)
            self.direction = cmath.exp(1j * group.guide.direction)
            self.line_point = frame[group.guide.name] + (self.contact_local - self.guide_local) * turn
            m = self.line_point - self.centre
            along = (m * self.direction.conjugate()).real
            if spec.contact == "flat_face":
                self.travel0 = self.pitch_radius - along
            else:
                discriminant = along * along - abs(m) ** 2 + self.pitch_radius**2
                if discriminant < 0.0:
                    raise LinkageError(
                        f"the cam pair {group.pair.name}: the follower's line passes "
                        f"{abs((m * self.direction.conjugate()).imag):.6g} m from the cam's pivot, "
                        f"farther than the base circle's {self.pitch_radius:.6g} m "
                        "(with the roller); expected a smaller offset or a larger base circle"
                    )
                self.travel0 = -along + math.sqrt(discriminant)
            self.offset = (m * self.direction.conjugate()).imag
            self.generalised_mass = self.follower_mass + roller_mass
        else:
            self.pivot = frame[group.guide.name]
            arm = self.contact_local - self.guide_local
            self.arm, self.arm_angle = abs(arm), cmath.phase(arm)
            span = self.centre - self.pivot
            distance = abs(span)
            cosine = (self.arm**2 + distance**2 - self.pitch_radius**2) / (2.0 * self.arm * distance)
            if not -1.0 <= cosine <= 1.0:
                raise LinkageError(
                    f"the cam pair {group.pair.name}: the follower's arm {self.arm:.6g} m about "
                    f"{group.guide.name} cannot reach the base circle of radius {self.pitch_radius:.6g} "
                    f"m (with the roller) {distance:.6g} m away; expected |d - l| <= R <= d + l"
                )
            self.sigma = float(linkage.branches.get(group.pair.name, 1))
            self.psi0 = cmath.phase(span) + self.sigma * math.acos(cosine)
            centre_arm = self.follower_centre - self.guide_local
            self.generalised_mass = (
                self.follower_inertia
                + self.follower_mass * abs(centre_arm) ** 2
                + roller_mass * self.arm**2
                + (roller_link.inertia if roller_link is not None else 0.0)
            )
        if check:
            self._check_profile()

    # motion -------------------------------------------------------------------------------------------------
    def motion(self, phi) -> FollowerMotion:
        """The follower's motion at crank angles phi [rad] (module docstring)."""
        phi = np.atleast_1d(np.asarray(phi, dtype=float))
        s, ds, dds = self.spec.law.evaluate(phi - self.spec.start)
        if self.translating:
            u = self.direction
            P = self.line_point + (self.travel0 + s) * u
            zero = np.zeros_like(s)
            return FollowerMotion(s, ds, dds, P, ds * u, dds * u, np.full_like(P, u), zero + self.slider_angle, zero)
        psi = self.psi0 + self.sigma * s
        arm = self.arm * np.exp(1j * psi)
        P = self.pivot + arm
        return FollowerMotion(
            s,
            ds,
            dds,
            P,
            1j * self.sigma * ds * arm,
            (1j * self.sigma * dds - ds * ds) * arm,
            1j * self.sigma * arm,
            psi - self.arm_angle,
            self.sigma * ds,
        )

    def poses(self, phi: float) -> dict[str, list]:
        """The follower's (and roller's) pose [r, theta, r', theta', r'', theta''] at crank angle phi [rad], as
        kinematics.solve gives a group's links (the roller turns with its follower: its spin is passive)."""
        m = self.motion(phi)
        theta, dtheta = float(m.theta[0]), float(m.dtheta[0])
        ddtheta = self.sigma * float(m.dds[0]) if not self.translating else 0.0
        q = self.contact_local * cmath.exp(1j * theta)
        P, dP, ddP = complex(m.P[0]), complex(m.dP[0]), complex(m.ddP[0])
        r = P - q
        dr = dP - 1j * dtheta * q
        ddr = ddP - (1j * ddtheta - dtheta**2) * q
        found = {self.group.follower: [r, theta, dr, dtheta, ddr, ddtheta]}
        if self.group.roller is not None:
            found[self.group.roller] = [P, theta, dP, dtheta, ddP, ddtheta]
        return found

    # geometry -----------------------------------------------------------------------------------------------
    def _relative(self, m: FollowerMotion, phi: np.ndarray):
        """(T, T2): the pitch point's first and second phi-derivatives relative to the cam, in global axes."""
        radius = m.P - self.centre
        return m.dP - 1j * radius, m.ddP - 2j * m.dP - radius

    def pressure_angle(self, phi) -> np.ndarray:
        """The pressure angle [rad] at crank angles phi: between the contact normal and the follower's path."""
        phi = np.atleast_1d(np.asarray(phi, dtype=float))
        if self.spec.contact == "flat_face":
            return np.zeros_like(phi)
        m = self.motion(phi)
        T, _ = self._relative(m, phi)
        return np.arctan2(np.abs((T * m.along.conjugate()).real), np.abs((T.conjugate() * m.along).imag))

    def profile_radius(self, phi) -> np.ndarray:
        """The profile's radius of curvature [m] at the contact at crank angles phi (positive where convex)."""
        phi = np.atleast_1d(np.asarray(phi, dtype=float))
        m = self.motion(phi)
        if self.spec.contact == "flat_face":
            return self.pitch_radius + m.s + m.dds
        T, T2 = self._relative(m, phi)
        return -(np.abs(T) ** 3) / (T.conjugate() * T2).imag - self.roller_radius

    def contact_point(self, phi) -> np.ndarray:
        """The point where the cam touches its follower (or roller) at crank angles phi [rad] [m, complex]."""
        phi = np.atleast_1d(np.asarray(phi, dtype=float))
        m = self.motion(phi)
        if self.spec.contact == "flat_face":
            u = self.direction
            return self.centre + (self.pitch_radius + m.s) * u - 1j * m.ds * u
        T, _ = self._relative(m, phi)
        return m.P - self.roller_radius * 1j * T / np.abs(T)

    def profile(self, samples: int = SAMPLES) -> np.ndarray:
        """The cam's profile in its own coordinates (its pivot at 0, as drawn at crank angle 0) [m, complex], at
        `samples` cam angles over the turn: the contact points turned back by the cam's angle."""
        phi = np.linspace(0.0, TWO_PI, samples, endpoint=False)
        return (self.contact_point(phi) - self.centre) * np.exp(-1j * phi)

    def _check_profile(self) -> None:
        """Refuse an undercut (roller) or cusped (flat face) profile, naming the crank angle."""
        phi = self._angles()
        radius = self.profile_radius(phi)
        if self.spec.contact == "knife_edge":
            return
        convex_pitch = radius + self.roller_radius > 0.0
        bad = np.flatnonzero(radius <= 0.0 if self.spec.contact == "flat_face" else convex_pitch & (radius <= 0.0))
        if bad.size:
            k = bad[np.argmin(radius[bad])]
            what = (
                f"the roller's radius {self.roller_radius:.6g} m exceeds the pitch curve's radius of curvature "
                f"{radius[k] + self.roller_radius:.6g} m: the profile would be undercut"
                if self.spec.contact == "roller"
                else f"the profile's radius of curvature R + s + s'' is {radius[k]:.6g} m: it would have a cusp"
            )
            raise LinkageError(
                f"the cam pair {self.group.pair.name} at crank angle {math.degrees(phi[k]) % 360:.2f} "
                f"deg: {what}; expected a larger base circle, a smaller roller or a gentler law"
            )

    def _angles(self) -> np.ndarray:
        """The crank angles at which the turn is checked: SAMPLES over the turn and just before each segment end."""
        grid = np.linspace(0.0, TWO_PI, SAMPLES, endpoint=False)
        ends = self.spec.law.kinks() + self.spec.start - KINK_APPROACH
        return np.concatenate([grid, np.mod(ends, TWO_PI)])

    # dynamics -----------------------------------------------------------------------------------------------
    def weight_along(self, m: FollowerMotion) -> np.ndarray:
        """G_s: the follower's and roller's weight as a force along s [N or N m]."""
        if self.translating:
            return self.generalised_mass * (self.gravity * m.along.conjugate()).real
        centre = self.pivot + (self.follower_centre - self.guide_local) * np.exp(1j * m.theta)
        along_centre = 1j * self.sigma * (centre - self.pivot)
        return (
            self.follower_mass * (self.gravity * along_centre.conjugate()).real
            + self.roller_mass * (self.gravity * m.along.conjugate()).real
        )

    def reduced(self, phi) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(J_f [kg m^2], dJ_f/dphi [kg m^2/rad], the weight's reduced moment G_s s' [N m], the spring's
        -(F0 + k s) s' [N m]) at crank angles phi: the follower's share of the machine's reduction."""
        m = self.motion(phi)
        M = self.generalised_mass
        spring = -(self.spec.preload + self.spec.stiffness * m.s) * m.ds
        return M * m.ds**2, 2.0 * M * m.ds * m.dds, self.weight_along(m) * m.ds, spring

    def contact_force(self, phi, omega, epsilon=0.0) -> tuple[np.ndarray, np.ndarray]:
        """(Q_c [N or N m], N [N]): what the cam must push along s, and the contact force along the normal, at
        crank angles phi [rad], speed omega [rad/s] and acceleration epsilon [rad/s^2] (module docstring)."""
        phi = np.atleast_1d(np.asarray(phi, dtype=float))
        m = self.motion(phi)
        needed = (
            self.generalised_mass * (m.dds * omega**2 + m.ds * epsilon)
            + self.spec.preload
            + self.spec.stiffness * m.s
            - self.weight_along(m)
        )
        if self.spec.contact == "flat_face":
            return needed, needed
        T, _ = self._relative(m, phi)
        normal = 1j * T / np.abs(T)
        return needed, needed / (normal * m.along.conjugate()).real

    def jump(self) -> tuple[float, float]:
        """(omega_jump [rad/s], the crank angle [rad] where contact is first lost at that steady speed): 0 when the
        spring does not hold the follower even at rest, inf when it holds it at any speed."""
        phi = self._angles()
        m = self.motion(phi)
        holding = self.spec.preload + self.spec.stiffness * m.s - self.weight_along(m)
        if np.min(holding) < 0.0:
            k = int(np.argmin(holding))
            return 0.0, float(phi[k])
        braking = m.dds < 0.0
        if not np.any(braking):
            return math.inf, math.nan
        speeds = np.full_like(phi, math.inf)
        speeds[braking] = np.sqrt(holding[braking] / (-self.generalised_mass * m.dds[braking]))
        k = int(np.argmin(speeds))
        return float(speeds[k]), float(phi[k])

    def numbers(self) -> CamNumbers:
        """The cam pair's checks over the turn: the largest pressure angle [deg] and its crank angle [deg], the
        profile's least radius of curvature where convex [m] and its crank angle, the lift [m or rad], the jump speed
        [rad/s] (jump(): 0 contact lost at rest, None never) and its crank angle [deg]."""
        phi = self._angles()
        alpha = self.pressure_angle(phi)
        radius = self.profile_radius(phi)
        k = int(np.argmax(alpha))
        convex = np.flatnonzero(radius > 0.0)
        j = int(convex[np.argmin(radius[convex])]) if convex.size else None
        speed, where = self.jump()
        return {
            "pair": self.group.pair.name,
            "follower": self.group.follower,
            "contact": self.spec.contact,
            "motion": "translating" if self.translating else "oscillating",
            "lift": float(np.max(self.motion(phi).s)),
            "pressure_angle_max_deg": math.degrees(alpha[k]),
            "pressure_angle_max_at_deg": _degrees(phi[k]),
            "least_radius": float(radius[j]) if j is not None else None,
            "least_radius_at_deg": _degrees(phi[j]) if j is not None else None,
            "jump_speed": None if math.isinf(speed) else speed,
            "jump_at_deg": None if math.isinf(speed) else _degrees(where),
        }

    def report(self) -> list[str]:
        """The cam pair's numbers as text lines (`structure`)."""
        found = self.numbers()
        kind = (
            f"translating, offset {self.offset:.6g} m"
            if self.translating
            else f"oscillating about {self.group.guide.name}, arm {self.arm:.6g} m"
        )
        unit = "m" if self.translating else "rad"
        lines = [
            (
                f"cam pair {found['pair']}: cam {self.group.pair.links[0]}, {self.spec.contact.replace('_', ' ')} "
                f"follower {self.group.follower} ({kind}), base circle {self.spec.base_radius:.6g} m, lift "
                f"{found['lift']:.6g} {unit}"
            ),
            (
                f"  pressure angle up to {found['pressure_angle_max_deg']:.3f} deg at crank angle "
                f"{found['pressure_angle_max_at_deg']:.2f} deg"
            ),
        ]
        if found["least_radius"] is not None:
            lines.append(
                f"  least radius of curvature of the profile {found['least_radius']:.6g} m at crank angle "
                f"{found['least_radius_at_deg']:.2f} deg"
            )
        spring = f"spring {self.spec.stiffness:g}, preload {self.spec.preload:g}"
        speed = found["jump_speed"]
        if speed is None:
            lines.append(f"  {spring}: the follower never decelerates; contact holds at any speed")
        elif speed == 0.0:
            lines.append(f"  {spring}: contact is lost even at rest (crank angle {found['jump_at_deg']:.2f} deg)")
        else:
            lines.append(
                f"  {spring}: the follower jumps above {speed:.6g} rad/s ({speed * 30 / math.pi:.5g} rpm), "
                f"first at crank angle {found['jump_at_deg']:.2f} deg"
            )
        return lines


def _degrees(angle: float) -> float:
    """An angle [rad] in degrees within [0, 360)."""
    return math.degrees(float(angle)) % 360.0


def follower_zero(linkage: Linkage, group: CamFollower) -> tuple[float, float]:
    """(sigma, the follower's travel d0 [m] (translating; sigma 1) or angle theta0 [rad] (oscillating) at s = 0), as
    flat_program.encode writes them into the cam record."""
    pair = CamPair(linkage, group, None, check=False)
    if pair.translating:
        return 1.0, pair.travel0
    return pair.sigma, pair.psi0 - pair.arm_angle


def cam_pairs(linkage: Linkage, groups, gravity: tuple[float, float] | None) -> list[CamPair]:
    """The CamPair of every cam follower group among `groups` (a structure's)."""
    return [CamPair(linkage, group, gravity) for group in groups if isinstance(group, CamFollower)]


def check_cams(linkage: Linkage, structure) -> None:
    """Check every cam pair of a structure (CamPair: the follower reaches the base circle, the profile is neither
    undercut nor cusped); raises LinkageError naming what is refused."""
    cam_pairs(linkage, structure.groups, None)
