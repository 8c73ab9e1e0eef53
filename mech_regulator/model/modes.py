"""The modes of a machine model and their stops: the drive train's part of the right-hand side in each of its modes
(a clutch slipping or locked, a driven part turning or held by its Coulomb resistances, model/drivetrain.py), the
mode of a state, the constraint a mode holds, and the guards (the governor's, the drive train's, the crank's stop
and start under joint friction) whose crossing ends a mode (docs/theory.md §7). MachineModel (model/machine.py) has
these methods."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from mech_regulator.governors import Guard, MachineMode
from mech_regulator.model.drivetrain import (
    BACKWARD,
    DIRECTION,
    FORWARD,
    HELD,
    STUCK,
    Forces,
    coulomb_factor,
    train_guards,
)

if TYPE_CHECKING:
    from mech_regulator.model.machine import MachineModel


class MachineModes:
    """MachineModel's methods on its modes and their guards, mixed into it. Their self is the MachineModel (its
    fields and right-hand side): mypy checks them against it but refuses a self type narrower than this class, hence
    the `type: ignore[misc]` on their first lines."""

    def _train(  # type: ignore[misc]
        self: MachineModel,
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

    def train_mode_of(self: MachineModel, mode: MachineMode | None) -> tuple[str, ...]:  # type: ignore[misc]
        """The drive train's part of a machine's mode (its default when mode is None or carries none)."""
        train = tuple(mode[2:] if self.governor is not None else mode) if mode is not None else ()
        if train or self.driven is None:
            return train
        return (STUCK, FORWARD) if self.clutch is not None else (FORWARD,)

    def drive_train_at(  # type: ignore[misc]
        self: MachineModel,
        t: float,
        y: np.ndarray,
        external: float | None = None,
        train_mode: tuple[str, ...] | None = None,
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

    def constraint(self: MachineModel, mode: MachineMode | None) -> Callable[[np.ndarray], None] | None:  # type: ignore[misc]
        """What a mode imposes on the states the solver gives, in place, or None: a stuck clutch sets omega2 =
        omega bit for bit (the solver holds its own omega2 frozen meanwhile)."""
        if self.clutch is None or mode is None or self.train_mode_of(mode)[0] != STUCK:
            return None
        index = self.driven_speed_index

        def stuck(y: np.ndarray) -> None:
            y[index] = y[1]

        return stuck

    def initial_mode(self: MachineModel, y: np.ndarray) -> MachineMode | None:  # type: ignore[misc]
        """The mode at a state with the governor at rest: the governor's (None without a governor), followed by
        the drive train's mode of the state (drive_train_at)."""
        governor = self.governor.initial_mode(y) if self.governor is not None else None
        if self.driven is None:
            return governor
        return (governor or ()) + self.drive_train_at(0.0, y)[0]

    def guards(self: MachineModel, mode: MachineMode | None, y: np.ndarray | None = None) -> list:  # type: ignore[misc]
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
    def _built_guards(self: MachineModel) -> dict:  # type: ignore[misc]
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

    def _mode_guards(self: MachineModel, mode: MachineMode | None) -> list:  # type: ignore[misc]
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


def _carrying(guard: Guard, train_mode: tuple[str, ...]) -> Guard:
    """A governor's guard whose transition keeps the drive train's mode after the governor's new mode."""

    def transition(y: np.ndarray) -> tuple[MachineMode, np.ndarray]:
        governor_mode, state = guard.transition(y)
        assert governor_mode is not None, "a governor's guard gives the governor's new mode"
        return governor_mode + train_mode, state

    return Guard(guard.name, guard.value, transition)
