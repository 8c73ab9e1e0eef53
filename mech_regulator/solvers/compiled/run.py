"""The fast path's outer loop: the reference path's segments, modes and restarts (solvers/time_domain.py) around the
compiled right-hand side (codegen.py) and the compiled integrators (integrators.py).

Each external-load piece is integrated on its own; within it the mode is settled, p is set for the piece, the mode
and the switch window, and the scene's compiled stepper runs until the piece ends, a guard fires (a governor or
driven-part event, located in the stepper; its transition is the model's own Guard, applied here), the crank angle
passes the wrap limit (it is re-wrapped by whole dynamic periods and the stepper restarts with its last step size;
without a switch window the stepper does that itself, without returning) or MAX_STEPS_PER_CALL steps are done (so
that progress moves and Ctrl-C is heard). Every call's steps become one piece of the Trajectory, with the ends of
those steps (Trajectory.step_ends: the works of the energy balance are integrated step by step).
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np

from mech_regulator.model import MachineModel
from mech_regulator.scene import SceneError, schema
from mech_regulator.solvers.compiled import fast_path_refusal, integrators
from mech_regulator.solvers.compiled.codegen import CompiledScene, compile_scene
from mech_regulator.solvers.time_domain import (MAX_INSTANT_EVENTS, RESTART_PERIODS, _fail_stuck, _held_pieces,
                                                _log_event, _settle_mode, _Shifted, _switch_window,
                                                integrate_time_domain)
from mech_regulator.solvers.trajectory import Progress, Trajectory

MAX_STEPS_PER_CALL = 2000  # a stepper call returns to Python after this many steps (progress moves, Ctrl-C is heard);
# the next call warm-starts with the last step size


def integrate_compiled(model: MachineModel, progress: Progress | None = None) -> Trajectory:
    """Integrate the scene's scenario on the fast path; returns the (possibly partial) trajectory, with the same
    statuses and messages as the reference path (time_domain.integrate_time_domain). A scene the fast path cannot
    run raises SceneError (fast_path_refusal)."""
    return integrate_time_domain(model, progress, compiled_segment(model))


def compiled_segment(model: MachineModel):
    """time_domain._segment's compiled twin for this model (same arguments and result; the scene compiled once here):
    what integrate_compiled and the co-simulation's steppers (solvers/cosim.py) step a load piece or an exchange
    step with. A model the fast path cannot run raises SceneError (fast_path_refusal)."""
    reason = fast_path_refusal(model)
    if reason is not None:
        raise SceneError(reason)
    compiled = compile_scene(model)
    return functools.partial(_compiled_segment, compiled, _Layout.of(model, compiled))


class _Layout(NamedTuple):
    """What every segment of a model reuses (a co-simulation steps thousands of short ones): its switch grid [rad],
    dynamic period [rad], whether the crank angle is wrapped, the absolute tolerances and the guards' thresholds."""

    grid: list[float]
    period: float
    wraps: bool
    atol: np.ndarray
    thresholds: np.ndarray

    @classmethod
    def of(cls, model: MachineModel, compiled: CompiledScene) -> _Layout:
        """The layout of a model and its compiled scene."""
        return cls(grid=model.switch_grid(), period=model.dynamic_period(),
                   wraps=model.reduced is not None or "phi" in model.depends_on(),
                   atol=np.full(len(model.state_names()), model.scene.solver.atol),
                   thresholds=np.zeros(compiled.n_guards))  # the steppers apply time_domain's GUARD_TOLERANCE


