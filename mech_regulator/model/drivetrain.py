"""The drive train behind the crank: a driven part (possibly a branched drive) reached through an elastic
coupling or a friction clutch, its Coulomb resistances, and the hybrid modes of clutch and driven part.

Driven part (docs/theory.md §7.4): a main shaft turning at omega_driven with inertia I_main and branches n,
each with the inertia I_n beyond its section (on the branch's shaft) and the ratio i_1n = omega_driven /
omega_n. Reduced to the main shaft by equal kinetic energy and equal power,

    I = I_main + sum_n I_n / i_1n^2,        M_reduced = M_n / i_1n  (M_n of omega_n = omega_driven / i_1n),

so I domega_driven/dt = M_passed + M_smooth(omega_driven) - s R with R = the Coulomb resistances (constant
loads, reduced, and the external load) and s = +1 turning forward, -1 backward. Behind an elastic coupling
the main shaft may carry a mechanism (a crank-slider or four-bar whose crank angle is phi_driven): then
I = I(phi_driven) adds its links' reduced inertia, M_smooth its links' weight, its loads read phi_driven
and the slider's or rocker's q2, dq2/dphi2, and the equation gains 1/2 I'(phi_driven) omega_driven^2 on
the left (docs/theory.md §7.1). At rest ('held') the
resistances hold the part while |M_passed + M_smooth| <= R; they are then mobilised in proportion,
s = (M_passed + M_smooth) / R. The moment in the section of branch n (the paper's M_kr, on the branch's
shaft) is

    M_section_n = M_n,c + (I_n / i_1n) domega_driven/dt,

M_n,c = the branch's resisting moments (magnitudes) on its shaft.

Friction clutch between the crank side (inertia J, net moment F1 = M_d + M_c - 1/2 J' omega^2 without the
clutch) and the driven part. Modes: 'slip+' (omega > omega_driven; the clutch passes +kinetic_torque),
'slip-' (omega < omega_driven; -kinetic_torque), 'stuck' (omega = omega_driven; the clutch passes the
moment T that keeps them together, (J + I) domega/dt = F1 + M_smooth - s R, T = F1 - J domega/dt, while
|T| <= static_torque). A stuck clutch on a held driven part holds the crank at rest too (T = F1).
A train mode is (clutch mode, driven mode) with a clutch, (driven mode,) with a coupling.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mech_regulator.effects import Effect, build_load, output_position_of
from mech_regulator.governors import Guard
from mech_regulator.scene import machine_keys

FORWARD, BACKWARD, HELD = "forward", "backward", "held"
STUCK, SLIP_AHEAD, SLIP_BEHIND = "stuck", "slip+", "slip-"
DIRECTION = {FORWARD: 1.0, BACKWARD: -1.0, HELD: 0.0}
CLUTCH_CODE = {STUCK: 0.0, SLIP_AHEAD: 1.0, SLIP_BEHIND: -1.0}


@dataclass(frozen=True)
class Forces:
    """The drive train's answer in one mode: crank acceleration [rad/s^2] (NaN behind a coupling, see
    MachineModel.drive_train_at), driven part's acceleration
    [rad/s^2], moment the clutch passes to the driven part [N m] (0 for a coupling), the moment pushing the
    driven part apart from its resistances [N m], and the Coulomb factor s of its resistances [-]."""

    crank: float
    driven: float
    clutch: float
    push: float
    factor: float


@dataclass(frozen=True)
class BranchModel:
    """A branch: name, inertia I_n beyond its section on its shaft [kg m^2], ratio i_1n [-], and the indices
    of its (reduced) effects in DrivenModel.effects."""

    name: str
    inertia: float
    ratio: float
    effects: tuple[int, ...]


@dataclass(frozen=True)
class DrivenModel:
    """A driven part reduced to its main shaft: inertia I [kg m^2] (its constant part with a mechanism);
    effects: its moments and its branches' (reduced, M_n / i_1n, named <branch>_<load>); coulomb: which effects
    are Coulomb resistances (constant loads: the moment given is the one turning forward); resistance: their
    sum R0 [N m]; branches; reduced: its mechanism's phi2 -> (I_links, dI_links/dphi2, M_weight, q2, dq2/dphi2)
    or None; has_weight: whether its links weigh (a M_driven_weight column)."""

    inertia: float
    effects: tuple[Effect, ...]
    coulomb: tuple[bool, ...]
    resistance: float
    branches: tuple[BranchModel, ...]
    reduced: Callable[[float], tuple[float, float, float, float, float]] | None = None
    has_weight: bool = False

    @property
    def reads_angle(self) -> bool:
        """Whether the driven part's inertia or moments depend on its angle phi2."""
        return self.reduced is not None or any("phi" in effect.depends_on for effect in self.effects)

    def state(self, phi_driven: float) -> tuple[float, float, float, float, float]:
        """(I(phi2) [kg m^2], dI/dphi2 [kg m^2/rad], M_weight [N m], q2, dq2/dphi2) at phi_driven [rad]."""
        if self.reduced is None:
            return self.inertia, 0.0, 0.0, 0.0, 0.0
        links, slope, weight, q, dq = self.reduced(phi_driven)
        return self.inertia + links, slope, weight, q, dq

    def smooth_moment(self, t: float, omega_driven: float, phi_driven: float = 0.0) -> float:
        """Sum of the non-Coulomb moments (viscous, fan, tables, its mechanism's loads and links' weight) at
        phi_driven [rad] and omega_driven [rad/s] [N m]."""
        return self._smooth_at(t, phi_driven, omega_driven, self.state(phi_driven))

    def _smooth_at(self, t: float, phi_driven: float, omega_driven: float, state: tuple) -> float:
        """smooth_moment [N m] given state = self.state(phi_driven) (its kinematics evaluated once)."""
        _, _, weight, q, dq = state
        return weight + sum(
            effect.moment(t, phi_driven, omega_driven, q, dq)
            for effect, dry in zip(self.effects, self.coulomb)
            if not dry
        )

    def dynamics(self, t: float, phi_driven: float, omega_driven: float) -> tuple[float, float]:
        """(I(phi2) [kg m^2], M_smooth - 1/2 I'(phi2) omega2^2 [N m]) at phi_driven [rad], omega_driven [rad/s]:
        the inertia and the non-Coulomb side of the driven part's equation."""
        state = self.state(phi_driven)
        inertia, slope = state[0], state[1]
        return inertia, self._smooth_at(t, phi_driven, omega_driven, state) - 0.5 * slope * omega_driven**2

    def forward_moment(self, t: float, omega_driven: float, phi_driven: float = 0.0) -> float:
        """Sum of all its moments turning forward at omega_driven [rad/s] and phi_driven [rad] [N m] (Coulomb
        ones at -R0)."""
        return self.smooth_moment(t, omega_driven, phi_driven) - self.resistance

    def acceleration(
        self, mode: str, push: float, smooth: float, resistance: float, inertia: float | None = None
    ) -> float:
        """domega_driven/dt [rad/s^2] = (push + smooth - s R) / I turning, 0 held; inertia: I(phi2) (default:
        the constant I)."""
        if mode == HELD:
            return 0.0
        return (push + smooth - DIRECTION[mode] * resistance) / (self.inertia if inertia is None else inertia)

    def at_rest(self, push: float, resistance: float) -> str:
        """The mode of the part at rest pushed by `push` [N m] against resistances R [N m]: held while
        |push| <= R, else moving the way it is pushed; with no resistance (R = 0) nothing holds it, so it is
        never held (forward when not pushed either way)."""
        if abs(push) <= resistance and resistance > 0.0:
            return HELD
        return FORWARD if push >= 0.0 else BACKWARD


