"""The machine model: a scene assembled once into an immutable model and its right-hand side.

The model (like MuJoCo's mjModel) holds everything that does not change during a run; the state
(phi [rad], omega [rad/s]) lives in the solvers. The equation of motion is the moment form of
docs/theory.md §2.3,

    J(phi) domega/dt + 1/2 J'(phi) omega^2 = M_d + M_c,

with J = J0 + J_flywheel ratio^2 + J_links(phi). The right-hand side is specialised to the scene:
a machine without a mechanism has no J(phi), no J' term and no kinematics call at all.

A machine with an elastic coupling is the two-mass machine of docs/theory.md §7.1: the crank (the
driving part above) passes M_m = M_elastic(phi - phi2) + c (omega - omega2) (M_elastic = k twist or a
tabulated characteristic) to a driven part with its own mechanism and loads,
I2(phi2) domega2/dt + 1/2 I2'(phi2) omega2^2 = M_m + M_c2(t, phi2, omega2) - M_external;
its states, the twist phi - phi2 and omega2, come last in the state vector. A machine with a friction clutch has the driven part's speed
omega2 last. The driven part (possibly a branched drive), its Coulomb resistances and the modes of clutch
and driven part are in model/drivetrain.py; a mode is the governor's (sleeve, servo) followed by the
drive train's (clutch, driven part) or (driven part,).
"""

from __future__ import annotations

import bisect
import dataclasses
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
from scipy import optimize

from mech_regulator.effects import Effect, build_drive, build_load, output_position_of
from mech_regulator.effects.joint_friction import JointFrictionModel, build_joint_friction, worst_locking
from mech_regulator.effects.tables import extrapolated_linear, slope_breaks
from mech_regulator.governors import ARM, ElectronicGovernor, Governor, Guard, MachineMode, build_governor
from mech_regulator.mechanisms import build_reduced, cam_law_angles
from mech_regulator.mechanisms.checks import refuse_unbuildable
from mech_regulator.model.drivetrain import (
    BACKWARD,
    CLUTCH_CODE,
    DIRECTION,
    FORWARD,
    HELD,
    STUCK,
    ClutchModel,
    DrivenModel,
    Forces,
    build_driven,
    coulomb_factor,
    train_guards,
)
from mech_regulator.scene import SceneError
from mech_regulator.scene.schema import Linkage, Scene

CYCLE_POINTS_PER_TURN = 720  # samples per turn of the cycle averages of the governor's statics

Reduced = Callable[[float], tuple[float, float, float, float, float]]
RightHandSide = Callable[[float, np.ndarray], tuple[float, float] | list[float]]


@dataclass(frozen=True)
class LoadPiece:
    """The inputs on [start, end): the external load moment value(t) = offset + slope * t [N m], opposing motion,
    and, for a machine whose governor runs outside the model (co-simulation), the throttle [-] that scales its
    drive (1 otherwise): u(t) = throttle + throttle_slope s + throttle_curvature s^2, s = t - start, clamped to
    [0, 1] (held when both are 0; a polynomial extrapolated from the governor's last answers otherwise)."""

    start: float
    end: float
    offset: float
    slope: float
    throttle: float = 1.0
    throttle_slope: float = 0.0  # [1/s]
    throttle_curvature: float = 0.0  # [1/s^2]

    def throttle_at(self, t: float) -> float:
        """u(t) [-] (see the class)."""
        s = t - self.start
        return min(max(self.throttle + s * (self.throttle_slope + s * self.throttle_curvature), 0.0), 1.0)


@dataclass(frozen=True)
class CouplingModel:
    """An elastic coupling and the driven part behind it (docs/theory.md §7.1).

    stiffness k [N m/rad] of a linear coupling, or table = (twist [rad], moment [N m]) knots of a nonlinear
    characteristic (linear between them, end segments continued); damping c [N m s/rad]; the driven part
    (model/drivetrain.py: inertia reduced to its shaft, its mechanism, its moments read at (t, phi2, omega2,
    q2, dq2)).
    """

    stiffness: float | None
    damping: float
    driven: DrivenModel
    table: tuple[np.ndarray, np.ndarray] | None = None

    @functools.cached_property
    def elastic(self) -> Callable[..., float]:
        """twist [rad] -> M_elastic [N m] for one twist, for the hot path (elastic_moment takes arrays); a table's
        also takes anchor= (effects.tables.extrapolated_linear)."""
        if self.table is None:
            stiffness = self.stiffness
            assert stiffness is not None, "a coupling without a table has a stiffness"
            return lambda twist: stiffness * twist
        return extrapolated_linear(self.table[0].tolist(), self.table[1].tolist())

    @property
    def driven_inertia(self) -> float:
        """I2 [kg m^2], branches included."""
        return self.driven.inertia

    @property
    def driven_effects(self) -> tuple[Effect, ...]:
        """The driven part's moments (effects of omega_driven), branches' reduced."""
        return self.driven.effects

    def moment(self, twist, relative_speed):
        """The moment the coupling passes to the driven part [N m]: M_m = M_elastic(twist) + c (omega - omega2)
        (the crank feels -M_m); twist [rad] and relative_speed [rad/s] scalars or arrays."""
        return self.elastic_moment(twist) + self.damping * relative_speed

    def _segments(self, twist):
        """Knots, values, index of the table segment of each twist (end segments beyond the table), slopes."""
        knots, values = self.table
        index = np.clip(np.searchsorted(knots, twist, side="right") - 1, 0, knots.size - 2)
        slopes = np.diff(values) / np.diff(knots)
        return knots, values, index, slopes

    def elastic_moment(self, twist):
        """M_elastic(twist) [N m]: k twist, or the table linear between knots (end segments continued)."""
        if self.table is None:
            return self.stiffness * np.asarray(twist, dtype=float)
        knots, values, i, slopes = self._segments(twist)
        return values[i] + slopes[i] * (twist - knots[i])

    def local_stiffness(self, twist):
        """dM_elastic/dtwist at twist [N m/rad]: k, or the slope of the table's segment there."""
        if self.table is None:
            return self.stiffness + 0.0 * np.asarray(twist, dtype=float)
        _, _, i, slopes = self._segments(twist)
        return slopes[i]

    def elastic_energy(self, twist):
        """E_elastic = integral_0^twist M_elastic dtwist [J]: 1/2 k twist^2, or exact for the piecewise-linear
        table (a quadratic on each segment)."""
        if self.table is None:
            return 0.5 * self.stiffness * np.asarray(twist, dtype=float) ** 2
        knots, values, i, slopes = self._segments(twist)
        at_knots = np.concatenate([[0.0], np.cumsum(0.5 * (values[1:] + values[:-1]) * np.diff(knots))])
        at_knots -= at_knots[int(np.flatnonzero(knots == 0.0)[0])]
        step = twist - knots[i]
        return at_knots[i] + values[i] * step + 0.5 * slopes[i] * step**2

    def twist_for(self, moment: float) -> float:
        """The twist [rad] at which the elastic moment equals `moment` [N m] (the characteristic is strictly
        increasing, so this is unique)."""
        if self.table is None:
            assert self.stiffness is not None, "a coupling without a table has a stiffness"
            return moment / self.stiffness
        knots, values = self.table
        i = int(np.clip(np.searchsorted(values, moment, side="right") - 1, 0, knots.size - 2))
        return float(knots[i] + (moment - values[i]) * (knots[i + 1] - knots[i]) / (values[i + 1] - values[i]))

    def driven_moment(self, t: float, omega_driven: float, phi_driven: float = 0.0) -> float:
        """Sum of the driven part's own moments (its loads and its links' weight) turning forward at phi_driven
        [rad] and omega_driven [rad/s] [N m] (negative: resisting)."""
        return self.driven.forward_moment(t, omega_driven, phi_driven)

    def required_moment(self, t: float, phi_driven: float, omega: float, external: float) -> float:
        """The coupling moment [N m] that keeps the driven part at constant speed omega [rad/s] at phi_driven
        [rad] against its moments and the external load [N m]: M_m = external - M_c2 + 1/2 I2' omega^2."""
        _, slope, *_ = self.driven.state(phi_driven)
        return external - self.driven_moment(t, omega, phi_driven) + 0.5 * slope * omega * omega


