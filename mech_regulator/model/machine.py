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

Beside this module: the modes and their guards (model/modes.py) and the output columns (model/columns.py), both
mixed into MachineModel; the elastic coupling (model/coupling.py); build_model, which assembles a scene into a
MachineModel (model/building.py).
"""

from __future__ import annotations

import bisect
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from fractions import Fraction
from typing import NamedTuple

import numpy as np
from scipy import optimize

from mech_regulator.effects import Effect, OutputCoordinate
from mech_regulator.effects.joint_friction import JointFrictionModel
from mech_regulator.effects.tables import slope_breaks
from mech_regulator.governors import GovernorKind, MachineMode
from mech_regulator.mechanisms import cam_law_angles
from mech_regulator.model.columns import MachineColumns
from mech_regulator.model.coupling import CouplingModel
from mech_regulator.model.drivetrain import ClutchModel, DrivenModel
from mech_regulator.model.modes import MachineModes
from mech_regulator.scene.schema import Scene

CYCLE_POINTS_PER_TURN = 720  # samples per turn of the cycle averages of the governor's statics

Reduced = Callable[[float], tuple[float, float, float, OutputCoordinate, OutputCoordinate]]
RightHandSide = Callable[[float, np.ndarray], tuple[float, float] | list[float]]


class LoadPiece(NamedTuple):
    """The inputs on [start, end): the external load moment value(t) = offset + slope * t [N m], opposing motion,
    and, for a machine whose governor runs outside the model (co-simulation), the throttle [-] that scales its
    drive (1 otherwise): u(t, omega) = throttle + throttle_slope s + throttle_curvature s^2 + throttle_per_speed omega,
    s = t - start, omega the crank's speed [rad/s], clamped to [throttle_low, throttle_high] (held when the three
    rates are 0; a polynomial extrapolated from the governor's last answers, or the governor's tentative throttle
    with its sensitivity to the crank's speed as the corrected coupling's corrector applies it, docs/ros.md, "The
    throttle's sensitivity to the speed", otherwise). A named tuple, immutable as a frozen dataclass and built in a
    fourth of its time: a co-simulation builds some 15 000 (docs/speed.md, "A fourth sitting")."""

    start: float
    end: float
    offset: float
    slope: float
    throttle: float = 1.0
    throttle_slope: float = 0.0  # [1/s]
    throttle_curvature: float = 0.0  # [1/s^2]
    throttle_per_speed: float = 0.0  # [s/rad]
    throttle_low: float = 0.0  # [-] the throttle's stops
    throttle_high: float = 1.0  # [-]

    def throttle_at(self, t: float, omega: float) -> float:
        """u(t, omega) [-] at time t [s] and crank speed omega [rad/s] (see the class)."""
        s = t - self.start
        command = (
            self.throttle + s * (self.throttle_slope + s * self.throttle_curvature) + self.throttle_per_speed * omega
        )
        return min(max(command, self.throttle_low), self.throttle_high)


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
class MachineModel(MachineModes, MachineColumns):
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
    governor: GovernorKind | None = None
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
        tables (effect_keys.BranchLoad), nor has a driven part behind a clutch (no angle)."""
        tables = []
        governor = self.governor
        if governor is not None and governor.valve_breaks:
            tables.append(StateTable("valve table", governor.valve_position, governor.valve_breaks))
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
        ramped = piece is not None and (
            piece.throttle_slope != 0.0 or piece.throttle_curvature != 0.0 or piece.throttle_per_speed != 0.0
        )
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
        if governor is not None and "valve table" in held:
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
            q: OutputCoordinate
            dq: OutputCoordinate
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
                share = held_throttle if ramp is None else ramp(t, omega)
                for moment in scaled:
                    total += share * moment(t, phi, omega, q, dq)
                return omega, (total - 0.5 * dJ * omega * omega) / J
            share = throttle(y) if throttle is not None else held_throttle if ramp is None else ramp(t, omega)
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


def _period_of(effect: Effect) -> float:
    """The period in phi [rad] of an effect with switch or kink angles (build_effect gives such an effect one)."""
    assert effect.period is not None, f"{effect.name} has angles in phi but no period"
    return effect.period
