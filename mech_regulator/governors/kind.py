"""The governor level's interface (docs/governors.md, Adding a governor): what the machine model, the statics and
stability analyses, the fast path's code generator, the report, the plots, the recording and the nodes need from a
governor, whatever its kind. Each kind of governor is one class deriving from GovernorKind in its own module, which
registers its builder for its scene class with `builds`; nothing outside its module reads its kind.

A governor's states follow the machine's (phi, omega) in the state vector y, in the order of its state_names. Its
discrete mode is a pair of strings (Mode; ('', '') for a governor without modes), which the fast path carries as two
mode codes (mode_codes). Its formulas are plain functions both paths run: its methods call them on the reference path,
and its `source` writes their calls into the fast path's generated module (solvers/compiled/codegen.py) through a
SourceWriter.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np
from scipy import optimize

from mech_regulator.effects.definition import union_members

if TYPE_CHECKING:
    from mech_regulator.governors.sensor import CentrifugalSensor
    from mech_regulator.governors.valve import ValveCharacteristic

Mode = tuple[str, str]
# A machine's mode (model.machine): its governor's Mode, if it has a governor, then its drive train's, if any; None
# for a machine with neither.
MachineMode = tuple[str, ...]
# A guard linear in the state: ((state index, coefficient), ...) and a constant c0, its level c0 + sum c_i y_i
LinearGuard = tuple[tuple[tuple[int, float], ...], float]


@dataclass(frozen=True)
class Guard:
    """A condition of a mode: value(y) >= 0 while the mode holds; when it turns negative the solver
    applies transition(y) -> (new mode, state to restart from). A timed guard's value and transition
    also read the time: value(t, y), transition(t, y) (a moment that changes in time, such as the
    external load, takes part in it)."""

    name: str
    value: Callable[..., float]
    transition: Callable[..., tuple[MachineMode | None, np.ndarray]]
    timed: bool = False

    def level(self, t: float, y: np.ndarray) -> float:
        """The guard's value at time t [s] and state y."""
        return self.value(t, y) if self.timed else self.value(y)

    def apply(self, t: float, y: np.ndarray) -> tuple[MachineMode | None, np.ndarray]:
        """The guard's transition at time t [s] from state y: (new mode, state to restart from)."""
        return self.transition(t, y) if self.timed else self.transition(y)


@dataclass(frozen=True)
class OperatingPoint:
    """Steady operation of the cycle-averaged governed machine under an external load.

    external_load [N m]; speed [rad/s]; sleeve [m] (NaN without a sleeve); throttle [-]; servo [-] (indirect, else
    NaN); limited: what holds the point instead of the governor ('' when the governor regulates), e.g. 'sleeve on its
    high stop' or 'servo on its low stop'; mean_inertia [kg m^2].
    """

    external_load: float
    speed: float
    sleeve: float
    throttle: float
    servo: float
    limited: str
    mean_inertia: float


class AveragedMachine(Protocol):
    """What a governor's statics and stability read of the machine it governs (model.MachineModel): its cycle
    averages at constant speed."""

    def cycle_averages(self, omega: float, external: float = 0.0) -> tuple[float, float, float]:
        """(mean inertia J_m [kg m^2], mean drive M_d at full throttle [N m], mean of the other moments [N m]) at
        crank speed omega [rad/s] under an external load [N m]."""
        ...

    def balance_throttle(self, omega: float, external: float) -> float:
        """The throttle [-] at which the cycle-averaged drive balances the load at crank speed omega [rad/s]."""
        ...


def machine_speed(surplus: Callable[[float], float], guess: float) -> float:
    """Speed [rad/s] where the averaged machine balances at a fixed throttle: root of surplus(omega)
    bracketed outward from guess (NaN if the machine has no steady speed)."""
    lo, hi = guess, guess
    for _ in range(60):
        if surplus(lo) > 0.0 > surplus(hi) or surplus(lo) < 0.0 < surplus(hi):
            return optimize.brentq(surplus, lo, hi, xtol=1e-12)
        lo, hi = lo / 1.25, hi * 1.25
    return math.nan


