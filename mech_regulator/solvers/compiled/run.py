"""The fast path's outer loop: the reference path's segments, modes and restarts (solvers/time_domain.py) around the
compiled right-hand side (codegen.py) and the compiled integrators (integrators.py).

Each external-load piece is integrated on its own; within it the mode is settled, p is set for the piece, the mode
and the switch window, and the scene's compiled stepper runs until the piece ends, a guard fires (a governor or
driven-part event, located in the stepper; its transition is the model's own Guard, applied here), the crank angle
passes the wrap limit (it is re-wrapped by whole dynamic periods and the stepper restarts with its last step size;
without a switch window the stepper does that itself, without returning) or MAX_STEPS_PER_CALL steps are done (so
that progress moves and Ctrl-C is heard). A switch window's edge (a switch or a kink of a table) is a restart that
changes only the window: for a scene whose p depends on nothing else there (no state tables, no joint friction:
_FixedArguments.kink_grid) the stepper makes it itself, exactly as this loop would (integrators._kink_restart), and returns
only when a mode guard is near its threshold there, a speed went beyond its limit, or MAX_STEPS_PER_CALL steps or
MAX_RESTARTS_PER_CALL such restarts are done. A co-simulated governor's speed pieces (compiled_pieces) are gone on
into in the same way (integrators._piece_restart). Every call's steps become one piece of the Trajectory, with the
ends of those steps (Trajectory.step_ends: the works of the energy balance are integrated step by step). The run's
limits (limits.py) are kept by the stepper as the reference path keeps them step by step: it stops at the first step
end with a speed beyond MAX_SPEED or not finite (that step kept; the run fails there with time_domain.fail_blown_up's
message) and once the run has taken MAX_STEPS steps (fail_too_many_steps).
"""

from __future__ import annotations

import bisect
import functools
import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from mech_regulator.model import MachineModel
from mech_regulator.scene import SceneError
from mech_regulator.solvers import time_domain
from mech_regulator.solvers.compiled import fast_path_refusal, integrators, pieces, results, steppers
from mech_regulator.solvers.compiled.codegen import RECENT_MODELS, CompiledScene, compile_scene, sign_of
from mech_regulator.solvers.compiled.events import _switch_window
from mech_regulator.solvers.compiled.source import (
    CLAMP_HI,
    CLAMP_LO,
    CRANK_DIRECTION,
    PIECE_INDEX,
    PIECE_SLOTS,
    WINDOW_HI,
    WINDOW_LO,
)
from mech_regulator.solvers.time_domain import (
    MAX_INSTANT_EVENTS,
    MAX_RESTARTS_WITHOUT_PROGRESS,
    RESTART_PERIODS,
    _fail_stuck,
    _held_pieces,
    _log_event,
    _unwound_pieces,
    fail_blown_up,
    fail_no_progress,
    fail_too_many_steps,
    integrate_time_domain,
    settle_mode_in_phase,
    turns_and_phase,
)
from mech_regulator.solvers.trajectory import Progress, Stream, Trajectory

MAX_STEPS_PER_CALL = 2000  # a stepper call returns to Python after this many steps (progress moves, Ctrl-C is heard);
# the next call warm-starts with the last step size
MAX_RESTARTS_PER_CALL = 32  # and after this many restarts it made itself (kinks, pieces), for the same reasons


def integrate_compiled(
    model: MachineModel, progress: Progress | None = None, stream: Stream | None = None
) -> Trajectory:
    """Integrate the scene's scenario on the fast path; returns the (possibly partial) trajectory, with the same
    statuses and messages as the reference path (time_domain.integrate_time_domain). A scene the fast path cannot
    run raises SceneError (fast_path_refusal). stream: as integrate_time_domain's."""
    return integrate_time_domain(model, progress, compiled_segment(model), stream)