def coulomb_factor(mode: str, push: float, resistance: float) -> float:
    """s: +1 forward, -1 backward, push / R held (the resistances mobilised in proportion)."""
    if mode != HELD:
        return DIRECTION[mode]
    return push / resistance if resistance > 0.0 else 0.0


def build_driven(
    spec: machine_keys.DrivenPart,
    unique_names: Callable[[list[Effect]], list[Effect]],
    reduced: Callable | None = None,
    has_weight: bool = False,
) -> DrivenModel:
    """Assemble a scene's driven part, its branches reduced to the main shaft (module docstring); reduced and
    has_weight: its mechanism's reduced inertia and weight (mechanisms.build_reduced), if it has one (its output
    position places the kinks in phi_driven of a slider table, effects.build_load)."""
    effects = [
        build_load(load, 2.0 * math.pi if spec.mechanism is not None else None, output_position_of(reduced))
        for load in spec.loads
    ]  # a slider table's kinks: where its mechanism's x crosses a breakpoint
    coulomb = [effect.dry for effect in effects]  # constant loads: Coulomb resistances
    effects = unique_names(effects)
    branches = []
    for branch in spec.branches:
        own = unique_names([build_load(load, None) for load in branch.loads])
        first = len(effects)
        effects += [_reduced(effect, branch.name, branch.ratio) for effect in own]
        coulomb += [effect.dry for effect in own]
        branches.append(BranchModel(branch.name, branch.inertia, branch.ratio, tuple(range(first, len(effects)))))
    inertia = spec.inertia + sum(branch.inertia / branch.ratio**2 for branch in spec.branches)
    resistance = -sum(effect.moment(0.0, 0.0, 0.0, 0.0, 0.0) for effect, dry in zip(effects, coulomb) if dry)
    return DrivenModel(inertia, tuple(effects), tuple(coulomb), resistance, tuple(branches), reduced, has_weight)


