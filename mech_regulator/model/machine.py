"""The machine model: a scene assembled once into an immutable model and its right-hand side.

The model (like MuJoCo's mjModel) holds everything that does not change during a run; the state
(phi [rad], omega [rad/s]) lives in the solvers. The equation of motion is the moment form of
physics.md section 1,

    J(phi) domega/dt + 1/2 J'(phi) omega^2 = M_d + M_c,

with J = J0 + J_flywheel ratio^2 + J_links(phi). The right-hand side is specialised to the scene:
a machine without a mechanism has no J(phi), no J' term and no kinematics call at all.

A machine with an elastic coupling is the two-mass machine of physics.md section 4: the crank (the
driving part above) passes M_m = M_elastic(phi - phi2) + c (omega - omega2) (M_elastic = k twist or a
tabulated characteristic) to a driven part with its own mechanism and loads,
I2(phi2) domega2/dt + 1/2 I2'(phi2) omega2^2 = M_m + M_c2(t, phi2, omega2) - M_external;
its states, the twist phi - phi2 and omega2, come last in the state vector.
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
from scipy import optimize

from mech_regulator.effects import Effect, build_drive, build_load
from mech_regulator.effects.tables import extrapolated_linear
from mech_regulator.governors import Governor, Mode, build_governor
from mech_regulator.mechanisms import build_reduced
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
    """An elastic coupling and the driven part behind it (physics.md section 4).

    stiffness k [N m/rad] of a linear coupling, or table = (twist [rad], moment [N m]) knots of a nonlinear
    characteristic (linear between them, end segments continued); elastic: twist -> M_elastic [N m] for the
    hot path; damping c [N m s/rad]; the driven part: constant inertia [kg m^2], driven_reduced: its
    mechanism's phi2 -> (I_links, dI_links/dphi2, M_weight, q2, dq2/dphi2) or None; driven_effects: its
    resisting moments, read at (t, phi2, omega2, q2, dq2).
    """

    stiffness: float | None
    damping: float
    driven_inertia: float
    driven_effects: tuple[Effect, ...]
    elastic: Callable[[float], float]
    table: tuple[np.ndarray, np.ndarray] | None = None
    driven_reduced: Reduced | None = None
    driven_has_weight: bool = False

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
        return at_knots[i] + values[i] * step + 0.5 * slopes[i] * step ** 2

    def twist_for(self, moment: float) -> float:
        """The twist [rad] at which the elastic moment equals `moment` [N m] (the characteristic is strictly
        increasing, so this is unique)."""
        if self.table is None:
            return moment / self.stiffness
        knots, values = self.table
        i = int(np.clip(np.searchsorted(values, moment, side="right") - 1, 0, knots.size - 2))
        return float(knots[i] + (moment - values[i]) * (knots[i + 1] - knots[i]) / (values[i + 1] - values[i]))

    @property
    def reads_angle(self) -> bool:
        """Whether the driven part's inertia or moments depend on its angle phi2."""
        return self.driven_reduced is not None or any("phi" in e.depends_on for e in self.driven_effects)

    def driven_state(self, phi2: float) -> tuple[float, float, float, float, float]:
        """(I2 [kg m^2], dI2/dphi2 [kg m^2/rad], M_weight [N m], q2, dq2/dphi2) of the driven part at phi2 [rad]."""
        if self.driven_reduced is None:
            return self.driven_inertia, 0.0, 0.0, 0.0, 0.0
        links, slope, weight, q, dq = self.driven_reduced(phi2)
        return self.driven_inertia + links, slope, weight, q, dq

    def driven_moment(self, t: float, omega_driven: float, phi_driven: float = 0.0) -> float:
        """Sum of the driven part's own moments (its loads and its links' weight) at phi_driven [rad] and
        omega_driven [rad/s] [N m] (negative: resisting)."""
        _, _, weight, q, dq = self.driven_state(phi_driven)
        return weight + sum(effect.moment(t, phi_driven, omega_driven, q, dq) for effect in self.driven_effects)

    def required_moment(self, t: float, phi_driven: float, omega: float, external: float) -> float:
        """The coupling moment [N m] that keeps the driven part at constant speed omega [rad/s] at phi_driven
        [rad] against its moments and the external load [N m]: M_m = external - M_c2 + 1/2 I2' omega^2."""
        _, slope, *_ = self.driven_state(phi_driven)
        return external - self.driven_moment(t, omega, phi_driven) + 0.5 * slope * omega * omega