class SourceWriter(Protocol):
    """What a governor's `source` needs from the fast path's code generator (solvers/compiled/codegen.py): numbers
    stored in the parameter vector p, shared functions and formula calls written as source."""

    @property
    def sleeve_mode(self) -> str:
        """Source of the segment's first mode code (GovernorKind.mode_codes)."""
        ...

    @property
    def servo_mode(self) -> str:
        """Source of the segment's second mode code."""
        ...

    def scalar(self, value: float) -> str:
        """Source reading a new slot of p that holds value."""
        ...

    def shared(self, *functions: Callable[..., float]) -> tuple[str, ...]:
        """The names the module calls plain functions by, their very source compiled into it."""
        ...

    def formula_call(
        self, function: Callable[..., float], inputs: Mapping[str, str], numbers: Mapping[str, float]
    ) -> str:
        """Source of a formula function's call (effects/definition.py's call_source), its numbers stored in p."""
        ...

    def valve_call(self, z: str, anchor: str) -> str:
        """Source of the scene's valve at the sleeve position z [m] (source), its table read on the piece that holds
        the anchor ('p[slot]' of the valve table's anchor; 'math.nan': z itself)."""
        ...


@dataclass(frozen=True)
class GovernorSource:
    """A governor's part of the fast path's generated module: throttle, the expression of the throttle [-]; rates,
    lines setting dydt of its states; guards, lines setting levels[0..] of its mode's guards in the order of its
    guards(mode) and g to the number of them; n_guards, the most guards a mode of it has."""

    throttle: str
    rates: list[str]
    guards: list[str]
    n_guards: int