@dataclass(frozen=True)
class StateTable:
    """A piecewise-linear table read at a function of the state (the valve table at the sleeve position z [m], the
    coupling characteristic at the twist [rad], a table load of a coupled driven part at its angle phi2 = phi - twist
    [rad]): value(y) is where it is read, breaks the values where its slope jumps (sorted; with a period, those in
    [0, period), repeated every period). Each break is a guard value(y) - break that changes no mode: the solvers
    restart on its crossings and between two of them see the table continued along one piece (rhs's anchors).
    angular: whether value turns with the crank angle phi (value(y) - phi independent of phi): the solvers read it,
    its pieces and its anchor on their wrapped phi (time_domain._held_pieces)."""

    name: str
    value: Callable[[np.ndarray], float]
    breaks: tuple[float, ...]
    period: float | None = None
    angular: bool = False


@dataclass(frozen=True)
class MachineModel:
    """A scene assembled for simulation.

    inertia_constant: J0 + J_flywheel ratio^2 [kg m^2]; reduced: the mechanism's
    phi -> (J_links, dJ_links/dphi, M_weight, q, dq/dphi), or None for a constant-J machine;
    effects: the drive and loads; load_pieces: the external load in time, or () if the scene has none;
    governor: the speed governor whose throttle scales the drive, or None; coupling: the elastic coupling
    to a driven part (which then carries the external load), or None; clutch: the friction clutch to a
    driven part (which then carries the external load), or None; joint_friction: the friction in the
    joints (effects.joint_friction), or None.
    """

    scene: Scene
    inertia_constant: float
    reduced: Reduced | None
    has_weight: bool
    effects: tuple[Effect, ...]
    load_pieces: tuple[LoadPiece, ...]
    governor: Governor | ElectronicGovernor | None = None
    coupling: CouplingModel | None = None
    joint_friction: JointFrictionModel | None = None
    clutch: ClutchModel | None = None

    @property
    def driven(self) -> DrivenModel | None:
        """The driven part behind the coupling or the clutch (None without one)."""
        if self.coupling is not None:
            return self.coupling.driven
        return self.clutch.driven if self.clutch is not None else None

    def breakpoints(self) -> list[float]:
        """Times where the external load has a kink or a jump: integration never steps across them."""
        return sorted({piece.start for piece in self.load_pieces[1:]})

    def piece_at(self, t: float) -> LoadPiece | None:
        """The external-load piece in force from t on (None if the scene has no external load)."""
        if not self.load_pieces:
            return None
        index = bisect.bisect_right(self.load_pieces, t, key=lambda piece: piece.start) - 1
        return self.load_pieces[max(index, 0)]

    def external_load(self, t: float) -> float:
        """External load moment magnitude at time t [N m] (the moment on the crank is minus this)."""
        piece = self.piece_at(t)
        return 0.0 if piece is None else piece.offset + piece.slope * t

    def switch_angles(self) -> list[tuple[float, float]]:
        """(angle, period) pairs [rad] where some moment jumps with phi (a cam follower's law changes segment: its
        s'' jumps, and dJ/dphi with it)."""
        cams = cam_law_angles(self.scene.machine.mechanism) if self.scene.machine.mechanism is not None else []
        return [(angle, _period_of(effect)) for effect in self.effects for angle in effect.switch_angles] + [
            (angle, 2.0 * math.pi) for angle in cams
        ]

    @functools.cached_property
    def state_tables(self) -> tuple[StateTable, ...]:
        """The tables read at a function of the state that have breakpoints (StateTable): a direct governor's valve
        table (at the sleeve position), a nonlinear coupling's characteristic (at the twist), each table load with
        kinks of a coupled driven part (periodic, at its angle phi2 = phi - twist [rad], named "driven part's <load>":
        a table in phi2 at its knots, a slider table of its mechanism where x(phi2) crosses a breakpoint; angular: its
        rhs anchor is in the solver's wrapped phi); the order of rhs's anchors. A driven part's branches have no
        tables (schema.BranchLoad), nor has a driven part behind a clutch (no angle)."""
        tables = []
        governor = self.governor
        if isinstance(governor, Governor) and governor.valve_breaks:  # a PI governor has no valve table
            sleeve, arm = governor.sensor.sleeve, ARM
            tables.append(StateTable("valve table", lambda y: sleeve(y[arm]), governor.valve_breaks))
        if self.coupling is not None:
            twist = self.driven_speed_index - 1
            if self.coupling.table is not None:
                breaks = slope_breaks(self.coupling.table[0].tolist(), self.coupling.table[1].tolist(), ends=False)
                if breaks:
                    tables.append(StateTable("coupling table", lambda y: y[twist], breaks))
            tables += [
                StateTable(
                    f"driven part's {effect.name}",
                    lambda y: y[0] - y[twist],
                    effect.kink_angles,
                    effect.period,
                    angular=True,
                )
                for effect in self.coupling.driven.effects
                if effect.kink_angles and effect.segment_moment is not None
            ]
        return tuple(tables)

    def kink_angles(self) -> list[tuple[float, float]]:
        """(angle, period) pairs [rad] where the slope of some moment in phi jumps (the knots of its tables in phi,
        joint friction's corner angles, where a joint's relative rate changes sign, every turn): the solvers restart
        on them as on switch angles, and between two of them see each table continued along one segment and the
        friction's |k_j| as s_j k_j with the signs of the window's middle (rhs's window)."""
        corners = self.joint_friction.corner_angles if self.joint_friction is not None else ()
        return [(angle, _period_of(effect)) for effect in self.effects for angle in effect.kink_angles] + [
            (angle, 2.0 * math.pi) for angle in corners
        ]

    def dynamic_period(self) -> float:
        """Phi_omega = lcm of the kinematic period and the effects' periods [rad] (docs/theory.md §2.5).

        Periods are taken as rational multiples of 2 pi; a machine with nothing periodic in phi gets 2 pi.
        """
        return self._dynamic_period

    @functools.cached_property
    def _dynamic_period(self) -> float:
        """dynamic_period, worked out once per model (the solvers ask for it at every segment)."""
        turns = [Fraction(1)]
        driven = self.driven.effects if self.driven is not None else ()
        turns += [
            Fraction(effect.period / (2.0 * math.pi)).limit_denominator(360)
            for effect in self.effects + driven
            if effect.period is not None
        ]
        lcm = turns[0]
        for turn in turns[1:]:
            numerator = math.lcm(lcm.numerator * turn.denominator, turn.numerator * lcm.denominator)
            lcm = Fraction(numerator, lcm.denominator * turn.denominator)
        return float(lcm) * 2.0 * math.pi

    def depends_on(self) -> frozenset[str]:
        """Which of 't', 'phi', 'omega' the net moment reads."""
        effects = self.effects + (self.driven.effects if self.driven is not None else ())
        reads = set().union(*(effect.depends_on for effect in effects)) if effects else set()
        if self.has_weight or (self.driven is not None and self.driven.reduced is not None):
            reads.add("phi")
        if self.load_pieces:
            reads.add("t")
        if self.joint_friction is not None:
            reads.add("omega")
        return frozenset(reads)

    def inertia(self, phi: float) -> tuple[float, float]:
        """Reduced inertia J(phi) [kg m^2] and dJ/dphi [kg m^2/rad]."""
        if self.reduced is None:
            return self.inertia_constant, 0.0
        J_links, dJ, *_ = self.reduced(phi)
        return self.inertia_constant + J_links, dJ

    def switch_grid(self, kinks: bool = True) -> list[float]:
        """All switch angles and, with kinks, kink angles within one dynamic period, sorted, in [0, Phi_omega) [rad]."""
        return list(self._switch_grid if kinks else self._jump_grid)

    @functools.cached_property
    def _switch_grid(self) -> tuple[float, ...]:
        """switch_grid(), worked out once per model (the solvers ask for it at every segment)."""
        return self._grid(self.switch_angles() + self.kink_angles())

    @functools.cached_property
    def _jump_grid(self) -> tuple[float, ...]:
        """switch_grid(kinks=False), worked out once per model."""
        return self._grid(self.switch_angles())

    def _grid(self, angles: list[tuple[float, float]]) -> tuple[float, ...]:
        """The (angle, period) pairs [rad] repeated over one dynamic period, sorted, in [0, Phi_omega) [rad]."""
        period = self.dynamic_period()
        grid = set()
        for angle, switch_period in angles:
            for k in range(int(round(period / switch_period))):
                grid.add(round((angle + k * switch_period) % period, 12))
        return tuple(sorted(grid))

    def rhs(
        self,
        piece: LoadPiece | None = None,
        window: tuple[float, float] | None = None,
        mode: MachineMode | None = None,
        ideal: bool = False,
        kinks: bool = True,
        anchors: tuple[float, ...] | None = None,
        normal_signs: tuple[float, ...] = (),
    ) -> RightHandSide:
        """The right-hand side `f(t, y) = dy/dt` for one external-load piece and mode.

        y = [phi, omega] or, governed, [phi, omega, governor states...]. The machine's part is epsilon =
        (throttle M_drive + M_c - 1/2 dJ/dphi omega^2) / J(phi) (docs/theory.md §2.3), with throttle = 1
        without a governor. With a coupling, y ends with [twist, omega2]: the crank's M_c includes -M_m, the
        external load acts on the driven part, d twist/dt = omega - omega2 and I2(phi2) domega2/dt + 1/2
        I2'(phi2) omega2^2 = M_m + M_c2(t, phi2, omega2) - M_external, phi2 = phi - twist (docs/theory.md §7.1),
        domega2/dt = 0 while the driven part is held at rest. With a clutch, y
        ends with omega2 and the crank and driven part follow the clutch's mode (model/drivetrain.py); while it
        is stuck the solver's own omega2 is frozen and `constraint` sets it to omega. window = (lo, hi): the
        crank-angle interval between two switch angles the solver is in; effects that jump at switch angles then
        see phi clamped into it, so they keep their mode across the switch until the solver has located the
        crossing and restarted (no step straddles a jump), and effects with kinks (tables in phi) see each table
        continued along the segment that holds the window's middle, so no step straddles a kink either (kinks
        False: the tables as they are, for a window between switch angles only, switch_grid(kinks=False)). The
        drive is scaled by the governor's throttle(y) or, for a machine co-simulated with an outside governor, by the
        piece's held throttle. ideal: the governor without friction, limits and stops (the smooth model of the
        stability analysis). mode None: the governor as `ideal` says and the drive train in its default mode (driven part turning forward, clutch stuck).
        With joint friction the crank's epsilon is the root of `J epsilon = J epsilon_0 - sign(omega) F(epsilon)`
        (effects.joint_friction), epsilon_0 the frictionless acceleration and F reading the force on the output
        link (the drive's scaled by the throttle). anchors (one per state_tables entry, in their units, an angular
        one's in the wrapped phi the solver integrates): each table read at a function of the state continued along the
        piece that holds that value (no step straddles its breakpoint either); None: the tables as they are.
        normal_signs (one per guide with friction, +1 or -1, in joint_friction.guides' order; (): |N|): each guide's
        friction f |x'| |N| (a crank–slider's guide, a linkage's prismatic joints) read as f |x'| s_N N, continued
        across N = 0 between two crossings of the guard guide_normal locates (effects.joint_friction).
        """
        return self._right_hand_side(
            piece,
            window if kinks else None,
            window,
            mode,
            ideal,
            crank_only=False,
            anchors=anchors,
            normal_signs=normal_signs,
        )

    def guide_normal(
        self,
        piece: LoadPiece | None = None,
        window: tuple[float, float] | None = None,
        mode: MachineMode | None = None,
        kinks: bool = True,
        anchors: tuple[float, ...] | None = None,
        normal_signs: tuple[float, ...] = (),
        guide: int = 0,
    ) -> Callable[[float, np.ndarray], float] | None:
        """(t, y) -> the normal force N [N] of guide number `guide` with friction (joint_friction.guides' order: a
        crank–slider's guide, a linkage's prismatic joints) with the acceleration of rhs(piece, window, mode,
        kinks=kinks, anchors=anchors, normal_signs=normal_signs) (the guard of the corner of its friction f |x'| |N|),
        or None for a machine without that guide with friction."""
        if self.joint_friction is None or guide >= len(self.joint_friction.guides):
            return None
        return self._right_hand_side(
            piece,
            window if kinks else None,
            window,
            mode,
            False,
            crank_only=False,
            anchors=anchors,
            normal_signs=normal_signs,
            normal=guide,
        )

    def joint_reactions(
        self,
        piece: LoadPiece | None = None,
        window: tuple[float, float] | None = None,
        mode: MachineMode | None = None,
        kinks: bool = True,
        anchors: tuple[float, ...] | None = None,
        normal_signs: tuple[float, ...] = (),
    ) -> Callable[[float, np.ndarray], list[float]] | None:
        """(t, y) -> the reaction magnitudes |R_j| [N] of the joints with friction (joint_friction.names' order) with
        the acceleration of rhs(piece, window, mode, kinks=kinks, anchors=anchors, normal_signs=normal_signs): the
        reactions the rhs reads, continued along its segment as it is (the solvers keep their steps away from the
        journals' branch points, time_domain._reaction_branches), or None for a machine without joint friction on a
        mechanism."""
        if self.joint_friction is None or self.joint_friction.loads is None:
            return None
        return self._right_hand_side(
            piece,
            window if kinks else None,
            window,
            mode,
            False,
            crank_only=False,
            anchors=anchors,
            normal_signs=normal_signs,
            reactions=True,
        )

    @functools.cached_property
    def crank_side(self) -> Callable[[float, np.ndarray], tuple[float, float]]:
        """(t, y) -> (J(phi) [kg m^2], F1 [N m]): the crank's inertia and its net moment apart from the coupling or
        clutch and the external load, F1 = throttle M_drive + M_c + M_weight - 1/2 J' omega^2 (throttle from the
        governor's state in y; joint friction, which depends on the acceleration, is not in it)."""
        return self._right_hand_side(None, None, None, None, False, crank_only=True)

    def _right_hand_side(
        self,
        piece: LoadPiece | None,
        segment: tuple[float, float] | None,
        window: tuple[float, float] | None,
        mode: MachineMode | None,
        ideal: bool,
        crank_only: bool,
        anchors: tuple[float, ...] | None = None,
        normal_signs: tuple[float, ...] = (),
        normal: int | None = None,
        reactions: bool = False,
    ) -> Callable:
        """rhs (see there) or, crank_only, crank_side, or, normal (a guide's number), guide_normal, or, reactions,
        joint_reactions; segment: the window when its tables continue along one segment (rhs's kinks), else None;
        anchors, normal_signs: rhs's."""
        held = dict(zip((table.name for table in self.state_tables), anchors)) if anchors is not None else {}
        governor = self.governor
        held_throttle = piece.throttle if piece is not None else 1.0
        ramped = piece is not None and (piece.throttle_slope != 0.0 or piece.throttle_curvature != 0.0)
        # a co-simulated throttle's polynomial; None: held_throttle
        ramp = piece.throttle_at if piece is not None and ramped else None
        scale_drive = governor is not None or held_throttle != 1.0 or ramped

        def moment_of(effect) -> Callable:
            """The effect's moment; between two kinks (segment, a window), its tables continued along one segment."""
            if segment is None or not effect.kink_angles:
                return effect.moment
            return functools.partial(effect.segment_moment, 0.5 * (segment[0] + segment[1]))

        scaled = tuple(moment_of(effect) for effect in self.effects if scale_drive and effect.role == "drive")
        rest = [effect for effect in self.effects if not (scale_drive and effect.role == "drive")]
        switched = tuple(effect.moment for effect in rest if effect.switch_angles)
        smooth = tuple(moment_of(effect) for effect in rest if not effect.switch_angles)
        if window is None:
            smooth, switched = smooth + switched, ()
            lo = hi = 0.0
        else:
            margin = 1e-9 * (window[1] - window[0])
            lo, hi = window[0] + margin, window[1] - margin
        offset, slope = (piece.offset, piece.slope) if piece is not None else (0.0, 0.0)
        J0 = self.inertia_constant
        reduced = self.reduced
        throttle: Callable[[np.ndarray], float] | None = governor.throttle if governor is not None else None
        if isinstance(governor, Governor) and "valve table" in held:  # only a Governor has one (state_tables)
            throttle = governor.held_throttle(held["valve table"])
        governor_rates = None
        if governor is not None and not crank_only:
            governor_rates = governor.derivatives((mode[0], mode[1]) if mode is not None else None, ideal)
        train = (
            None
            if crank_only or self.driven is None
            else self._train(self.train_mode_of(mode), held.get("coupling table"), held)
        )
        friction = None if crank_only else self.joint_friction
        output_force = self._output_force(scale_drive, segment) if friction is not None else None
        ratio_signs = None  # between two corners of the friction (segment), |k_j| continued as s_j k_j
        if friction is not None and segment is not None and friction.corner_angles:
            ratio_signs = friction.ratio_signs(0.5 * (segment[0] + segment[1]))
        plain = governor_rates is None and train is None and friction is None and not crank_only
        external_on_crank = train is None and not crank_only

        def machine(t: float, y: np.ndarray):
            phi, omega = y[0], y[1]
            if reduced is None:
                J, dJ, total, q, dq = J0, 0.0, 0.0, 0.0, 0.0
            else:
                J_links, dJ, total, q, dq = reduced(phi)
                J = J0 + J_links
            if external_on_crank:
                total -= offset + slope * t
            for moment in smooth:
                total += moment(t, phi, omega, q, dq)
            for moment in switched:
                total += moment(t, min(max(phi, lo), hi), omega, q, dq)
            if plain:
                share = held_throttle if ramp is None else ramp(t)
                for moment in scaled:
                    total += share * moment(t, phi, omega, q, dq)
                return omega, (total - 0.5 * dJ * omega * omega) / J
            share = throttle(y) if throttle is not None else held_throttle if ramp is None else ramp(t)
            for moment in scaled:
                total += share * moment(t, phi, omega, q, dq)
            net = total - 0.5 * dJ * omega * omega
            if crank_only:
                return J, net
            if train is None:
                epsilon, train_rates = net / J, ()
            else:
                epsilon, train_rates = train(t, y, J, net, offset + slope * t)
            # J epsilon = J epsilon_0 - sign(omega) F(epsilon), effects.joint_friction (output_force: with friction)
            if friction is not None and output_force is not None:
                force = output_force(t, phi, omega, q, dq, share)
                epsilon = friction.acceleration(phi, omega, force, J, J * epsilon, ratio_signs, normal_signs)
                if normal is not None:
                    return friction.guide_normal(phi, omega, epsilon, force, normal)
                if reactions:
                    return friction.joint_values(phi, omega, epsilon, force)[1]
            rates = [omega, epsilon]
            if governor_rates is not None:
                rates += governor_rates(y)
            rates += train_rates
            return rates

        return machine

    def _output_force(self, scale_drive: bool, segment: tuple[float, float] | None = None) -> Callable[..., float]:
        """`force(t, phi, omega, q, dq, share)`: the generalised force on the output link [N or N m], the sum of
        the effects' output forces, the drive's times share (the throttle [-]) when scale_drive; segment (a window
        between two kinks [rad], as _right_hand_side's): the tables in the output forces (a slider table's, an engine's
        pressure) read on the segment their moments are read on."""

        def force_of(effect) -> Callable:
            """The effect's output force; inside a segment, on the piece of its table held there."""
            if segment is None or effect.segment_output_force is None:
                return effect.output_force
            return functools.partial(effect.segment_output_force, 0.5 * (segment[0] + segment[1]))

        scaled = tuple(
            force_of(effect)
            for effect in self.effects
            if effect.output_force is not None and scale_drive and effect.role == "drive"
        )
        fixed = tuple(
            force_of(effect)
            for effect in self.effects
            if effect.output_force is not None and not (scale_drive and effect.role == "drive")
        )

        def force(t: float, phi: float, omega: float, q: float, dq: float, share: float) -> float:
            total = 0.0
            for function in fixed:
                total += function(t, phi, omega, q, dq)
            for function in scaled:
                total += share * function(t, phi, omega, q, dq)
            return total

        return force

    def _joint_friction_columns(
        self,
        t: np.ndarray,
        y: np.ndarray,
        J: np.ndarray,
        moment: np.ndarray,
        q: np.ndarray,
        dq: np.ndarray,
        throttle: np.ndarray,
    ) -> dict[str, np.ndarray]:
        """Joint friction at the samples, given J [kg m^2] and every other moment M = M_d + M_c - 1/2 J' omega^2
        [N m]: M_joint_friction, the friction reduced to the crank (J epsilon - M) [N m], and for each joint
        friction_<joint> (journal: moment rho |R| [N m]; guide: force f |N| [N]) and reaction_<joint> |R| [N];
        friction_thrust_collar [N m] with a collar."""
        friction = self.joint_friction
        assert friction is not None, "the joint friction columns read a machine with joint friction"
        output_force = self._output_force(True)
        n = t.size
        reduced = np.zeros(n)
        frictions = np.zeros((len(friction.names), n))
        reactions = np.zeros((len(friction.names), n))
        for i in range(n):
            phi, omega = y[0, i], y[1, i]
            force = output_force(t[i], phi, omega, q[i], dq[i], throttle[i])
            epsilon = friction.acceleration(phi, omega, force, J[i], moment[i])
            reduced[i] = J[i] * epsilon - moment[i]
            frictions[:, i], reactions[:, i], _ = friction.joint_values(phi, omega, epsilon, force)
        out = {"M_joint_friction": reduced}
        for k, name in enumerate(friction.names):
            out[f"friction_{name}"], out[f"reaction_{name}"] = frictions[k], reactions[k]
        if friction.collar > 0.0:
            out["friction_thrust_collar"] = np.full(n, friction.collar)
        return out

    def _train(
        self,
        train_mode: tuple[str, ...],
        twist_anchor: float | None = None,
        driven_anchors: dict[str, float] | None = None,
    ) -> Callable:
        """The drive train's part of the right-hand side in a train mode: (t, y, J, F1, external) -> (domega/dt,
        rates of the train's states), F1 the crank's net moment apart from the train (crank_side), external the
        external load's magnitude [N m], a Coulomb resistance of the driven part; twist_anchor [rad]: a coupling
        table continued along the segment that holds it (None: the table as it is); driven_anchors: a driven part's
        table load named in state_tables read along the segment that holds its anchor phi2 [rad] (in the solver's
        wrapped phi; absent: as it is)."""
        driven = self.driven
        assert driven is not None, "the drive train's right-hand side reads a machine with a driven part"
        index = self.driven_speed_index
        resistance = driven.resistance
        anchored = driven_anchors or {}

        def moment_of(effect) -> Callable:
            """The driven effect's moment; with an anchor, its table continued along the segment that holds it."""
            anchor = anchored.get(f"driven part's {effect.name}")
            return effect.moment if anchor is None else functools.partial(effect.segment_moment, anchor)

        smooth = tuple(moment_of(effect) for effect, dry in zip(driven.effects, driven.coulomb) if not dry)
        if self.coupling is not None:
            elastic, c, state = self.coupling.elastic, self.coupling.damping, driven.state
            if twist_anchor is not None:
                elastic = functools.partial(self.coupling.elastic, anchor=twist_anchor)
            part = train_mode[0]
            held, direction = part == HELD, DIRECTION[part]

            def coupled(t: float, y: np.ndarray, J: float, net: float, external: float):
                omega, twist, omega2 = y[1], y[index - 1], y[index]
                passed = elastic(twist) + c * (omega - omega2)
                if held:
                    return (net - passed) / J, [omega - omega2, 0.0]
                phi2 = y[0] - twist
                I2, dI2, driven_total, q2, dq2 = state(phi2)
                driven_total += passed - direction * (resistance + external) - 0.5 * dI2 * omega2 * omega2
                for moment in smooth:
                    driven_total += moment(t, phi2, omega2, q2, dq2)
                return (net - passed) / J, [omega - omega2, driven_total / I2]

            return coupled
        assert self.clutch is not None, "a driven part is behind a coupling or a clutch"
        clutch_forces = self.clutch.forces
        stuck = train_mode[0] == STUCK

        def clutched(t: float, y: np.ndarray, J: float, net: float, external: float):
            omega2 = y[1] if stuck else y[index]
            driven_total = 0.0  # DrivenModel.smooth_moment: a clutch's driven part has no mechanism (schema)
            for moment in smooth:
                driven_total += moment(t, 0.0, omega2, 0.0, 0.0)
            forces = clutch_forces(train_mode, net, J, driven_total, resistance + external)
            return forces.crank, [0.0 if stuck else forces.driven]

        return clutched

    def train_mode_of(self, mode: MachineMode | None) -> tuple[str, ...]:
        """The drive train's part of a machine's mode (its default when mode is None or carries none)."""
        train = tuple(mode[2:] if self.governor is not None else mode) if mode is not None else ()
        if train or self.driven is None:
            return train
        return (STUCK, FORWARD) if self.clutch is not None else (FORWARD,)

    def drive_train_at(
        self, t: float, y: np.ndarray, external: float | None = None, train_mode: tuple[str, ...] | None = None
    ) -> tuple[tuple[str, ...], Forces, float]:
        """(train mode, Forces, Coulomb resistance R [N m]) at time t [s] and state y, in `train_mode` or, if None,
        in the mode the state is in (a clutch or driven part at rest decided by the forces, as
        ClutchModel.mode_at); external: the external load's magnitude [N m] (default: the scenario's at t). Behind
        a coupling Forces.crank is NaN: nothing here needs the crank's acceleration (the right-hand side gives it)."""
        driven = self.driven
        assert driven is not None, "drive_train_at reads a machine with a driven part"
        resistance = driven.resistance + (self.external_load(t) if external is None else external)
        index = self.driven_speed_index
        omega2 = y[index]
        if self.clutch is not None:
            J, F1 = self.crank_side(t, y)
            if train_mode is None:
                train_mode = self.clutch.mode_at(
                    y[1] - omega2, omega2, F1, J, driven.smooth_moment(t, omega2), resistance
                )
            if train_mode[0] == STUCK:
                omega2 = y[1]
            return (
                train_mode,
                self.clutch.forces(train_mode, F1, J, driven.smooth_moment(t, omega2), resistance),
                resistance,
            )
        coupling = self.coupling
        assert coupling is not None, "a driven part is behind a coupling or a clutch"
        passed = float(coupling.elastic(y[index - 1]) + coupling.damping * (y[1] - omega2))
        inertia, smooth = driven.dynamics(t, y[0] - y[index - 1], omega2)
        push = passed + smooth
        if train_mode is None:
            train_mode = (driven.at_rest(push, resistance) if omega2 == 0.0 else FORWARD if omega2 > 0.0 else BACKWARD,)
        part = train_mode[0]
        return (
            train_mode,
            Forces(
                math.nan,
                driven.acceleration(part, passed, smooth, resistance, inertia),
                0.0,
                push,
                coulomb_factor(part, push, resistance),
            ),
            resistance,
        )

    def constraint(self, mode: MachineMode | None) -> Callable[[np.ndarray], None] | None:
        """What a mode imposes on the states the solver gives, in place, or None: a stuck clutch sets omega2 =
        omega bit for bit (the solver holds its own omega2 frozen meanwhile)."""
        if self.clutch is None or mode is None or self.train_mode_of(mode)[0] != STUCK:
            return None
        index = self.driven_speed_index

        def stuck(y: np.ndarray) -> None:
            y[index] = y[1]

        return stuck

    @property
    def coupling_index(self) -> int:
        """Index of the coupling's twist (omega2 follows) or of the clutch's omega2 in the state vector; the
        governor's states come before."""
        return 2 + (len(self.governor.state_names) if self.governor is not None else 0)

    @property
    def driven_speed_index(self) -> int:
        """Index of the driven part's speed omega2 in the state vector."""
        return self.coupling_index + (1 if self.coupling is not None else 0)

    def state_names(self) -> tuple[str, ...]:
        """Names of the entries of the state vector y."""
        return (
            ("phi", "omega")
            + (self.governor.state_names if self.governor is not None else ())
            + (("twist", "omega_driven") if self.coupling is not None else ())
            + (("omega_driven",) if self.clutch is not None else ())
        )

    def initial_state(self) -> np.ndarray:
        """The state at t = 0 from the scenario (governor at rest in equilibrium unless the scene says)."""
        initial = self.scene.scenario.initial
        parts = [np.array([initial.phi, initial.omega], dtype=float)]
        if self.governor is not None:
            parts.append(
                self.governor.initial_state(initial.omega, initial.sleeve, initial.servo, self.initial_balance_throttle)
            )
        omega_driven = initial.omega if initial.omega_driven is None else initial.omega_driven
        if self.coupling is not None:
            parts.append(
                np.array([self.static_twist(initial.omega) if initial.twist is None else initial.twist, omega_driven])
            )
        if self.clutch is not None:
            parts.append(np.array([omega_driven]))
        return np.concatenate(parts)

    def static_twist(self, omega: float) -> float:
        """The twist [rad] at which the coupling carries the driven part's loads and the external load at t = 0
        at speed omega [rad/s] with the driven part at phi_driven = phi0 - twist (phi0 the initial crank angle):
        M_elastic(twist) = CouplingModel.required_moment, solved by Brent's method when it depends on phi_driven."""
        coupling, external, phi0 = self.coupling, self.external_load(0.0), self.scene.scenario.initial.phi
        assert coupling is not None, "static_twist reads a machine with a coupling"
        if not coupling.driven.reads_angle:
            return coupling.twist_for(coupling.required_moment(0.0, phi0, omega, external))
        needed = [coupling.required_moment(0.0, angle, omega, external) for angle in np.linspace(0, 2 * math.pi, 361)]
        low, high = coupling.twist_for(min(needed)), coupling.twist_for(max(needed))
        if low == high:
            return low
        return optimize.brentq(
            lambda twist: float(coupling.elastic(twist)) - coupling.required_moment(0.0, phi0 - twist, omega, external),
            low,
            high,
            xtol=1e-15,
        )

    def initial_mode(self, y: np.ndarray) -> MachineMode | None:
        """The mode at a state with the governor at rest: the governor's (None without a governor), followed by
        the drive train's mode of the state (drive_train_at)."""
        governor = self.governor.initial_mode(y) if self.governor is not None else None
        if self.driven is None:
            return governor
        return (governor or ()) + self.drive_train_at(0.0, y)[0]

    def guards(self, mode: MachineMode | None, y: np.ndarray | None = None) -> list:
        """The governor's guards in a mode, then the drive train's (none without either) and, with joint friction
        and given the state y the solver starts from, the crank's: 'crank stops' (omega reaches 0 from the sign
        it has in y: the solver restarts there exactly, omega = 0, where friction may hold the crank at rest) or,
        starting at rest, 'crank starts' (omega leaves 0: the solver restarts to watch for the next stop). Built once
        per mode and sign of y's omega (all they depend on; the solvers ask at every segment)."""
        direction = None
        if self.joint_friction is not None and y is not None:
            direction = 0.0 if y[1] == 0.0 else 1.0 if y[1] > 0.0 else -1.0
        built = self._built_guards.get((mode, direction))
        if built is None:
            built = self._built_guards[mode, direction] = tuple(
                self._mode_guards(mode) + self._crank_guards(mode, direction)
            )
        return list(built)

    @functools.cached_property
    def _built_guards(self) -> dict:
        """guards' answers so far, by (mode, sign of omega or None)."""
        return {}

    @staticmethod
    def _crank_guards(mode: MachineMode | None, direction: float | None) -> list:
        """The crank's guard that guards ends with under joint friction: 'crank starts' from rest (direction 0),
        'crank stops' turning in the direction +-1; none for direction None (no joint friction, or no state given)."""
        if direction is None:
            return []
        if direction == 0.0:
            return [Guard("crank starts", lambda state: -abs(state[1]), lambda state: (mode, state))]

        def stop(state: np.ndarray) -> tuple[MachineMode | None, np.ndarray]:
            state = np.array(state, dtype=float)
            state[1] = 0.0
            return mode, state

        return [Guard("crank stops", lambda state: direction * state[1], stop)]

    def _mode_guards(self, mode: MachineMode | None) -> list:
        """The governor's guards in a mode, then the drive train's (none without either)."""
        if mode is None:
            return []
        governor = self.governor
        if self.driven is None:
            return governor.guards((mode[0], mode[1])) if governor is not None else []
        train_mode = self.train_mode_of(mode)
        governor_mode: MachineMode = (mode[0], mode[1]) if governor is not None else ()
        guards = (
            [_carrying(guard, train_mode) for guard in governor.guards((mode[0], mode[1]))]
            if governor is not None
            else []
        )
        return guards + train_guards(
            train_mode,
            self.driven_speed_index,
            lambda t, y: self.drive_train_at(t, y, train_mode=train_mode)[1:],
            lambda t, y: self.drive_train_at(t, y)[0],
            lambda train: governor_mode + tuple(train),
            self.clutch,
        )

    def cycle_averages(self, omega: float, external: float = 0.0) -> tuple[float, float, float]:
        """Cycle averages at constant crank speed omega [rad/s] over one dynamic period: (mean J [kg m^2],
        mean M_drive at full throttle [N m], mean of all other moments with the external load `external`
        [N m], which opposes motion). A coupled or clutched driven part turns with the crank in the mean: its
        inertia and moments are added (the coupling is taken as rigid, the clutch as stuck).

        The weight moment averages out over a turn; the J' omega^2 / 2 term averages to zero at constant
        speed. These define the cycle-averaged model J_m omega' = throttle M_d(omega) + M_c(omega) used by
        the governor's statics and linear stability. Mean of CYCLE_POINTS_PER_TURN samples per turn.
        """
        phis, inertia, weight, q, dq = self._cycle_grid
        drive = other = 0.0
        for i, phi in enumerate(phis):
            for effect in self.effects:
                value = effect.moment(0.0, phi, omega, q[i], dq[i])
                if effect.role == "drive":
                    drive += value
                else:
                    other += value
        count = len(phis)
        if self.driven is not None:  # the driven part at phi_driven = phi
            driven = self.driven
            pairs = [(driven.state(phi)[0], driven.forward_moment(0.0, omega, phi)) for phi in phis]
            mean_inertia, mean_moment = np.mean(pairs, axis=0)
            return inertia + float(mean_inertia), drive / count, other / count + float(mean_moment) + weight - external
        return inertia, drive / count, other / count + weight - external

    @property
    def mean_crank_inertia(self) -> float:
        """Mean of the crank side's reduced inertia J(phi) over one dynamic period [kg m^2] (without a coupled
        driven part)."""
        return self._cycle_grid[1]

    @functools.cached_property
    def _cycle_grid(self) -> tuple[np.ndarray, float, float, np.ndarray, np.ndarray]:
        """Crank angles over one dynamic period with the mean J and weight moment and q, dq/dphi there
        (one angle if nothing varies with phi)."""
        period = self.dynamic_period()
        count = max(1, int(round(period / (2.0 * math.pi)))) * CYCLE_POINTS_PER_TURN
        if self.reduced is None and "phi" not in self.depends_on():
            count = 1
        phis = np.arange(count) * (period / count)
        if self.reduced is None:
            return phis, self.inertia_constant, 0.0, np.zeros(count), np.zeros(count)
        J_links, _, weight, q, dq = (np.array(values, dtype=float) for values in zip(*map(self.reduced, phis)))
        return phis, self.inertia_constant + float(np.mean(J_links)), float(np.mean(weight)), q, dq

    def initial_balance_throttle(self, omega: float) -> float:
        """balance_throttle at speed omega [rad/s] for the scenario's external load at t = 0."""
        return self.balance_throttle(omega, self.external_load(0.0))

    def balance_throttle(self, omega: float, external: float) -> float:
        """Throttle at which the cycle-averaged drive balances the load (with external load `external`
        [N m]) at speed omega [-]; may lie outside 0..1 if no throttle can."""
        _, drive, other = self.cycle_averages(omega, external)
        return -other / drive if drive != 0.0 else math.nan

    def columns(
        self, t: np.ndarray, y: np.ndarray, throttle: np.ndarray | None = None, external: np.ndarray | None = None
    ) -> dict[str, np.ndarray]:
        """Output columns at sample times t [s] for states y (shape n_states x n). throttle [-] and external
        [N m] (the load's magnitude): inputs given from outside the model (co-simulation) at each sample,
        in place of the governor's throttle and the scenario's load.

        t, phi, omega, epsilon, J, dJ_dphi, M_drive (as applied, throttle included), M_load (sum of
        all resisting moments and the external load), one M_<effect> column per load (and M_weight,
        M_external when present), E_kinetic = 1/2 J omega^2, the output coordinate with its speed
        (x, v for a slider, theta4, omega4 for a rocker, x_shuttle [m], v_shuttle [m/s] for a walking beam's
        shuttle bar; with several cylinders x_slider, v_slider are piston 1's and x_slider_k, v_slider_k piston k's)
        and, governed: throttle, sleeve z [m], sleeve_velocity z' [m/s], arm_angle [rad], servo [-] and
        feedback_shift [m] where present.
        With a coupling: M_coupling = -M_m (the coupling's moment on the crank, part of M_load; the external
        load is not), twist [rad], phi_driven = phi - twist [rad], omega_driven [rad/s], I2 [kg m^2] and
        dI2_dphi2 [kg m^2/rad] (the driven part's inertia), M_driven_<effect>, M_driven_weight (with a driven
        mechanism and gravity) and M_driven_external (moments on the driven part [N m]), its mechanism's output
        (x_driven, v_driven or theta4_driven, omega4_driven), E_elastic = integral_0^twist M_elastic dtwist
        [J]; E_kinetic includes 1/2 I2 omega_driven^2.
        With joint friction: M_joint_friction (part of M_load), friction_<joint> and reaction_<joint>
        (_joint_friction_columns); epsilon then solves the implicit equation of effects.joint_friction.
        With a clutch: clutch_torque (the moment it passes to the driven part; M_load includes minus it) [N m],
        slip_speed = omega - omega_driven [rad/s], clutch_mode (0 stuck, +1 slipping with the motor ahead, -1
        with the machine ahead), omega_driven, M_driven_<effect>, M_driven_external, E_kinetic as above. Either
        driven part adds epsilon_driven [rad/s^2], driven_mode (+1 turning forward, -1 backward, 0 held at rest
        by its resistances), its loads reduced to its shaft as M_driven_<effect> (a branch's as
        M_driven_<branch>_<effect>; Coulomb ones as mobilised) and the torque in each branch's section
        M_section_<branch> = M_n,c + (I_n / i_1n) epsilon_driven on the branch's shaft [N m].
        """
        n = t.size
        names = [effect.name for effect in self.effects]
        per_effect = np.zeros((len(names), n))
        J = np.full(n, self.inertia_constant)
        dJ = np.zeros(n)
        weight = np.zeros(n)
        cylinders = getattr(self.scene.machine.mechanism, "cylinders", None)
        q = np.zeros((n, len(cylinders)) if cylinders else n)  # several cylinders: one column per piston
        dq = np.zeros_like(q)
        given = external is not None
        external = np.array([self.external_load(ti) for ti in t]) if external is None else np.asarray(external)
        outside_throttle = throttle is not None
        throttle = np.ones(n) if throttle is None else np.array(throttle, dtype=float)
        for i in range(n):
            phi, omega = y[0, i], y[1, i]
            if self.reduced is not None:
                J_links, dJ[i], weight[i], q[i], dq[i] = self.reduced(phi)
                J[i] += J_links
            for k, effect in enumerate(self.effects):
                per_effect[k, i] = effect.moment(t[i], phi, omega, q[i], dq[i])
            if self.governor is not None and not outside_throttle:
                throttle[i] = self.governor.throttle(y[:, i])
        omega = y[1]
        drive = throttle * sum((per_effect[k] for k, e in enumerate(self.effects) if e.role == "drive"), np.zeros(n))
        load = sum((per_effect[k] for k, e in enumerate(self.effects) if e.role == "load"), np.zeros(n))
        coupling = self.coupling
        driven = self.driven
        if driven is not None:
            train = [self.drive_train_at(ti, y[:, i], external[i]) for i, ti in enumerate(t)]
            forces = {
                key: np.array([getattr(state[1], key) for state in train]) for key in ("driven", "clutch", "factor")
            }
            omega_driven = y[self.driven_speed_index]
        if driven is None:
            load = load - external
        elif coupling is not None:
            twist = y[self.coupling_index]
            passed = coupling.moment(twist, y[1] - omega_driven)
            load = load - passed
        else:
            load = load - forces["clutch"]
        net = drive + load + weight
        if self.joint_friction is not None:
            friction_columns = self._joint_friction_columns(t, y, J, net - 0.5 * dJ * omega**2, q, dq, throttle)
            load = load + friction_columns["M_joint_friction"]
            net = net + friction_columns["M_joint_friction"]
        out = {
            "t": t,
            "phi": y[0],
            "omega": omega,
            "epsilon": (net - 0.5 * dJ * omega**2) / J,
            "J": J,
            "dJ_dphi": dJ,
            "M_drive": drive,
            "M_load": load,
        }
        for k, name in enumerate(names):
            if self.effects[k].role == "load":
                out[f"M_{name}"] = per_effect[k]
        if self.has_weight:
            out["M_weight"] = weight
        if self.joint_friction is not None:
            out.update(friction_columns)
        if coupling is not None:
            out["M_coupling"] = -passed
        if self.clutch is not None:
            out["clutch_torque"] = forces["clutch"]
            out["slip_speed"] = omega - omega_driven
            out["clutch_mode"] = np.array([CLUTCH_CODE[state[0][0]] for state in train])
        if driven is not None:
            phi_driven = y[0] - twist if coupling is not None else np.zeros(n)
            state = np.array([driven.state(p) for p in phi_driven]).T.reshape(5, n)
            for effect, dry in zip(driven.effects, driven.coulomb):
                moment = np.array(
                    [
                        effect.moment(ti, p, w, q2, dq2)
                        for ti, p, w, q2, dq2 in zip(t, phi_driven, omega_driven, state[3], state[4])
                    ]
                )
                out[f"M_driven_{effect.name}"] = moment * forces["factor"] if dry else moment
            if driven.has_weight:
                out["M_driven_weight"] = state[2]
            out["M_driven_external"] = -external * forces["factor"]
            if coupling is not None:
                out["twist"], out["phi_driven"] = twist, phi_driven
                out["I2"], out["dI2_dphi2"] = state[0], state[1]
                assert self.scene.machine.coupling is not None, "the model's coupling is the scene's"
                driven_mechanism = self.scene.machine.coupling.driven.mechanism
                if driven_mechanism is not None:
                    slider = (
                        driven_mechanism.type == "crank_slider"
                        or getattr(driven_mechanism, "output_kind", None) == "slider"
                    )
                    position, speed = ("x_driven", "v_driven") if slider else ("theta4_driven", "omega4_driven")
                    out[position], out[speed] = state[3], state[4] * omega_driven
            out["omega_driven"] = omega_driven
            out["epsilon_driven"] = forces["driven"]
            out["driven_mode"] = np.array([DIRECTION[state[0][-1]] for state in train])
            for branch in driven.branches:
                resisting = -branch.ratio * sum(out[f"M_driven_{driven.effects[i].name}"] for i in branch.effects)
                out[f"M_section_{branch.name}"] = resisting + branch.inertia / branch.ratio * forces["driven"]
            out["E_kinetic"] = 0.5 * J * omega**2 + 0.5 * state[0] * omega_driven**2
            if coupling is not None:
                out["E_elastic"] = coupling.elastic_energy(twist)
        else:
            if self.load_pieces or given:
                out["M_external"] = -external
            out["E_kinetic"] = 0.5 * J * omega**2
        mechanism = self.scene.machine.mechanism
        kind = mechanism.type if mechanism is not None else None
        if kind == "crank_slider" and cylinders:
            out["x_slider"], out["v_slider"] = q[:, 0], dq[:, 0] * omega  # piston 1
            for k in range(1, len(cylinders)):
                out[f"x_slider_{k + 1}"], out[f"v_slider_{k + 1}"] = q[:, k], dq[:, k] * omega
        elif kind == "crank_slider":
            out["x_slider"], out["v_slider"] = q, dq * omega
        elif kind == "four_bar":
            out["theta4"], out["omega4"] = q, dq * omega
        elif kind == "walking_beam":
            out["x_shuttle"], out["v_shuttle"] = q, dq * omega
        elif isinstance(mechanism, Linkage) and mechanism.output is not None:  # its output: a travel or an angle
            position, speed = ("x_output", "v_output") if mechanism.output.joint else ("theta_output", "omega_output")
            out[position], out[speed] = q, dq * omega
        if self.governor is not None:
            out["throttle"] = throttle
            out.update(self.governor.signals(y))
        return out