def _reduced(effect: Effect, branch: str, ratio: float) -> Effect:
    """A branch's effect reduced to the main shaft: M(omega_driven / i) / i (equal power)."""
    moment = effect.moment
    return Effect(
        f"{branch}_{effect.name}",
        effect.role,
        lambda t, phi, omega, q, dq: moment(t, phi, omega / ratio, q, dq) / ratio,
        effect.depends_on,
        f"{branch}: ({effect.formula.replace('omega', 'omega_n')}) / {ratio:g}, omega_n = omega_driven / {ratio:g}",
    )


@dataclass(frozen=True)
class ClutchModel:
    """A friction clutch: static_torque and kinetic_torque [N m], and the driven part behind it."""

    static_torque: float
    kinetic_torque: float
    driven: DrivenModel

    def forces(self, mode: tuple[str, ...], F1: float, J: float, smooth: float, resistance: float) -> Forces:
        """The accelerations and moments in a train mode (module docstring): F1 [N m] the crank's net moment
        apart from the clutch, J [kg m^2] its inertia, smooth [N m] the driven part's non-Coulomb moments,
        resistance R [N m] its Coulomb resistances."""
        clutch, held_or_moving = mode
        driven = self.driven
        if clutch == STUCK:
            if held_or_moving == HELD:  # everything at rest: the clutch passes the crank's moment
                return Forces(0.0, 0.0, F1, F1 + smooth, coulomb_factor(HELD, F1 + smooth, resistance))
            s = DIRECTION[held_or_moving]
            acceleration = (F1 + smooth - s * resistance) / (J + driven.inertia)
            torque = F1 - J * acceleration
            return Forces(acceleration, acceleration, torque, torque + smooth, s)
        torque = self.kinetic_torque if clutch == SLIP_AHEAD else -self.kinetic_torque
        push = torque + smooth
        return Forces(
            (F1 - torque) / J,
            driven.acceleration(held_or_moving, torque, smooth, resistance),
            torque,
            push,
            coulomb_factor(held_or_moving, push, resistance),
        )

    def mode_at(
        self, slip: float, omega_driven: float, F1: float, J: float, smooth: float, resistance: float
    ) -> tuple[str, str]:
        """The consistent train mode of a state: a clutch that is not at rest (slip = omega - omega_driven
        [rad/s] != 0) slips the way it slips and a driven part that turns keeps turning; a clutch at rest
        sticks while the moment that keeps it stuck is within static_torque, else slips the way the
        accelerations pull; a driven part at rest is held while its resistances can (static friction first).
        """
        clutches = [STUCK, SLIP_AHEAD, SLIP_BEHIND] if slip == 0.0 else [SLIP_AHEAD if slip > 0.0 else SLIP_BEHIND]
        parts = [HELD, FORWARD, BACKWARD] if omega_driven == 0.0 else [FORWARD if omega_driven > 0.0 else BACKWARD]
        best, least = None, math.inf
        for clutch in clutches:
            for part in parts:
                forces = self.forces((clutch, part), F1, J, smooth, resistance)
                violation = 0.0
                if clutch == STUCK:
                    violation += max(abs(forces.clutch) - self.static_torque, 0.0)
                elif slip == 0.0:  # starting to slip: the slip must grow
                    relative = (forces.crank - forces.driven) * (1.0 if clutch == SLIP_AHEAD else -1.0)
                    violation += max(-relative, 0.0) * J + (relative == 0.0)
                if part == HELD:
                    violation += max(abs(forces.push) - resistance, 0.0)
                elif omega_driven == 0.0:  # starting to turn: it must accelerate that way
                    along = forces.driven * DIRECTION[part]
                    violation += max(-along, 0.0) * self.driven.inertia + (along == 0.0)
                if violation == 0.0:
                    return clutch, part
                if violation < least:
                    best, least = (clutch, part), violation
        assert best is not None, "a finite state's modes violate their conditions by finite amounts"
        return best


