"""The fast path's outer loop: the reference path's segments, modes and restarts (solvers/time_domain.py) around the
compiled right-hand side (codegen.py) and the compiled integrators (integrators.py).

Each external-load piece is integrated on its own; within it the mode is settled, p is set for the piece, the mode
and the switch window, and the scene's compiled stepper runs until the piece ends, a guard fires (a governor or
driven-part event, located in the stepper; its transition is the model's own Guard, applied here), the crank angle
passes the wrap limit (it is re-wrapped by whole dynamic periods and the stepper restarts with its last step size)
or MAX_STEPS_PER_CALL steps are done (so that progress moves and Ctrl-C is heard). Every call's steps become one
piece of the Trajectory.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from mech_regulator.model import MachineModel
from mech_regulator.scene import SceneError, schema
from mech_regulator.solvers.compiled import integrators
from mech_regulator.solvers.compiled.codegen import CompiledScene, compile_scene
from mech_regulator.solvers.time_domain import (GUARD_TOLERANCE, MAX_INSTANT_EVENTS, RESTART_PERIODS, _fail_stuck,
                                                _log_event, _settle_mode, _Shifted, _switch_window,
                                                integrate_time_domain)
from mech_regulator.solvers.trajectory import Progress, Trajectory

FAST_METHODS = ("RK45", "DOP853", "RK4", "Rosenbrock23")
MAX_STEPS_PER_CALL = 2000  # a stepper call returns to Python after this many steps (progress, Ctrl-C)


def fast_path_refusal(scene_or_model) -> str | None:
    """Why a scene (or its model) cannot run on the fast path, naming the key, its value and what the fast path
    has; None when it can."""
    scene = getattr(scene_or_model, "scene", scene_or_model)
    method = scene.solver.method
    if method not in FAST_METHODS:
        return (f"solver.path: 'fast' does not run solver.method: '{method}'; expected one of "
                f"{', '.join(FAST_METHODS)}, or solver.path: reference")
    machine = scene.machine
    coupling = machine.coupling
    mechanism = machine.mechanism
    features = [
        ("machine.clutch", machine.clutch is not None),
        ("machine.joint_friction", machine.joint_friction is not None),
        ("machine.mechanism.cylinders (a multi-cylinder engine)",
         isinstance(mechanism, schema.CrankSlider) and mechanism.cylinders is not None),
        ("machine.mechanism: walking_beam", isinstance(mechanism, schema.WalkingBeam)),
        ("machine.coupling.driven.branches", coupling is not None and bool(coupling.driven.branches)),
        ("machine.coupling.driven.mechanism: walking_beam",
         coupling is not None and isinstance(coupling.driven.mechanism, schema.WalkingBeam)),
    ]
    for key, present in features:
        if present:
            return f"solver.path: 'fast' does not compile {key} yet; expected a scene without it, or solver.path: reference"
    return None


def integrate_compiled(model: MachineModel, progress: Progress | None = None) -> Trajectory:
    """Integrate the scene's scenario on the fast path; returns the (possibly partial) trajectory, with the same
    statuses and messages as the reference path (time_domain.integrate_time_domain). A scene the fast path cannot
    run raises SceneError (fast_path_refusal)."""
    reason = fast_path_refusal(model)
    if reason is not None:
        raise SceneError(reason)
    compiled = compile_scene(model)
    return integrate_time_domain(model, progress, functools.partial(_compiled_segment, compiled))


def _compiled_segment(compiled: CompiledScene, model: MachineModel, piece, t_start: float, t_end: float,
                      y: np.ndarray, mode, trajectory: Trajectory, progress: Progress | None):
    """time_domain._segment on the fast path: step [t_start, t_end] with the compiled stepper, restarting at every
    event (mode transition applied), switch angle and wrap of the crank angle; returns the state and mode at the
    end."""
    settings = model.scene.solver
    grid = model.switch_grid()
    period = model.dynamic_period()
    wraps = model.reduced is not None or "phi" in model.depends_on()
    wrap_limit = RESTART_PERIODS * period if wraps else math.inf
    atol = np.full(y.size, settings.atol)
    levels = np.empty(compiled.n_guards)
    t, first_step = t_start, 0.0
    instant_events = 0
    while t < t_end and trajectory.status == "complete":
        y, mode = _settle_mode(model, t, y, mode, trajectory)
        if trajectory.status != "complete":
            break
        offset = period * math.floor(y[0] / period) if wraps else 0.0
        window = _switch_window(grid, period, y[0] - offset, forward=y[1] >= 0.0) if grid else None
        p = compiled.parameters_for(piece, mode, window)
        y_wrapped = np.array(y, dtype=float)
        y_wrapped[0] -= offset
        compiled.guards(t, y_wrapped, p, levels)
        thresholds = np.where(levels <= GUARD_TOLERANCE, -GUARD_TOLERANCE, 0.0)
        run = _step(settings, compiled, compiled.linear(mode, window), thresholds, t, y_wrapped, t_end, p, atol,
                    first_step, wrap_limit)
        trajectory.add_piece(t, run.t_end, _Shifted(run.dense(), offset))
        trajectory.stats.steps += run.n_steps
        trajectory.stats.nfev += run.nfev
        trajectory.stats.njev += run.njev
        trajectory.stats.nlu += run.nlu
        first_step = min(run.last_step, t_end - run.t_end) if run.last_step > 0.0 else 0.0
        t_old, t = t, run.t_end
        y = np.array(run.y_end, dtype=float)
        y[0] += offset
        if run.status == integrators.FAILED:
            trajectory.status = "failed"
            if np.all(np.isfinite(run.y_end)):
                trajectory.message = f"{settings.method} failed at t = {t:.6g} s: the step size became too small"
            else:
                advice = "use a smaller step" if settings.method == "RK4" else "tighten rtol/atol or limit max_step"
                trajectory.message = (f"{settings.method}: the state became non-finite at t = {t:.6g} s; {advice}")
        elif run.status == integrators.EVENT:
            g = run.event_guard
            if compiled.window_slot is not None and g >= compiled.window_slot:
                trajectory.stats.switches += 1
                y[0] = offset + window[g - compiled.window_slot]
                trajectory.stats.restarts += t < t_end
            else:
                guard = model.guards(mode, y)[g]
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
          y: np.ndarray, t_end: float, p: np.ndarray, atol: np.ndarray, first_step: float, wrap_limit: float):
    """One call of the scene's compiled stepper, as an integrators.CompiledRun."""
    common = (compiled.rhs, compiled.guards, compiled.n_guards, linear, thresholds, t, y, t_end, p)
    if settings.method == "RK4":
        result = integrators.rk4(*common, settings.step, wrap_limit, MAX_STEPS_PER_CALL)
    else:
        stepper = {"RK45": integrators.rk45, "DOP853": integrators.dop853,
                   "Rosenbrock23": integrators.rosenbrock23}[settings.method]
        result = stepper(*common, settings.rtol, atol, settings.max_step or math.inf, first_step, wrap_limit,
                         MAX_STEPS_PER_CALL)
    return integrators.CompiledRun.from_result(result)