def _compiled_segment(compiled: CompiledScene, layout: _Layout, model: MachineModel, piece, t_start: float,
                      t_end: float, y: np.ndarray, mode, trajectory: Trajectory, progress: Progress | None):
    """time_domain._segment on the fast path: step [t_start, t_end] with the compiled stepper, restarting at every
    event (mode transition applied), switch angle and wrap of the crank angle; returns the state and mode at the
    end."""
    settings = model.scene.solver
    grid, period, wraps, atol, thresholds = layout
    wrap_limit = RESTART_PERIODS * period if wraps else math.inf
    t, first_step = t_start, 0.0
    tables = model.state_tables
    turning = any(table.angular for table in tables)  # a guard reads phi (a driven part's table at phi - twist)
    held = _held_pieces(tables, y)
    normal_side, crossed_normal = 0.0, False  # joint friction's guide: the held sign of N, just crossed (issue 19)
    instant_events = 0
    while t < t_end and trajectory.status == "complete":
        y, mode = _settle_mode(model, t, y, mode, trajectory)
        if trajectory.status != "complete":
            break
        offset = period * math.floor(y[0] / period) if wraps else 0.0
        window = _switch_window(grid, period, y[0] - offset, forward=y[1] >= 0.0) if grid else None
        start = np.array(y, dtype=float)  # the guards are those of the mode at this start (time_domain._segment)
        held = _held_pieces(tables, y, held)
        p = compiled.parameters_for(piece, mode, window, start[1], held, start, offset)
        y_wrapped = start.copy()
        y_wrapped[0] -= offset
        if compiled.normal_slot is not None:
            normal_side = compiled.hold_normal(p, t, y_wrapped, normal_side if crossed_normal else 0.0)
            crossed_normal = False
        # without a switch window or a driven part's table no guard reads phi: the stepper wraps it itself instead
        # of returning to restart
        wrap_period = period if wraps and window is None and not turning else 0.0
        linear = compiled.linear(mode, window, start[1], held, start, offset)
        run = _step(settings, compiled, linear, thresholds, t, y_wrapped, t_end, p,
                    atol, first_step, wrap_limit, wrap_period)
        if run.n_steps:
            trajectory.add_piece(t, run.t_end, _Shifted(run.dense, offset), step_ends=run.times[1:])
        trajectory.stats.steps += int(run.n_steps)
        trajectory.stats.nfev += int(run.nfev)
        trajectory.stats.njev += int(run.njev)
        trajectory.stats.nlu += int(run.nlu)
        trajectory.stats.restarts += int(run.wraps)
        if run.last_step > 0.0:
            first_step = min(run.last_step, t_end - run.t_end)
        t_old, t = t, run.t_end
        y = np.array(run.y_end, dtype=float)
        y[0] += offset
        if run.status == integrators.FAILED and run.failure != integrators.TOO_MANY_STEPS:
            trajectory.status = "failed"
            if run.failure == integrators.NONFINITE:
                advice = "use a smaller step" if settings.method == "RK4" else "tighten rtol/atol or limit max_step"
                trajectory.message = f"{settings.method}: the state became non-finite at t = {t:.6g} s; {advice}"
            else:
                trajectory.message = f"{settings.method} failed: {run.message}"
        elif run.status == integrators.EVENT:
            g = int(run.event_guard)
            if compiled.window_slot is not None and g >= compiled.window_slot:
                trajectory.stats.switches += 1
                y[0] = offset + window[g - compiled.window_slot]
                trajectory.stats.restarts += int(t < t_end)
            elif g == compiled.normal_slot:  # the guide's N = 0: the other sign held, mode and state kept
                normal_side, crossed_normal = -normal_side, True
                trajectory.stats.switches += 1
                trajectory.stats.restarts += int(t < t_end)
            elif compiled.breakpoint_slot is not None and g >= compiled.breakpoint_slot:  # a table's: its next piece
                table, side = divmod(g - compiled.breakpoint_slot, 2)
                held[table] += 1 if side else -1
                trajectory.stats.switches += 1
                trajectory.stats.restarts += int(t < t_end)
            else:
                guard = model.guards(mode, start)[g]
                mode, y = guard.apply(t, y)
                y = np.array(y, dtype=float)
                _log_event(trajectory, t, guard.name, mode)
                instant_events = instant_events + 1 if t == t_old else 0
                if instant_events > MAX_INSTANT_EVENTS:
                    _fail_stuck(trajectory, t)
                trajectory.stats.restarts += 1
        elif run.status == integrators.WRAPPED and t < t_end:
            trajectory.stats.restarts += 1
        if progress is not None:
            progress(t)
    return y, mode


def _step(settings: schema.Solver, compiled: CompiledScene, linear: np.ndarray, thresholds: np.ndarray, t: float,
          y: np.ndarray, t_end: float, p: np.ndarray, atol: np.ndarray, first_step: float, wrap_limit: float,
          wrap_period: float):
    """One call of the scene's compiled stepper, as an integrators.CompiledRun."""
    common = (compiled.rhs_callback, compiled.guards_callback, compiled.n_guards, linear, thresholds, t, y, t_end, p)
    stepper = _entry_point(settings.method)
    if settings.method == "RK4":
        result = stepper(*common, settings.step, wrap_limit, wrap_period, MAX_STEPS_PER_CALL)
    else:
        result = stepper(*common, settings.rtol, atol, settings.max_step or math.inf, first_step, wrap_limit,
                         wrap_period, MAX_STEPS_PER_CALL)
    return integrators.CompiledRun.from_result(result)


@functools.cache
def _entry_point(method: str):
    """The machine-code entry of the method's compiled stepper for its one explicit signature: calling it skips
    numba's type dispatch of the arguments (some 15 us per call, as much as a short call's integration)."""
    (compiled,) = integrators.stepper(method).overloads.values()
    return compiled.entry_point
