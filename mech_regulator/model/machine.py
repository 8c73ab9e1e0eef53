"""The machine model: a scene assembled once into an immutable model and its right-hand side.

The model (like MuJoCo's mjModel) holds everything that does not change during a run; the state
(phi [rad], omega [rad/s]) lives in the solvers. The equation of motion is the moment form of
physics.md section 1,

    J(phi) domega/dt + 1/2 J'(phi) omega^2 = M_d + M_c,

with J = J0 + J_flywheel ratio^2 + J_links(phi). The right-hand side is specialised to the scene:
a machine without a mechanism has no J(phi), no J' term and no kinematics call at all.

A machine with an elastic coupling is the two-mass machine of physics.md section 4: the crank (the
driving part above) passes M_m = k (phi - phi2) + c (omega - omega2) to a driven part of constant
inertia I2, I2 domega2/dt = M_m + M_c2(omega2) - M_external; its states, the twist phi - phi2 and
omega2, come last in the state vector.
"""

from __future__ import annotations

import bisect
import dataclasses
import functools
import math
from dataclasses import dataclass
from fractions import Fraction
from typing import Callable

import numpy as np

from mech_regulator.effects import Effect, build_drive, build_load
from mech_regulator.effects.joint_friction import JointFrictionModel, build_joint_friction, worst_locking
from mech_regulator.governors import Governor, Guard, Mode, build_governor
from mech_regulator.mechanisms import build_reduced
from mech_regulator.scene import SceneError
from mech_regulator.scene.schema import Scene

CYCLE_POINTS_PER_TURN = 720  # samples per turn of the cycle averages of the governor's statics

Reduced = Callable[[float], tuple[float, float, float, float, float]]
RightHandSide = Callable[[float, np.ndarray], tuple[float, float] | list[float]]


@dataclass(frozen=True)
class LoadPiece:
    """The inputs held on [start, end): the external load moment value(t) = offset + slope * t [N m],
    opposing motion, and, for a machine whose governor runs outside the model (co-simulation), the
    throttle [-] that scales its drive (1 otherwise)."""

    start: float
    end: float
    offset: float
    slope: float
    throttle: float = 1.0


@dataclass(frozen=True)
class CouplingModel:
    """An elastic coupling and the driven part behind it: stiffness k [N m/rad], damping c [N m s/rad], the
    driven part's inertia I2 [kg m^2] and its resisting moments (effects of omega_driven)."""

    stiffness: float
    damping: float
    driven_inertia: float
    driven_effects: tuple[Effect, ...]

    def moment(self, twist: float, relative_speed: float) -> float:
        """The moment the coupling passes to the driven part [N m]: M_m = k twist + c (omega - omega2)
        (the crank feels -M_m)."""
        return self.stiffness * twist + self.damping * relative_speed

    def driven_moment(self, t: float, omega_driven: float) -> float:
        """Sum of the driven part's own moments at speed omega_driven [rad/s] [N m] (negative: resisting)."""
        return sum(effect.moment(t, 0.0, omega_driven, 0.0, 0.0) for effect in self.driven_effects)