class GovernorKind(ABC):
    """A governor assembled from its scene entry: its states, its right-hand side in a mode and its guards, its
    statics and stability, its part of the fast path's module and what the report, plots, recording and nodes show
    of it.

    kind: its kind ('direct', 'indirect', 'pi'; what the governor analysis reports, nothing branches on it); sensor:
    its centrifugal sensor (the static characteristic, the insensitivity, the drawing), or None; valve: throttle(z) of a
    sleeve position z [m] for a direct action, else None; valve_breaks: the sleeve positions [m] where a valve table's
    slope jumps; hybrid: whether it has modes and guards.
    """

    kind: str
    speed_action = False  # whether throttle_command's sensitivity to the crank speed is other than 0
    sensor: CentrifugalSensor | None  # no defaults here: a dataclass kind's fields would take them as theirs
    valve: ValveCharacteristic | None
    valve_breaks: tuple[float, ...] = ()
    hybrid: bool = True

    @property
    @abstractmethod
    def state_names(self) -> tuple[str, ...]:
        """Names of its states in y[2:]."""

    @property
    @abstractmethod
    def state_units(self) -> tuple[str, ...]:
        """Units of its states in y[2:]."""

    @property
    def throttle_label(self) -> str:
        """The throttle's name in the recording."""
        return "throttle"

    @property
    def vyshnegradsky_cubic(self) -> bool:
        """Whether its averaged loop is the classic cubic of Vyshnegradsky's A and B."""
        return False

    # ---------------------------------------------------------------------------------------------
    # Dynamics

    @abstractmethod
    def throttle(self, y: np.ndarray) -> float:
        """Throttle 0..1 at state y."""

    @property
    def throttle_range(self) -> tuple[float, float]:
        """The throttle's stops (low, high) [-] (within 0..1)."""
        return 0.0, 1.0

    def throttle_command(self, y: np.ndarray) -> tuple[float, float]:
        """The throttle at state y before its stops clip it to throttle_range, and that command's sensitivity to the
        crank speed omega with the governor's own states held, d command / d omega [s/rad] (what the corrected
        coupling's corrector applies, docs/ros.md, "The throttle's sensitivity to the speed"): here the throttle
        itself and 0, a throttle the crank speed moves only through the governor's states (a sleeve's, a servo's)."""
        return self.throttle(y), 0.0

    @abstractmethod
    def set_speed(self) -> float:
        """The crank speed [rad/s] held without droop, NaN for a governor whose speed moves with the load."""

    @abstractmethod
    def initial_state(
        self, omega: float, sleeve: float | None, servo: float | None, balance_throttle: Callable[[float], float]
    ) -> np.ndarray:
        """Its states at t = 0 for an initial crank speed omega [rad/s], the scenario's initial sleeve [m] and servo
        [-] (None: at rest in equilibrium), balance_throttle(omega) the throttle that balances the initial load."""

    @abstractmethod
    def initial_mode(self, y: np.ndarray) -> Mode:
        """The mode of a state at rest."""

    @abstractmethod
    def derivatives(self, mode: Mode | None, ideal: bool = False) -> Callable[[np.ndarray], list[float]]:
        """y -> time derivatives of its states in a mode; ideal: the smooth model without friction, limits and stops
        that is linearised (mode None only with ideal)."""

    @abstractmethod
    def guards(self, mode: Mode) -> list[Guard]:
        """The guards of a mode."""

    @abstractmethod
    def signals(self, y: np.ndarray) -> dict[str, np.ndarray | float]:
        """Its outputs at state(s) y (one state, or states along the last axis) besides the throttle, by name."""

    @abstractmethod
    def describe(self) -> list[str]:
        """Lines for `describe`: its parts and equations."""

    def held_throttle(self, anchor: float) -> Callable[[np.ndarray], float]:
        """y -> throttle of its valve table continued along the piece that holds the sleeve position anchor [m]
        (only for a governor with valve_breaks)."""
        raise NotImplementedError(f"a {self.kind} governor has no valve table")

    def valve_position(self, y: np.ndarray) -> float:
        """The position [m] its valve table reads at state y (only for a governor with valve_breaks)."""
        raise NotImplementedError(f"a {self.kind} governor has no valve table")

    # ---------------------------------------------------------------------------------------------
    # The fast path

    def mode_codes(self, mode: Mode) -> tuple[float, float]:
        """The two numbers the generated module reads its mode from (SourceWriter.sleeve_mode, servo_mode)."""
        return 0.0, 0.0

    def linear_guards(self, mode: Mode) -> list[LinearGuard | None]:
        """Per guard of guards(mode), in its order, its form linear in the state, or None where it is not linear."""
        return [None] * len(self.guards(mode))

    def valve_table_state(self, breaks: tuple[float, ...]) -> tuple[tuple[tuple[int, float], ...], tuple[float, ...]]:
        """The (state index, coefficient) pairs of the state its valve table's guards are linear in, and the valve
        table's breakpoints `breaks` [m] there (only for a governor with valve_breaks)."""
        raise NotImplementedError(f"a {self.kind} governor has no valve table")

    @abstractmethod
    def source(self, writer: SourceWriter, valve_anchor: str) -> GovernorSource:
        """Its part of the fast path's module, the same formulas as its methods run; valve_anchor: 'p[slot]' of
        its valve table's anchor, or 'math.nan' (none)."""

    # ---------------------------------------------------------------------------------------------
    # Statics and stability

    @abstractmethod
    def operating_point(self, machine: AveragedMachine, external_load: float) -> OperatingPoint:
        """Steady operation of the cycle-averaged machine under an external load [N m] with this governor."""

    @abstractmethod
    def equilibrium_state(self, point: OperatingPoint) -> np.ndarray:
        """Its states at an operating point, in the averaged model (its ideal derivatives all zero there)."""

    @abstractmethod
    def state_scale(self, point: OperatingPoint) -> np.ndarray:
        """Typical size of each of its states at an operating point, for difference steps and tolerances."""

    def loop_coefficients(self, machine: AveragedMachine, point: OperatingPoint) -> tuple[float, float] | None:
        """Closed forms of its averaged loop's characteristic polynomial at an operating point, where it has them."""
        return None

    def with_damping(self, damping: float) -> GovernorKind | None:
        """The same governor with its sleeve's damping c [N s/m] (critical damping), None without a sleeve."""
        return None

    # ---------------------------------------------------------------------------------------------
    # What is shown

    @abstractmethod
    def title(self) -> str:
        """Its name in a run's text log, e.g. 'direct governor'."""

    @abstractmethod
    def set_speed_text(self) -> str:
        """The recording's note on its set speed and throttle."""

    @abstractmethod
    def plotted(self) -> tuple[str, str, float, str]:
        """Its own signal plotted beside the throttle: (key in signals, label, factor to the plotted unit, unit)."""

    @abstractmethod
    def joints(self) -> tuple[tuple[str, str, str | None], ...]:
        """What the nodes publish of it on governor/state, one joint each: (joint name, key of its position in
        signals (or 'throttle'), key of its velocity or None: 0)."""

    def summary(self) -> dict[str, str | None]:
        """Its entries in the governor analysis (cli governor): its sensor's name and its feedback, where it has
        them."""
        return {"sensor": self.sensor.name if self.sensor is not None else None, "feedback": None}


_BUILDERS: dict[type, Callable[..., GovernorKind]] = {}


def builds(*kinds: type) -> Callable:
    """Register the decorated `build(spec, balance_throttle) -> GovernorKind` for the scene classes `kinds`."""

    def register(build: Callable[..., GovernorKind]) -> Callable[..., GovernorKind]:
        for kind in kinds:
            _BUILDERS[kind] = build
        return build

    return register


def builder_of(spec: object) -> Callable[..., GovernorKind]:
    """The registered builder of a scene's governor entry."""
    return _BUILDERS[type(spec)]


def check_covered(union: object) -> None:
    """Raise TypeError naming the members of the scene's governor union that no builder is registered for."""
    missing = [kind.__name__ for kind in union_members(union) if kind not in _BUILDERS]
    if missing:
        raise TypeError(
            f"no governor builder for the scene entries {', '.join(missing)}; each governor kind registers one with "
            "governors.kind.builds (docs/governors.md)"
        )