def compiled_segment(model: MachineModel):
    """time_domain._segment's compiled twin for this model (same arguments and result; the scene compiled once here):
    what integrate_compiled and the co-simulation's steppers (solvers/cosim.py) step a load piece or an exchange
    step with. A model the fast path cannot run raises SceneError (fast_path_refusal)."""
    return functools.partial(_compiled_segment, *_compiled(model))


def compiled_pieces(model: MachineModel):
    """cosim.follow_samples' compiled twin for this model (same arguments and result): the governor's pieces along
    sequences of the machine's speed samples, each started with the crank's speed set, stepped in as few compiled calls
    as the pieces allow (_compiled_pieces)."""
    return functools.partial(_follow_compiled, *_compiled(model))


_LAYOUTS: dict[int, tuple[CompiledScene, _Layout]] = {}  # id(compiled scene) -> it and its layout, the last few


def _compiled(model: MachineModel) -> tuple[CompiledScene, _Layout]:
    """The model's compiled scene and layout (worked out once per compiled scene: a model is immutable, and
    compile_scene answers a recent one from memory); a model the fast path cannot run raises SceneError."""
    reason = fast_path_refusal(model)
    if reason is not None:
        raise SceneError(reason)
    compiled = compile_scene(model)
    known = _LAYOUTS.get(id(compiled))
    if known is None or known[0] is not compiled:
        if len(_LAYOUTS) >= RECENT_MODELS:
            del _LAYOUTS[next(iter(_LAYOUTS))]
        known = _LAYOUTS[id(compiled)] = (compiled, _Layout.of(model, compiled))
    return known


class _Address:
    """A compiled callback (numba CFunc) by its machine address: numba's wrapper address protocol
    (numba.experimental.function_type), which the stepper's entry takes without checking the callback's signature
    again on every call (some 2 us of 3.5 for each of the three callbacks). The callback is held, so the address
    stays valid."""

    def __init__(self, callback):
        self.callback, self.address = callback, callback.address

    def __wrapper_address__(self) -> int:
        return self.address


class _FixedArguments(NamedTuple):
    """The arguments of a model's compiled stepper calls that are the same at every call, in the stepper's order
    (integrators' module docstring), worked out once per model: the scene's compiled rhs and guards as the stepper
    takes them (_Address), the number of guards and their thresholds (zero: the steppers apply time_domain's
    GUARD_TOLERANCE), the reactions (_Address) and the number of journals, the solver's rtol, absolute tolerances,
    max_step [s] (inf: none) and RK4's step [s], the crank angle's wrap limit [rad] (inf: never wrapped); for the
    stepper's own restarts on the window's edges (integrators._kink_restart) the switch grid as an array (empty: the
    scene's p depends on more than the window there, every edge returns to Python), the dynamic period [rad] and the
    slots it writes; the indices of the speeds the stepper keeps within MAX_SPEED (the run stops beyond it); the
    method."""

    rhs: _Address
    guards: _Address
    n_guards: int
    thresholds: np.ndarray
    reactions: _Address
    n_journals: int
    rtol: float
    atol: np.ndarray
    max_step: float
    step: float
    wrap_limit: float
    kink_grid: np.ndarray
    period: float
    kink_slots: np.ndarray
    speed_indices: np.ndarray
    method: str