@dataclass(frozen=True)
class MachineModel:
    """A scene assembled for simulation.

    inertia_constant: J0 + J_flywheel ratio^2 [kg m^2]; reduced: the mechanism's
    phi -> (J_links, dJ_links/dphi, M_weight, q, dq/dphi), or None for a constant-J machine;
    effects: the drive and loads; load_pieces: the external load in time, or () if the scene has none;
    governor: the speed governor whose throttle scales the drive, or None; coupling: the elastic coupling
    to a driven part (which then carries the external load), or None; joint_friction: the friction in the
    joints (effects.joint_friction), or None.
    """

    scene: Scene
    inertia_constant: float
    reduced: Reduced | None
    has_weight: bool
    effects: tuple[Effect, ...]
    load_pieces: tuple[LoadPiece, ...]
    governor: Governor | None = None
    coupling: CouplingModel | None = None
    joint_friction: JointFrictionModel | None = None

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
        """(angle, period) pairs [rad] where some moment jumps with phi."""
        return [(angle, effect.period) for effect in self.effects for angle in effect.switch_angles]

    def dynamic_period(self) -> float:
        """Phi_omega = lcm of the kinematic period and the effects' periods [rad] (physics.md section 1).

        Periods are taken as rational multiples of 2 pi; a machine with nothing periodic in phi gets 2 pi.
        """
        turns = [Fraction(1)]
        turns += [Fraction(effect.period / (2.0 * math.pi)).limit_denominator(360)
                  for effect in self.effects if effect.period is not None]
        lcm = turns[0]
        for turn in turns[1:]:
            numerator = math.lcm(lcm.numerator * turn.denominator, turn.numerator * lcm.denominator)
            lcm = Fraction(numerator, lcm.denominator * turn.denominator)
        return float(lcm) * 2.0 * math.pi

    def depends_on(self) -> frozenset[str]:
        """Which of 't', 'phi', 'omega' the net moment reads."""
        effects = self.effects + (self.coupling.driven_effects if self.coupling is not None else ())
        reads = set().union(*(effect.depends_on for effect in effects)) if effects else set()
        if self.has_weight:
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

    def switch_grid(self) -> list[float]:
        """All switch angles within one dynamic period, sorted, in [0, Phi_omega) [rad]."""
        period = self.dynamic_period()
        angles = set()
        for angle, switch_period in self.switch_angles():
            for k in range(int(round(period / switch_period))):
                angles.add(round((angle + k * switch_period) % period, 12))
        return sorted(angles)

    def rhs(self, piece: LoadPiece | None = None, window: tuple[float, float] | None = None,
            mode: Mode | None = None, ideal: bool = False) -> RightHandSide:
        """The right-hand side `f(t, y) = dy/dt` for one external-load piece and governor mode.

        y = [phi, omega] or, governed, [phi, omega, governor states...]. The machine's part is epsilon =
        (throttle M_drive + M_c - 1/2 dJ/dphi omega^2) / J(phi) (physics.md section 1), with throttle = 1
        without a governor. With a coupling, y ends with [twist, omega2]: the crank's M_c includes -M_m, the
        external load acts on the driven part, d twist/dt = omega - omega2 and domega2/dt = (M_m + M_c2(omega2)
        - M_external) / I2 (physics.md section 4). window = (lo, hi): the crank-angle interval between two
        switch angles the solver is in; effects that jump at switch angles then see phi clamped into it, so they
        keep their mode across the switch until the solver has located the crossing and restarted (no step
        straddles a jump). The drive is scaled by the governor's throttle(y) or, for a machine co-simulated with
        an outside governor, by the piece's held throttle. ideal: the governor without friction, limits and
        stops (the smooth model of the stability analysis).
        """
        governor = self.governor
        held_throttle = piece.throttle if piece is not None else 1.0
        scale_drive = governor is not None or held_throttle != 1.0
        scaled = tuple(effect.moment for effect in self.effects if scale_drive and effect.role == "drive")
        rest = [effect for effect in self.effects if not (scale_drive and effect.role == "drive")]
        switched = tuple(effect.moment for effect in rest if effect.switch_angles)
        smooth = tuple(effect.moment for effect in rest if not effect.switch_angles)
        if window is None:
            smooth, switched = smooth + switched, ()
            lo = hi = 0.0
        else:
            margin = 1e-9 * (window[1] - window[0])
            lo, hi = window[0] + margin, window[1] - margin
        offset, slope = (piece.offset, piece.slope) if piece is not None else (0.0, 0.0)
        J0 = self.inertia_constant
        reduced = self.reduced
        throttle = governor.throttle if governor is not None else None
        governor_rates = governor.derivatives(mode, ideal) if governor is not None else None
        coupling = self.coupling
        if coupling is not None:
            k, c, I2 = coupling.stiffness, coupling.damping, coupling.driven_inertia
            driven = tuple(effect.moment for effect in coupling.driven_effects)
            index = self.coupling_index
        plain = governor_rates is None and coupling is None

        def machine(t: float, y: np.ndarray):
            phi, omega = y[0], y[1]
            if reduced is None:
                J, dJ, total, q, dq = J0, 0.0, 0.0, 0.0, 0.0
            else:
                J_links, dJ, total, q, dq = reduced(phi)
                J = J0 + J_links
            if coupling is None:
                total -= offset + slope * t
            else:
                passed = k * y[index] + c * (omega - y[index + 1])
                total -= passed
            for moment in smooth:
                total += moment(t, phi, omega, q, dq)
            for moment in switched:
                total += moment(t, min(max(phi, lo), hi), omega, q, dq)
            if plain:
                for moment in scaled:
                    total += held_throttle * moment(t, phi, omega, q, dq)
                return omega, (total - 0.5 * dJ * omega * omega) / J
            share = held_throttle if governor_rates is None else throttle(y)
            for moment in scaled:
                total += share * moment(t, phi, omega, q, dq)
            rates = [omega, (total - 0.5 * dJ * omega * omega) / J]
            if governor_rates is not None:
                rates += governor_rates(y)
            if coupling is not None:
                omega2 = y[index + 1]
                driven_total = passed - (offset + slope * t)
                for moment in driven:
                    driven_total += moment(t, 0.0, omega2, 0.0, 0.0)
                rates += [omega - omega2, driven_total / I2]
            return rates

        if self.joint_friction is None:
            return machine
        return self._with_joint_friction(machine, scale_drive, held_throttle)

    def _with_joint_friction(self, frictionless: RightHandSide, scale_drive: bool, held_throttle: float
                             ) -> RightHandSide:
        """The right-hand side with joint friction: frictionless's rates with epsilon replaced by the root of
        `J epsilon = J epsilon_0 - sign(omega) F(epsilon)` (effects.joint_friction), epsilon_0 being the
        frictionless acceleration and F reading the force on the output link (the drive's scaled by the
        throttle)."""
        friction = self.joint_friction
        J0, reduced = self.inertia_constant, self.reduced
        throttle = self.governor.throttle if self.governor is not None else None
        output_force = self._output_force(scale_drive)

        def machine(t: float, y: np.ndarray):
            rates = list(frictionless(t, y))
            phi, omega = y[0], y[1]
            if reduced is None:
                J, q, dq = J0, 0.0, 0.0
            else:
                J_links, _, _, q, dq = reduced(phi)
                J = J0 + J_links
            share = held_throttle if throttle is None else throttle(y)
            force = output_force(t, phi, omega, q, dq, share)
            rates[1] = friction.acceleration(phi, omega, force, J, J * rates[1])
            return rates

        return machine

    def _output_force(self, scale_drive: bool) -> Callable[..., float]:
        """`force(t, phi, omega, q, dq, share)`: the generalised force on the output link [N or N m], the sum of
        the effects' output forces, the drive's times share (the throttle [-]) when scale_drive."""
        scaled = tuple(effect.output_force for effect in self.effects
                       if effect.output_force is not None and scale_drive and effect.role == "drive")
        fixed = tuple(effect.output_force for effect in self.effects
                      if effect.output_force is not None and not (scale_drive and effect.role == "drive"))

        def force(t: float, phi: float, omega: float, q: float, dq: float, share: float) -> float:
            total = 0.0
            for function in fixed:
                total += function(t, phi, omega, q, dq)
            for function in scaled:
                total += share * function(t, phi, omega, q, dq)
            return total

        return force

    def _joint_friction_columns(self, t: np.ndarray, y: np.ndarray, J: np.ndarray, moment: np.ndarray,
                                q: np.ndarray, dq: np.ndarray, throttle: np.ndarray) -> dict[str, np.ndarray]:
        """Joint friction at the samples, given J [kg m^2] and every other moment M = M_d + M_c - 1/2 J' omega^2
        [N m]: M_joint_friction, the friction reduced to the crank (J epsilon - M) [N m], and for each joint
        friction_<joint> (journal: moment rho |R| [N m]; guide: force f |N| [N]) and reaction_<joint> |R| [N];
        friction_thrust_collar [N m] with a collar."""
        friction = self.joint_friction
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
        """Index of the coupling's twist in the state vector (omega2 follows); the governor's states come before."""
        return 2 + (len(self.governor.state_names) if self.governor is not None else 0)

    def state_names(self) -> tuple[str, ...]:
        """Names of the entries of the state vector y."""
        return (("phi", "omega") + (self.governor.state_names if self.governor is not None else ())
                + (("twist", "omega_driven") if self.coupling is not None else ()))

    def initial_state(self) -> np.ndarray:
        """The state at t = 0 from the scenario (governor at rest in equilibrium unless the scene says)."""
        initial = self.scene.scenario.initial
        parts = [np.array([initial.phi, initial.omega], dtype=float)]
        if self.governor is not None:
            parts.append(self.governor.initial_state(initial.omega, initial.sleeve, initial.servo,
                                                     self.initial_balance_throttle))
        if self.coupling is not None:
            parts.append(np.array([self.static_twist(initial.omega) if initial.twist is None else initial.twist,
                                   initial.omega]))
        return np.concatenate(parts)

    def static_twist(self, omega: float) -> float:
        """The twist [rad] at which the coupling carries the driven part's loads and the external load at t = 0
        at speed omega [rad/s]: k twist = M_external - M_c2(omega)."""
        return (self.external_load(0.0) - self.coupling.driven_moment(0.0, omega)) / self.coupling.stiffness

    def initial_mode(self, y: np.ndarray) -> Mode | None:
        """The governor's mode at a state with the governor at rest (None without a governor)."""
        return self.governor.initial_mode(y) if self.governor is not None else None

    def guards(self, mode: Mode | None, y: np.ndarray | None = None) -> list:
        """The governor's guards in a mode (none without a governor) and, with joint friction and given the
        state y the solver starts from, the crank's: 'crank stops' (omega reaches 0 from the sign it has
        in y: the solver restarts there exactly, omega = 0, where friction may hold the crank at rest) or,
        starting at rest, 'crank starts' (omega leaves 0: the solver restarts to watch for the next stop)."""
        guards = self.governor.guards(mode) if self.governor is not None else []
        if self.joint_friction is None or y is None:
            return guards
        if y[1] == 0.0:
            return guards + [Guard("crank starts", lambda state: -abs(state[1]), lambda state: (mode, state))]
        direction = 1.0 if y[1] > 0.0 else -1.0

        def stop(state: np.ndarray) -> tuple[Mode | None, np.ndarray]:
            state = np.array(state, dtype=float)
            state[1] = 0.0
            return mode, state

        return guards + [Guard("crank stops", lambda state: direction * state[1], stop)]

    def cycle_averages(self, omega: float, external: float = 0.0) -> tuple[float, float, float]:
        """Cycle averages at constant crank speed omega [rad/s] over one dynamic period: (mean J [kg m^2],
        mean M_drive at full throttle [N m], mean of all other moments with the external load `external`
        [N m], which opposes motion). A coupled driven part turns with the crank in the mean: its inertia
        and moments are added (the coupling is taken as rigid).

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
        if self.coupling is not None:
            return (inertia + self.coupling.driven_inertia, drive / count,
                    other / count + self.coupling.driven_moment(0.0, omega) + weight - external)
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

    def columns(self, t: np.ndarray, y: np.ndarray, throttle: np.ndarray | None = None,
                external: np.ndarray | None = None) -> dict[str, np.ndarray]:
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
        load is not), twist [rad], omega_driven [rad/s], M_driven_<effect> and M_driven_external (moments on
        the driven part [N m]), E_elastic = 1/2 k twist^2 [J]; E_kinetic includes 1/2 I2 omega_driven^2.
        With joint friction: M_joint_friction (part of M_load), friction_<joint> and reaction_<joint>
        (_joint_friction_columns); epsilon then solves the implicit equation of effects.joint_friction.
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
        if coupling is None:
            load = load - external
        else:
            twist, omega_driven = y[self.coupling_index], y[self.coupling_index + 1]
            passed = coupling.moment(twist, y[1] - omega_driven)
            load = load - passed
        net = drive + load + weight
        if self.joint_friction is not None:
            friction_columns = self._joint_friction_columns(t, y, J, net - 0.5 * dJ * omega ** 2, q, dq, throttle)
            load = load + friction_columns["M_joint_friction"]
            net = net + friction_columns["M_joint_friction"]
        out = {"t": t, "phi": y[0], "omega": omega, "epsilon": (net - 0.5 * dJ * omega ** 2) / J, "J": J,
               "dJ_dphi": dJ, "M_drive": drive, "M_load": load}
        for k, name in enumerate(names):
            if self.effects[k].role == "load":
                out[f"M_{name}"] = per_effect[k]
        if self.has_weight:
            out["M_weight"] = weight
        if self.joint_friction is not None:
            out.update(friction_columns)
        if coupling is not None:
            out["M_coupling"] = -passed
            for effect in coupling.driven_effects:
                out[f"M_driven_{effect.name}"] = np.array([effect.moment(ti, 0.0, w, 0.0, 0.0)
                                                           for ti, w in zip(t, omega_driven)])
            out["M_driven_external"] = -external
            out["twist"], out["omega_driven"] = twist, omega_driven
            out["E_kinetic"] = 0.5 * J * omega ** 2 + 0.5 * coupling.driven_inertia * omega_driven ** 2
            out["E_elastic"] = 0.5 * coupling.stiffness * twist ** 2
        else:
            if self.load_pieces or given:
                out["M_external"] = -external
            out["E_kinetic"] = 0.5 * J * omega ** 2
        kind = self.scene.machine.mechanism.type if self.scene.machine.mechanism is not None else None
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
        if self.governor is not None:
            arm, arm_rate = y[2], y[3]
            arm_length = self.governor.sensor.arm_length
            out["throttle"] = throttle
            out["sleeve"] = 2.0 * arm_length * (1.0 - np.cos(arm))
            out["sleeve_velocity"] = 2.0 * arm_length * np.sin(arm) * arm_rate
            out["arm_angle"] = arm
            for index, name in enumerate(self.governor.state_names[2:], start=4):
                out[name] = y[index]
        return out


def crank_moments(columns: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The moments on the crank by source from MachineModel.columns [N m]: drive (throttle included),
    resistance (the machine's own loads and the links' weight), external (minus the external load) and
    net = M_d + M_c = J epsilon + 1/2 J' omega^2 (physics.md section 1)."""
    external = columns.get("M_external", np.zeros_like(columns["omega"]))
    return {"drive": columns["M_drive"], "resistance": columns["M_load"] - external + columns.get("M_weight", 0.0),
            "external": external,
            "net": columns["J"] * columns["epsilon"] + 0.5 * columns["dJ_dphi"] * columns["omega"] ** 2}


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
    """Assemble a validated scene into a MachineModel: only the effects the scene names are built."""
    machine = scene.machine
    flywheel = machine.flywheel.inertia * machine.flywheel.ratio ** 2 if machine.flywheel else 0.0
    gravity = tuple(machine.gravity) if machine.gravity is not None else None
    has_weight = machine.mechanism is not None and gravity is not None and any(gravity) and _has_mass(machine.mechanism)
    reduced = build_reduced(machine.mechanism, gravity if has_weight else None) if machine.mechanism else None
    kinematic_period = 2.0 * math.pi if machine.mechanism is not None else None
    effects = []
    if machine.drive is not None:
        effects.append(build_drive(machine.drive, machine.mechanism))
    effects += [build_load(load, kinematic_period) for load in machine.loads]
    effects = _unique_names(effects)
    coupling = None
    if machine.coupling is not None:
        driven = machine.coupling.driven
        coupling = CouplingModel(machine.coupling.stiffness, machine.coupling.damping, driven.inertia,
                                 tuple(_unique_names([build_load(load, None) for load in driven.loads])))
    model = MachineModel(scene=scene, inertia_constant=machine.inertia + flywheel, reduced=reduced,
                         has_weight=has_weight, effects=tuple(effects), load_pieces=_load_pieces(scene),
                         coupling=coupling)
    if machine.joint_friction is not None:
        model = dataclasses.replace(model, joint_friction=_joint_friction(model))
    if scene.governor is None:
        return model
    governor = build_governor(scene.governor, model.initial_balance_throttle)
    return dataclasses.replace(model, governor=governor)


def _joint_friction(model: MachineModel) -> JointFrictionModel:
    """The machine's joint friction; a self-locking machine (friction growing faster with epsilon than the
    inertia, effects.joint_friction) is refused with a SceneError."""
    friction = build_joint_friction(model.scene.machine)
    phi, ratio = worst_locking(friction, lambda angle: model.inertia(angle)[0])
    if ratio >= 1.0:
        raise SceneError(f"machine.joint_friction: the machine self-locks at phi = {math.degrees(phi):.1f} deg: there "
                         f"the joint friction grows with the crank's acceleration {ratio:.3g} times as fast as the "
                         "inertia resists it (sum rho_j |k_j| |dR_j/d epsilon| >= J), so the equation of motion has "
                         "no unique acceleration; expected smaller joint radii or coefficient, or more inertia")
    return friction


def _has_mass(mechanism) -> bool:
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