def crank_moments(columns: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The moments on the crank by source from MachineModel.columns [N m]: drive (throttle included),
    resistance (the machine's own loads and the links' weight), external (minus the external load) and
    net = M_d + M_c = J epsilon + 1/2 J' omega^2 (docs/theory.md §2.3)."""
    external = columns.get("M_external", np.zeros_like(columns["omega"]))
    return {
        "drive": columns["M_drive"],
        "resistance": columns["M_load"] - external + columns.get("M_weight", 0.0),
        "external": external,
        "net": columns["J"] * columns["epsilon"] + 0.5 * columns["dJ_dphi"] * columns["omega"] ** 2,
    }


def _load_pieces(scene: Scene) -> tuple[LoadPiece, ...]:
    """Split the scenario's external load into pieces that are constant or linear in time."""
    scenario = scene.scenario
    if scenario.external_load == 0.0 and not scenario.load_events:
        return ()
    pieces: list[LoadPiece] = []
    now, value = 0.0, scenario.external_load
    for event in scenario.load_events:
        if event.time > now:
            pieces.append(LoadPiece(now, event.time, value, 0.0))
        if event.ramp > 0.0:
            slope = (event.torque - value) / event.ramp
            pieces.append(LoadPiece(event.time, event.time + event.ramp, value - slope * event.time, slope))
        now, value = event.time + event.ramp, event.torque
    if now < scenario.duration or not pieces:
        pieces.append(LoadPiece(now, scenario.duration, value, 0.0))
    return tuple(pieces)


def build_model(scene: Scene) -> MachineModel:
    """Assemble a validated scene into a MachineModel: only the effects the scene names are built; a scene whose
    mechanisms cannot be built is refused (SceneError, mechanisms/checks.py)."""
    machine = refuse_unbuildable(scene).machine
    flywheel = machine.flywheel.inertia * machine.flywheel.ratio**2 if machine.flywheel else 0.0
    gravity = (machine.gravity[0], machine.gravity[1]) if machine.gravity is not None else None
    has_weight = machine.mechanism is not None and (
        (gravity is not None and any(gravity) and _has_mass(machine.mechanism)) or has_cam_springs(machine.mechanism)
    )  # in M_weight too
    reduced = build_reduced(machine.mechanism, gravity if has_weight else None) if machine.mechanism else None
    _check_inertia(machine, machine.inertia + flywheel, reduced)
    kinematic_period = 2.0 * math.pi if machine.mechanism is not None else None
    effects = []
    if machine.drive is not None:
        effects.append(build_drive(machine.drive, machine.mechanism))
    effects += [build_load(load, kinematic_period, output_position_of(reduced)) for load in machine.loads]
    effects = _unique_names(effects)
    coupling = _coupling_model(machine, gravity)
    clutch = None
    if machine.clutch is not None:
        clutch = ClutchModel(
            machine.clutch.static_torque,
            machine.clutch.kinetic_torque,
            build_driven(machine.clutch.driven, _unique_names),
        )
    model = MachineModel(
        scene=scene,
        inertia_constant=machine.inertia + flywheel,
        reduced=reduced,
        has_weight=has_weight,
        effects=tuple(effects),
        load_pieces=_load_pieces(scene),
        coupling=coupling,
        clutch=clutch,
    )
    if machine.joint_friction is not None:
        model = dataclasses.replace(model, joint_friction=_joint_friction(model))
    if scene.governor is None:
        return model
    governor = build_governor(scene.governor, model.initial_balance_throttle)
    return dataclasses.replace(model, governor=governor)


def _coupling_model(machine, gravity: tuple[float, float] | None) -> CouplingModel | None:
    """The coupling and driven part of a scene's machine (None without machine.coupling); the driven
    mechanism's links weigh under the machine's gravity."""
    coupling = machine.coupling
    if coupling is None:
        return None
    mechanism = coupling.driven.mechanism
    if (
        mechanism is not None
        and mechanism.type == "linkage"
        and any(joint.type == "cam" for joint in mechanism.joints.values())
    ):
        raise SceneError(
            "machine.coupling.driven.mechanism has a cam pair: a cam behind a coupling is not supported "
            "yet (its contact is checked on the machine's own mechanism only); expected the cam on "
            "machine.mechanism"
        )
    weighs = mechanism is not None and gravity is not None and any(gravity) and _has_mass(mechanism)
    reduced = build_reduced(mechanism, gravity if weighs else None) if mechanism is not None else None
    driven = build_driven(coupling.driven, _unique_names, reduced, weighs)
    table = coupling.characteristic
    if table is None:
        return CouplingModel(coupling.stiffness, coupling.damping, driven)
    return CouplingModel(None, coupling.damping, driven, (np.array(table.twist), np.array(table.moment)))


def _joint_friction(model: MachineModel) -> JointFrictionModel:
    """The machine's joint friction; a self-locking machine (friction growing faster with epsilon than the
    inertia, effects.joint_friction) is refused with a SceneError."""
    friction = build_joint_friction(model.scene.machine)
    phi, ratio = worst_locking(friction, lambda angle: model.inertia(angle)[0])
    if ratio >= 1.0:
        raise SceneError(
            f"machine.joint_friction: the machine self-locks at phi = {math.degrees(phi):.1f} deg: there "
            f"the joint friction grows with the crank's acceleration {ratio:.3g} times as fast as the "
            "inertia resists it (sum rho_j |k_j| |dR_j/d epsilon| >= J), so the equation of motion has "
            "no unique acceleration; expected smaller joint radii or coefficient, or more inertia"
        )
    return friction


def _carrying(guard: Guard, train_mode: tuple[str, ...]) -> Guard:
    """A governor's guard whose transition keeps the drive train's mode after the governor's new mode."""

    def transition(y: np.ndarray) -> tuple[MachineMode, np.ndarray]:
        governor_mode, state = guard.transition(y)
        assert governor_mode is not None, "a governor's guard gives the governor's new mode"
        return governor_mode + train_mode, state

    return Guard(guard.name, guard.value, transition)


INERTIA_SCAN_POINTS = 720  # crank angles over a turn at which J(phi) is checked before its smallest value is refined


def _check_inertia(machine, J0: float, reduced: Reduced | None) -> None:
    """Refuse with a SceneError a machine whose reduced inertia J(phi) = J0 + J_links(phi) is not finite, or falls below
    MIN_INERTIA or below MIN_INERTIA_FRACTION of its largest value (limits.py) somewhere in a turn (a crank-slider
    with only a slider mass and no machine.inertia has J = 0 at the dead centres), or whose driven part's inertia is
    below MIN_INERTIA: there the acceleration M / J has no bound (or overflows) and the solvers grind to a halt. J is
    scanned at INERTIA_SCAN_POINTS angles and its smallest value refined by a bounded Brent search; the message
    names the keys and the mechanism's values."""
    from mech_regulator.scene.limits import MIN_INERTIA, MIN_INERTIA_FRACTION

    for key in ("coupling", "clutch"):
        part = getattr(machine, key)
        if part is not None and part.driven.inertia < MIN_INERTIA:
            raise SceneError(
                f"machine.{key}.driven.inertia = {part.driven.inertia:g} kg m^2: below the limit of "
                f"{MIN_INERTIA:g} kg m^2 for an inertia (moments divided by it would overflow)"
            )
    advice = "give machine.inertia > 0 (the rotor's, the crank's) or a flywheel"
    if reduced is None:
        if J0 < MIN_INERTIA:
            raise SceneError(
                f"machine.inertia = {machine.inertia:g} kg m^2 (with the flywheel's, J = {J0:g} kg m^2): "
                f"below the limit of {MIN_INERTIA:g} kg m^2 for an inertia (moments divided by it "
                "would overflow)"
            )
        return

    def inertia(phi: float) -> float:
        return J0 + reduced(phi)[0]

    phis = np.linspace(0.0, 2.0 * math.pi, INERTIA_SCAN_POINTS, endpoint=False)
    with np.errstate(all="ignore"):
        J = np.array([inertia(phi) for phi in phis], dtype=float)
    mechanism = machine.mechanism
    values = ", ".join(f"{key} {value:g}" for key, value in mechanism.model_dump().items() if isinstance(value, float))
    keys = (
        f"(J0 = machine.inertia + flywheel = {J0:g} kg m^2; machine.mechanism, type {mechanism.type}: {values}; "
        "lengths in m, masses in kg, inertias in kg m^2)"
    )
    if not np.all(np.isfinite(J)):
        where = math.degrees(phis[int(np.argmax(~np.isfinite(J)))])
        raise SceneError(
            f"machine: the reduced inertia J(phi) is not finite at phi = {where:.1f} deg {keys}; "
            "expected the lengths and masses of a real mechanism"
        )
    index, step = int(np.argmin(J)), phis[1] - phis[0]
    found = optimize.minimize_scalar(
        inertia, bounds=(phis[index] - step, phis[index] + step), method="bounded", options={"xatol": 1e-12}
    )
    J_min, phi_min = min((float(found.fun), float(found.x)), (float(J[index]), float(phis[index])))
    J_max = float(np.max(J))
    if J_min > MIN_INERTIA_FRACTION * J_max and J_min >= MIN_INERTIA:
        return
    limit = (
        f"above {MIN_INERTIA_FRACTION:g} of its largest value"
        if J_min <= MIN_INERTIA_FRACTION * J_max
        else f"at least {MIN_INERTIA:g} kg m^2 (the limit for an inertia)"
    )
    raise SceneError(
        f"machine: the reduced inertia J(phi) falls to {J_min:.3g} kg m^2 at phi = "
        f"{math.degrees(phi_min) % 360.0:.2f} deg (its largest: {J_max:.3g} kg m^2) {keys}; there the "
        f"crank's acceleration M / J has no bound: expected J(phi) {limit} over the whole turn: {advice}"
    )


def has_cam_springs(mechanism) -> bool:
    """Whether a linkage has a cam follower's spring (its moment is carried in the reduction's M_weight)."""
    return mechanism.type == "linkage" and any(
        joint.type == "cam" and joint.spring is not None for joint in mechanism.joints.values()
    )


def _has_mass(mechanism) -> bool:
    if mechanism.type == "linkage":  # a general linkage's masses are its links'
        return any(link.mass > 0 for link in mechanism.links.values())
    return any(getattr(mechanism, key) > 0 for key in type(mechanism).model_fields if key.endswith("_mass"))


def _unique_names(effects: list[Effect]) -> list[Effect]:
    """Rename repeated effect names to name_2, name_3, ... so output columns stay distinct."""
    seen: dict[str, int] = {}
    unique = []
    for effect in effects:
        seen[effect.name] = seen.get(effect.name, 0) + 1
        if seen[effect.name] > 1:
            effect = Effect(**{**effect.__dict__, "name": f"{effect.name}_{seen[effect.name]}"})
        unique.append(effect)
    return unique


def _period_of(effect: Effect) -> float:
    """The period in phi [rad] of an effect with switch or kink angles (build_effect gives such an effect one)."""
    assert effect.period is not None, f"{effect.name} has angles in phi but no period"
    return effect.period