class _Layout(NamedTuple):
    """What every segment of a model reuses (a co-simulation steps thousands of short ones): its switch grid [rad],
    dynamic period [rad], whether the crank angle is wrapped; whether the stepper may go on into the next of a
    sequence of load pieces itself (integrators._piece_restart: a scene whose p there depends on the piece and the
    crank's speed only, without switch angles or a wrapped angle); the stepper's arguments that are the same at every
    call (_FixedArguments); the model's state tables (MachineModel.state_tables), whether one turns with phi (a guard
    then reads phi: the stepper does not wrap it itself), the empty array of following pieces a call without them
    passes and the machine-code entry of time_domain.switch_window compiled
    (events._switch_window, steppers.entry_point: the same numbers, about 1 us a call against 5-8 in Python) that
    finds the window a call starts in."""

    grid: np.ndarray
    period: float
    wraps: bool
    pieces_inside: bool
    fixed: _FixedArguments
    tables: tuple
    turning: bool
    no_following: np.ndarray
    switch_window: Callable[..., tuple[float, float]]

    @classmethod
    def of(cls, model: MachineModel, compiled: CompiledScene) -> _Layout:
        """The layout of a model and its compiled scene."""
        grid = np.array(model.switch_grid(), dtype=float)
        wraps = model.reduced is not None or "phi" in model.depends_on()
        window_only = (
            compiled.window_slot is not None
            and wraps
            and not model.state_tables
            and model.joint_friction is None
            and compiled.normal_slot is None
        )
        names = model.state_names()
        period = model.dynamic_period()
        settings = model.scene.solver
        return cls(
            grid=grid,
            period=period,
            wraps=wraps,
            pieces_inside=(
                not grid.size
                and not wraps
                and not model.state_tables
                and model.joint_friction is None
                and compiled.normal_slot is None
            ),
            fixed=_FixedArguments(
                rhs=_Address(compiled.rhs_callback),
                guards=_Address(compiled.guards_callback),
                n_guards=compiled.n_guards,
                thresholds=np.zeros(compiled.n_guards),
                reactions=_Address(compiled.reactions_callback),
                n_journals=compiled.n_journals,
                rtol=settings.rtol,
                atol=np.full(len(names), settings.atol),
                max_step=settings.max_step or math.inf,
                step=settings.step,
                wrap_limit=RESTART_PERIODS * period if wraps else math.inf,
                kink_grid=grid if window_only else np.empty(0),
                period=period,
                kink_slots=np.array(
                    [compiled.window_slot or 0, CLAMP_LO, CLAMP_HI, WINDOW_LO, WINDOW_HI, CRANK_DIRECTION],
                    dtype=np.int64,
                ),
                speed_indices=np.array(
                    [index for index, name in enumerate(names) if name in ("omega", "omega_driven")], dtype=np.int64
                ),
                method=settings.method,
            ),
            tables=model.state_tables,
            turning=any(table.angular for table in model.state_tables),
            no_following=np.empty((0, 2 + len(PIECE_SLOTS))),
            switch_window=steppers.entry_point(_switch_window),
        )


def _compiled_segment(
    compiled: CompiledScene,
    layout: _Layout,
    model: MachineModel,
    piece,
    t_start: float,
    t_end: float,
    y: np.ndarray,
    mode,
    trajectory: Trajectory,
    progress: Progress | None,
):
    """time_domain._segment on the fast path: step [t_start, t_end] with the compiled stepper, restarting at every
    event (mode transition applied), switch angle and wrap of the crank angle; returns the state and mode at the
    end."""
    rows = np.array([(t_end, y[1], *compiled.piece_values(piece, y[1]))])
    return _compiled_pieces(compiled, layout, model, t_start, rows, 0, y, mode, trajectory, progress)[:2]


def _follow_compiled(
    compiled: CompiledScene,
    layout: _Layout,
    model: MachineModel,
    samples: list,
    y: np.ndarray,
    mode,
    trajectory: Trajectory,
    split: int = -1,
):
    """cosim.follow_samples on the fast path: the pieces of the speed samples (a list of (times [s], omega [rad/s]),
    each following on where the one before ends; cosim.speed_pieces of each, as the stepper's rows: speed_rows) each
    stepped from the state so far with y[1] set to its start speed, until one fails; returns the state and mode at the
    end and, given split (a piece's index), the start of that piece (as cosim.follow_pieces)."""
    rows = speed_rows(samples)
    index, at_split, t = 0, None, samples[0][0][0] if rows.size else 0.0
    while index < len(rows) and trajectory.status == "complete":
        y = np.array(y, dtype=float)
        y[1] = rows[index, 1]
        if index == split:
            at_split = (y.copy(), mode, len(trajectory.events))
        y, mode, index, inside = _compiled_pieces(
            compiled, layout, model, t, rows, index, y, mode, trajectory, None, split
        )
        t = float(rows[index - 1, 0])
        at_split = at_split or inside
    return y, mode, at_split