def train_guards(
    mode: tuple[str, ...], index: int, forces: Callable, decide: Callable, wrap: Callable, clutch: ClutchModel | None
) -> list[Guard]:
    """The guards of a train mode (timed: the external load in the resistances changes in time).

    index: position of omega_driven in the state; forces(t, y) -> (Forces, R) in this mode; decide(t, y) ->
    the train mode of a state (mode_at); wrap(train mode) -> the machine's whole mode. A clutch locks when
    the slip speed reaches 0, breaks away when the stuck moment leaves +-static_torque; a driven part comes to
    rest when omega_driven reaches 0 and breaks away when the push leaves +-R.
    """
    guards = []
    clutch_mode, part = (mode[0], mode[1]) if clutch is not None else (None, mode[0])
    static = clutch.static_torque if clutch is not None else 0.0

    def settle(fix: Callable[[np.ndarray], None]) -> Callable:
        def transition(t: float, y: np.ndarray):
            y = y.copy()
            fix(y)
            return wrap(decide(t, y)), y

        return transition

    def switch_to(new_clutch: str | None, new_part: str) -> Callable:
        def transition(t: float, y: np.ndarray):
            return wrap((new_clutch, new_part) if clutch is not None else (new_part,)), y.copy()

        return transition

    def lock(y: np.ndarray) -> None:
        y[index] = y[1]

    def stop(y: np.ndarray) -> None:
        y[index] = 0.0
        if clutch_mode == STUCK:
            y[1] = 0.0

    if clutch_mode == STUCK:
        guards += [
            Guard(
                "clutch breaks away, motor ahead",
                lambda t, y: static - forces(t, y)[0].clutch,
                switch_to(SLIP_AHEAD, part),
                timed=True,
            ),
            Guard(
                "clutch breaks away, machine ahead",
                lambda t, y: static + forces(t, y)[0].clutch,
                switch_to(SLIP_BEHIND, part),
                timed=True,
            ),
        ]
    elif clutch_mode is not None:
        slip_sign = 1.0 if clutch_mode == SLIP_AHEAD else -1.0
        guards.append(
            Guard("clutch locks (slip ends)", lambda t, y: slip_sign * (y[1] - y[index]), settle(lock), timed=True)
        )
    if part == HELD:
        guards += [
            Guard(
                "driven part breaks away forwards",
                lambda t, y: _margin(forces(t, y), -1.0),
                switch_to(clutch_mode, FORWARD),
                timed=True,
            ),
            Guard(
                "driven part breaks away backwards",
                lambda t, y: _margin(forces(t, y), 1.0),
                switch_to(clutch_mode, BACKWARD),
                timed=True,
            ),
        ]
    else:
        sign = DIRECTION[part]
        guards.append(Guard("driven part comes to rest", lambda t, y: sign * y[index], settle(stop), timed=True))
    return guards


def _margin(forces_and_resistance: tuple[Forces, float], sign: float) -> float:
    """R + sign * push [N m]: what is left of the resistances holding the part."""
    forces, resistance = forces_and_resistance
    return resistance + sign * forces.push