@dataclass(frozen=True)
class MachineModel:
    """A scene assembled for simulation.

    inertia_constant: J0 + J_flywheel ratio^2 [kg m^2]; reduced: the mechanism's
    phi -> (J_links, dJ_links/dphi, M_weight, q, dq/dphi), or None for a constant-J machine;
    effects: the drive and loads; load_pieces: the external load in time, or () if the scene has none;
    governor: the speed governor whose throttle scales the drive, or None; coupling: the elastic coupling
    to a driven part (which then carries the external load), or None.
    """

    scene: Scene
    inertia_constant: float
    reduced: Reduced | None
    has_weight: bool
    effects: tuple[Effect, ...]
    load_pieces: tuple[LoadPiece, ...]
    governor: Governor | None = None
    coupling: CouplingModel | None = None

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
        driven = self.coupling.driven_effects if self.coupling is not None else ()
        turns += [Fraction(effect.period / (2.0 * math.pi)).limit_denominator(360)
                  for effect in self.effects + driven if effect.period is not None]
        lcm = turns[0]
        for turn in turns[1:]:
            numerator = math.lcm(lcm.numerator * turn.denominator, turn.numerator * lcm.denominator)
            lcm = Fraction(numerator, lcm.denominator * turn.denominator)
        return float(lcm) * 2.0 * math.pi

    def depends_on(self) -> frozenset[str]:
        """Which of 't', 'phi', 'omega' the net moment reads."""
        effects = self.effects + (self.coupling.driven_effects if self.coupling is not None else ())
        reads = set().union(*(effect.depends_on for effect in effects)) if effects else set()
        if self.has_weight or (self.coupling is not None and self.coupling.driven_reduced is not None):
            reads.add("phi")
        if self.load_pieces:
            reads.add("t")
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
        external load acts on the driven part, d twist/dt = omega - omega2 and I2(phi2) domega2/dt + 1/2
        I2'(phi2) omega2^2 = M_m + M_c2(t, phi2, omega2) - M_external, phi2 = phi - twist (physics.md section 4).
        window = (lo, hi): the crank-angle interval between two
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
            elastic, c = coupling.elastic, coupling.damping
            driven_state = coupling.driven_state
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
                passed = elastic(y[index]) + c * (omega - y[index + 1])
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
                phi2, omega2 = phi - y[index], y[index + 1]
                I2, dI2, driven_total, q2, dq2 = driven_state(phi2)
                driven_total += passed - (offset + slope * t)
                for moment in driven:
                    driven_total += moment(t, phi2, omega2, q2, dq2)
                rates += [omega - omega2, (driven_total - 0.5 * dI2 * omega2 * omega2) / I2]
            return rates

        return machine

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
        at speed omega [rad/s] with the driven part at phi_driven = phi0 - twist (phi0 the initial crank angle):
        M_elastic(twist) = CouplingModel.required_moment, solved by Brent's method when it depends on phi_driven."""
        coupling, external, phi0 = self.coupling, self.external_load(0.0), self.scene.scenario.initial.phi
        if not coupling.reads_angle:
            return coupling.twist_for(coupling.required_moment(0.0, phi0, omega, external))
        needed = [coupling.required_moment(0.0, angle, omega, external) for angle in np.linspace(0, 2 * math.pi, 361)]
        low, high = coupling.twist_for(min(needed)), coupling.twist_for(max(needed))
        if low == high:
            return low
        return optimize.brentq(lambda twist: float(coupling.elastic(twist)) - coupling.required_moment(
            0.0, phi0 - twist, omega, external), low, high, xtol=1e-15)

    def initial_mode(self, y: np.ndarray) -> Mode | None:
        """The governor's mode at a state with the governor at rest (None without a governor)."""
        return self.governor.initial_mode(y) if self.governor is not None else None

    def guards(self, mode: Mode | None) -> list:
        """The governor's guards in a mode (none without a governor)."""
        return self.governor.guards(mode) if self.governor is not None else []

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
        if self.coupling is not None:  # the driven part at phi_driven = phi
            coupling = self.coupling
            driven = [(coupling.driven_state(phi)[0], coupling.driven_moment(0.0, omega, phi)) for phi in phis]
            mean_inertia, mean_moment = np.mean(driven, axis=0)
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
        values = np.array([self.reduced(phi) for phi in phis])
        return (phis, self.inertia_constant + float(np.mean(values[:, 0])), float(np.mean(values[:, 2])),
                values[:, 3], values[:, 4])

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
        (x, v for a slider, theta4, omega4 for a rocker) and, governed: throttle, sleeve z [m],
        sleeve_velocity z' [m/s], arm_angle [rad], servo [-] and feedback_shift [m] where present.
        With a coupling: M_coupling = -M_m (the coupling's moment on the crank, part of M_load; the external
        load is not), twist [rad], phi_driven = phi - twist [rad], omega_driven [rad/s], epsilon_driven
        [rad/s^2], I2 [kg m^2] and dI2_dphi2 [kg m^2/rad] (the driven part's inertia), M_driven_<effect>,
        M_driven_weight (with a driven mechanism and gravity) and M_driven_external (moments on the driven part
        [N m]), its mechanism's output (x_driven, v_driven or theta4_driven, omega4_driven), E_elastic =
        integral_0^twist M_elastic dtwist [J]; E_kinetic includes 1/2 I2 omega_driven^2.
        """
        n = t.size
        names = [effect.name for effect in self.effects]
        per_effect = np.zeros((len(names), n))
        J = np.full(n, self.inertia_constant)
        dJ = np.zeros(n)
        weight = np.zeros(n)
        q = np.zeros(n)
        dq = np.zeros(n)
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
        out = {"t": t, "phi": y[0], "omega": omega, "epsilon": (net - 0.5 * dJ * omega ** 2) / J, "J": J,
               "dJ_dphi": dJ, "M_drive": drive, "M_load": load}
        for k, name in enumerate(names):
            if self.effects[k].role == "load":
                out[f"M_{name}"] = per_effect[k]
        if self.has_weight:
            out["M_weight"] = weight
        if coupling is not None:
            out["M_coupling"] = -passed
            phi_driven = y[0] - twist
            driven = np.array([coupling.driven_state(p) for p in phi_driven]).T.reshape(5, n)
            I2, dI2 = driven[0], driven[1]
            driven_net = passed - external - 0.5 * dI2 * omega_driven ** 2
            for effect in coupling.driven_effects:
                moment = np.array([effect.moment(ti, p, w, q2, dq2) for ti, p, w, q2, dq2
                                   in zip(t, phi_driven, omega_driven, driven[3], driven[4])])
                out[f"M_driven_{effect.name}"] = moment
                driven_net = driven_net + moment
            if coupling.driven_has_weight:
                out["M_driven_weight"] = driven[2]
                driven_net = driven_net + driven[2]
            out["M_driven_external"] = -external
            out["twist"], out["phi_driven"], out["omega_driven"] = twist, phi_driven, omega_driven
            out["epsilon_driven"] = driven_net / I2
            out["I2"], out["dI2_dphi2"] = I2, dI2
            kind = self.scene.machine.coupling.driven.mechanism
            if kind is not None:
                names = ("x_driven", "v_driven") if kind.type == "crank_slider" else ("theta4_driven", "omega4_driven")
                out[names[0]], out[names[1]] = driven[3], driven[4] * omega_driven
            out["E_kinetic"] = 0.5 * J * omega ** 2 + 0.5 * I2 * omega_driven ** 2
            out["E_elastic"] = coupling.elastic_energy(twist)
        else:
            if self.load_pieces or given:
                out["M_external"] = -external
            out["E_kinetic"] = 0.5 * J * omega ** 2
        kind = self.scene.machine.mechanism.type if self.scene.machine.mechanism is not None else None
        if kind == "crank_slider":
            out["x_slider"], out["v_slider"] = q, dq * omega
        elif kind == "four_bar":
            out["theta4"], out["omega4"] = q, dq * omega
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
        effects.append(build_drive(machine.drive))
    effects += [build_load(load, kinematic_period) for load in machine.loads]
    effects = _unique_names(effects)
    coupling = _coupling_model(machine, gravity)
    model = MachineModel(scene=scene, inertia_constant=machine.inertia + flywheel, reduced=reduced,
                         has_weight=has_weight, effects=tuple(effects), load_pieces=_load_pieces(scene),
                         coupling=coupling)
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
    driven = coupling.driven
    weighs = driven.mechanism is not None and gravity is not None and any(gravity) and _has_mass(driven.mechanism)
    reduced = build_reduced(driven.mechanism, gravity if weighs else None) if driven.mechanism else None
    effects = tuple(_unique_names([build_load(load, 2.0 * math.pi if driven.mechanism else None)
                                   for load in driven.loads]))
    if coupling.characteristic is None:
        stiffness = coupling.stiffness
        return CouplingModel(stiffness, coupling.damping, driven.inertia, effects, lambda twist: stiffness * twist,
                             driven_reduced=reduced, driven_has_weight=weighs)
    table = coupling.characteristic
    return CouplingModel(None, coupling.damping, driven.inertia, effects,
                         extrapolated_linear(table.twist, table.moment), (np.array(table.twist), np.array(table.moment)),
                         reduced, weighs)


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