def speed_rows(samples: list) -> np.ndarray:
    """The pieces of the speed samples (a list of (times [s], omega [rad/s]), each an odd number, the quadratic through
    three on each piece) as the stepper's rows (pieces.speed_rows, by its entry: steppers.entry_point), one array."""
    counts = [max(0, (len(times) - 1) // 2) for times, _ in samples]
    rows = np.empty((sum(counts), 2 + len(PIECE_SLOTS)))
    first = 0
    write_rows = steppers.entry_point(pieces.speed_rows)
    for (times, speeds), count in zip(samples, counts):
        write_rows(np.array(times, dtype=float), np.array(speeds, dtype=float), rows[first : first + count])
        first += count
    return rows


def _compiled_pieces(
    compiled: CompiledScene,
    layout: _Layout,
    model: MachineModel,
    t: float,
    rows: np.ndarray,
    index: int,
    y: np.ndarray,
    mode,
    trajectory: Trajectory,
    progress: Progress | None,
    split: int = -1,
):
    """Step the piece rows[index] from t [s] and y with the compiled stepper, restarting at every event (mode
    transition applied), switch angle and wrap of the crank angle, and, where the layout allows it (pieces_inside),
    go on into the pieces after it inside the compiled calls (as _follow_compiled would start them); rows: one per
    piece, each starting where the one before ends, as the stepper takes them ([its end [s], the crank's speed at its
    start [rad/s], p[PIECE_SLOTS]]; of these the last, the sign of the crank's speed, is worked out anew from the state
    at each start). Returns the state and mode at the end, the index of the next piece to start and, when a call went on into
    rows[split] and took a step in it, that piece's start as follow_pieces gives it (its first step's start state, the
    call's mode, the events so far), else None."""
    grid, period, wraps = layout[:3]
    tables, stats = layout.tables, trajectory.stats
    t_end = float(rows[index, 0])
    following = rows[index + 1 :] if layout.pieces_inside else layout.no_following
    first_step = 0.0
    at_split = None
    held: list[int] = []  # per state table its piece, counted from the carried turns (_held_pieces; none yet)
    normal_sides: tuple[float, ...] = ()  # joint friction's guides: the held signs of N,
    crossed_normal: int | None = None  # the one just crossed
    instant_events = stalled = 0  # mode changes, and restarts of any kind, in a row that left the time where it was
    # the crank angle as whole periods and the phase within them (time_domain.turns_and_phase), carried exactly across
    # the restarts: phi = turns period + phase is only written out, never read back
    turns, phase = turns_and_phase(y[0], period) if wraps else (0, float(y[0]))  # (phi only an output)
    while t < t_end and trajectory.status == "complete":
        if wraps:
            whole = math.floor(phase / period)
            turns, phase = turns + whole, phase - whole * period
            if tables:
                held = _unwound_pieces(tables, held, whole, period)
        offset = turns * period if wraps else 0.0
        y, mode, phase = settle_mode_in_phase(model, t, y, phase, offset, mode, trajectory)
        if trajectory.status != "complete":
            break
        window = layout.switch_window(grid, period, phase, y[1] >= 0.0) if grid.size else None
        start = y  # settle_mode_in_phase's own array, never written: the guards are those of the mode at this start
        # (time_domain._segment)
        y_wrapped = start.copy()
        y_wrapped[0] = phase
        if tables:
            held = _held_pieces(tables, y_wrapped, held)
        values = rows[index, 2:].copy()
        values[-1] = sign_of(start[1])  # the crank's direction at this start (CompiledScene.piece_values)
        p = compiled.parameters_with(values, mode, window, held, y_wrapped)
        if compiled.normal_slot is not None:
            normal_sides = compiled.hold_normal(p, t, y_wrapped, normal_sides, crossed_normal)
            crossed_normal = None
        # without a switch window or a driven part's table no guard reads phi: the stepper wraps it itself instead
        # of returning to restart
        wrap_period = period if wraps and window is None and not layout.turning else 0.0
        linear = compiled.linear(mode, window, start[1], held, y_wrapped)
        run = _step(
            layout.fixed,
            linear,
            t,
            y_wrapped,
            t_end,
            p,
            first_step,
            wrap_period,
            time_domain.MAX_STEPS - stats.steps,
            offset,
            following,
        )
        t_stop = run.t_end
        if index < split <= index + run.pieces_done:  # went on into pieces[split]: its start is a step's start
            split_start = rows[split - 1, 0]
            first = bisect.bisect_left(run.times, split_start, 0, run.n_steps)  # searchsorted's, without its set-up
            if first < run.n_steps and run.times[first] == split_start:
                at_split = (run.y_old[first].copy(), mode, len(trajectory.events))
        dense = run.dense  # None when no step was taken
        if dense is not None:
            trajectory.add_piece(t, t_stop, dense, step_ends=run.times[1:])
        stats.steps += int(run.n_steps)
        stats.nfev += int(run.nfev)
        stats.njev += int(run.njev)
        stats.nlu += int(run.nlu)
        stats.restarts += int(run.wraps) + int(run.kinks)
        stats.switches += int(run.kinks)
        if run.kinks:  # the stepper went on into later windows: phi's offset and the window are those of the last
            later, window = round(run.offset / period), (run.window_lo, run.window_hi)
            if tables:
                held = _unwound_pieces(tables, held, later - turns, period)
            turns = later
            offset = turns * period
        if run.pieces_done:  # and into later pieces: the last is the one stepped now
            index += int(run.pieces_done)
            t_end = float(rows[index, 0])
            following = following[run.pieces_done :]
        if run.last_step > 0.0:  # within the reach of the journals' branch points the last step saw (integrators)
            first_step = min(run.last_step, t_end - t_stop, run.step_limit)
        t_old, t = t, t_stop
        y = np.array(run.y_end, dtype=float)
        phase = y[0]  # less offset (the stepper's own wraps added back)
        y[0] += offset
        y_stop = y.copy()  # the state where the call stopped, before an event's transition
        # the restart this call ended in, (format, its arguments), put in words only should the run stall
        what: tuple[str, tuple[object, ...]] = ("the end of a call", ())
        if run.status == integrators.FAILED and run.failure in (integrators.NONFINITE, integrators.STEP_TOO_SMALL):
            settings = model.scene.solver
            trajectory.status = "failed"
            if run.failure == integrators.NONFINITE:
                advice = "use a smaller step" if settings.method == "RK4" else "tighten rtol/atol or limit max_step"
                trajectory.message = f"{settings.method}: the state became non-finite at t = {t:.6g} s; {advice}"
            else:
                trajectory.message = f"{settings.method} failed: {run.message}"
        elif run.status == integrators.EVENT:
            g = int(run.event_guard)
            if compiled.window_slot is not None and g >= compiled.window_slot:
                stats.switches += 1
                assert window is not None, "a switch angle's guard is armed only within a switch window"
                phase = window[g - compiled.window_slot]
                y[0] = offset + phase
                stats.restarts += int(t < t_end)
                what = ("the switch angle phi = {:.12g} rad ({:.12g} rad in its period)", (y[0], phase))
            elif compiled.normal_slot is not None and 0 <= g - compiled.normal_slot < compiled.n_normals:
                crossed_normal = g - compiled.normal_slot  # a guide's N = 0: its other sign held, mode and state kept
                normal_sides = tuple(-side if k == crossed_normal else side for k, side in enumerate(normal_sides))
                stats.switches += 1
                stats.restarts += int(t < t_end)
                what = ("a guide's normal force N = 0 (guide {})", (crossed_normal,))
            elif compiled.breakpoint_slot is not None and g >= compiled.breakpoint_slot:  # a table's: its next piece
                table, side = divmod(g - compiled.breakpoint_slot, 2)
                held[table] += 1 if side else -1
                stats.switches += 1
                stats.restarts += int(t < t_end)
                what = ("a breakpoint of the table {}", (tables[table].name,))
            else:
                guard = model.guards(mode, start)[g]
                mode, y = guard.apply(t, y)
                y = np.array(y, dtype=float)
                _log_event(trajectory, t, guard.name, mode)
                instant_events = instant_events + 1 if t == t_old else 0
                if instant_events > MAX_INSTANT_EVENTS:
                    _fail_stuck(trajectory, t)
                stats.restarts += 1
                what = ("the guard '{}'", (guard.name,))
        elif run.status == integrators.WRAPPED and t < t_end:
            stats.restarts += 1
            what = ("a wrap of the crank angle", ())
        stalled = stalled + 1 if t == t_old and not run.n_steps and not run.pieces_done else 0
        if run.beyond >= 0:  # a speed beyond MAX_SPEED at the last step's end: the run stops there (time_domain)
            fail_blown_up(model, trajectory, t, y_stop, model.state_names()[run.beyond], float(y_stop[run.beyond]))
        elif trajectory.status == "complete" and stats.steps >= time_domain.MAX_STEPS:
            fail_too_many_steps(model, trajectory, t, y_stop)
        elif trajectory.status == "complete" and stalled >= MAX_RESTARTS_WITHOUT_PROGRESS:
            fail_no_progress(model, trajectory, t, y_stop, what[0].format(*what[1]))
        if progress is not None:
            progress(t)
    return y, mode, index + 1, at_split


def _step(
    fixed: _FixedArguments,
    linear: np.ndarray,
    t: float,
    y: np.ndarray,
    t_end: float,
    p: np.ndarray,
    first_step: float,
    wrap_period: float,
    run_steps: int,
    offset: float,
    following: np.ndarray,
) -> results.CompiledRun:
    """One call of the scene's compiled stepper from (t [s], y) to t_end [s] at most, as a results.CompiledRun: the
    arguments that change from call to call here, the others the layout's (fixed); run_steps: the most steps it may
    take (the run's left); offset: phi's whole periods [rad]; following: the pieces it may go on into (integrators'
    module docstring)."""
    (
        rhs,
        guards,
        n_guards,
        thresholds,
        reactions,
        n_journals,
        rtol,
        atol,
        max_step,
        step,
        wrap_limit,
        kink_grid,
        period,
        kink_slots,
        speed_indices,
        method,
    ) = fixed
    rk4 = method == "RK4"
    journals = () if rk4 else (reactions, n_journals)  # the adaptive ones keep their steps within their branch points
    stepping = (step,) if rk4 else (rtol, atol, max_step, first_step)
    result = _entry_point(method)(
        rhs,
        guards,
        n_guards,
        linear,
        thresholds,
        *journals,
        t,
        y,
        t_end,
        p,
        *stepping,
        wrap_limit,
        wrap_period,
        MAX_STEPS_PER_CALL,
        run_steps,
        kink_grid,
        period,
        offset,
        kink_slots,
        speed_indices,
        following,
        PIECE_INDEX,
        MAX_RESTARTS_PER_CALL,
    )
    return results.CompiledRun.from_result(result)


@functools.cache
def _entry_point(method: str):
    """The machine-code entry of the method's compiled stepper for its one explicit signature: calling it skips
    numba's type dispatch of the arguments (some 15 us per call, as much as a short call's integration)."""
    (compiled,) = steppers.stepper(method).overloads.values()
    return compiled.entry_point
