"""Solvers: integration in time (scipy's adaptive methods, fixed-step RK4) and the textbook energy
method in phi. All return a dense Trajectory with the solver's statistics."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable

from mech_regulator.model import MachineModel
from mech_regulator.scene import SceneError
from mech_regulator.scene.limits import LONG_RUN
from mech_regulator.solvers.advice import energy_step_refusal, rk4_stability_refusal, stiffness_refusal
from mech_regulator.solvers.compiled import AUTO_PATH_VARIABLE, fast_path_refusal, runs_compiled
from mech_regulator.solvers.energy_method import integrate_energy_method
from mech_regulator.solvers.time_domain import integrate_time_domain
from mech_regulator.solvers.trajectory import Progress, SolverStats, Stream, Trajectory


def simulate(model: MachineModel, progress: Progress | None = None, stream: Stream | None = None) -> Trajectory:
    """Run the scene's scenario with the scene's solver (solver.method) on its path (solver.path: the reference
    path, or the compiled fast path, solvers/compiled/run.py, which refuses what it cannot run with a SceneError;
    auto runs on the reference path here, compiled.runs_compiled, a command resolves it first). An
    RK4 step outside the stability region of the scene's coupling, an explicit adaptive method that stability alone
    would hold to more steps than limits.MAX_STEPS, and an energy method's step that would take more, are refused
    with a SceneError (advice.py); so is a long run whose start, probed, takes steps at a rate that would pass
    MAX_STEPS (step_limit_refusal; a probe the user interrupted is returned: the run's start). stream: given the
    trajectory after each piece it gains (Trajectory.stream; analysis/stream.py), not the probe's."""
    reason = rk4_stability_refusal(model) or stiffness_refusal(model) or energy_step_refusal(model)
    if reason is not None:
        raise SceneError(reason)
    probed = step_limit_refusal(model)
    if isinstance(probed, Trajectory):
        return probed
    if probed is not None:
        raise SceneError(probed)
    if progress is not None and model.scene.scenario.duration > LONG_RUN:
        progress(0.0)  # the run begins after its probe, which a progress bar then counts as start-up, not as work
    return _integrate(model, progress, stream)


def _integrate(model: MachineModel, progress: Progress | None = None, stream: Stream | None = None) -> Trajectory:
    """The run of the scene's scenario on its path with its method (simulate, without the refusals)."""
    if runs_compiled(model.scene.solver):
        from mech_regulator.solvers.compiled.run import integrate_compiled

        return integrate_compiled(model, progress, stream)
    if model.scene.solver.method == "energy":
        return integrate_energy_method(model, progress, stream)
    return integrate_time_domain(model, progress, stream=stream)


def on_path_for_a_command(
    model: MachineModel, report: Callable[[str], object], compile_now: bool = False
) -> MachineModel:
    """The model a command (simulate, sweep, flywheel, run and the nodes) runs, its solver.path decided: fast or
    reference, never auto.

    solver.path reference stays; fast and auto (the default) run the fast path where it covers the scene
    (fast_path_refusal), else the reference path with a one-line note to `report`. Where the method's stepper is not
    compiled on this machine yet, auto runs the reference path with a note while a background process compiles the
    stepper for the next run (compiled/warm.py), so a first run is never a wait of most of a minute. A scene that
    asks for the fast path by name (solver.path fast) gets it: the stepper is compiled here first, announced with its
    estimate (warm.compile_before_the_run), as it is with `compile_now` (the main job, whose nodes the reference path
    slows to a tenth of their pace); Rosenbrock23, which only the fast path has, is compiled in the foreground,
    announced.
    The environment variable MECH_REGULATOR_AUTO_PATH (reference or fast) fixes what auto means on a machine that
    must not depend on what is compiled (a reproducible CI, the test suite)."""
    path: str = model.scene.solver.path
    if path == "auto":
        path = auto_path()
        if path == "reference" and model.scene.solver.method != "Rosenbrock23":
            return on_path(model, "reference")
    if path == "reference":
        return model
    refusal = fast_path_refusal(model)
    if refusal is not None:
        report(f"note: {refusal}; this run uses the reference path")
        return on_path(model, "reference")
    from mech_regulator.solvers.compiled.warm import (
        compile_before_the_run,
        compile_estimate,
        compile_in_background,
        stepper_cached,
    )

    method = model.scene.solver.method
    if stepper_cached(method):
        return on_path(model, "fast")
    if compile_now or model.scene.solver.path == "fast":
        compile_before_the_run(method, lambda line: report(f"note: {line.strip()}"))
        return on_path(model, "fast")
    if method == "Rosenbrock23":
        report(
            f"note: compiling the fast path's {method} stepper once ({compile_estimate(method)}); later runs start at once"
        )
        return on_path(model, "fast")
    started = compile_in_background([method])
    report(
        f"note: the fast path's {method} stepper is {'now compiling' if started else 'compiling'} in the "
        f"background (once, {compile_estimate(method)}); this run uses the reference path, later runs the fast path"
    )
    return on_path(model, "reference")


def auto_path() -> str:
    """What solver.path auto means for a command on this machine: the environment variable MECH_REGULATOR_AUTO_PATH
    (reference or fast) when set, else fast (where it covers the scene and is compiled: on_path_for_a_command)."""
    chosen = os.environ.get(AUTO_PATH_VARIABLE, "")
    if chosen not in ("", "reference", "fast"):
        raise SceneError(
            f"{AUTO_PATH_VARIABLE}={chosen!r}: expected reference or fast (what solver.path auto "
            "means), or leave it unset"
        )
    return chosen or "fast"


def on_path(model: MachineModel, path: str) -> MachineModel:
    """The same scene with solver.path set to `path` (the model itself when it already has it)."""
    if model.scene.solver.path == path:
        return model
    from mech_regulator.model import build_model

    solver = model.scene.solver.model_copy(update={"path": path})
    return build_model(model.scene.model_copy(update={"solver": solver}))


def step_limit_refusal(model: MachineModel) -> str | Trajectory | None:
    """Why a run longer than limits.LONG_RUN [s] would pass limits.MAX_STEPS, worked out before it starts: its first
    limits.PROBE_DURATION s are stepped as the run steps them (same path, method and settings), and the probe's steps
    at its rate over the whole duration are the estimate (a machine at work repeats its cycle, so its steps come at a
    steady rate; a run that speeds up later may still stop at the limit, failed). Every method: an adaptive one's
    steps are known only so, and RK4's and the energy method's (limits.run_refusals, advice.energy_step_refusal)
    grow by a step at each restart on a switch. None when the run fits or is short; the probe's trajectory when the
    user interrupted it."""
    from mech_regulator.scene.limits import MAX_STEPS, PROBE_DURATION

    scene = model.scene
    duration, method = scene.scenario.duration, scene.solver.method
    if duration <= LONG_RUN:
        return None
    scenario = scene.scenario.model_copy(update={"duration": PROBE_DURATION})
    probe = _integrate(dataclasses.replace(model, scene=scene.model_copy(update={"scenario": scenario})))
    if probe.status == "interrupted":
        return probe
    steps = probe.stats.steps * duration / PROBE_DURATION
    if probe.status != "complete" or steps <= MAX_STEPS:
        return None  # (a probe that failed: the run fails the same way, and says why)
    longest = MAX_STEPS * PROBE_DURATION / probe.stats.steps
    fixes = {"RK4": "a longer solver.step", "energy": "a longer solver.phi_step_deg"}.get(
        method,
        ("" if method == "DOP853" else "a method that takes longer steps (DOP853), or ") + "a looser solver.rtol",
    )
    return (
        f"scenario.duration = {duration:g} s: solver.method = {method} took {probe.stats.steps} steps over the "
        f"run's first {PROBE_DURATION:g} s, so some {steps:.4g} steps over {duration:g} s, beyond the limit of "
        f"{MAX_STEPS:g} steps of one run; expected scenario.duration <= {longest:.3g} s, or {fixes} (docs/scenes.md, "
        "Limits)"
    )


__all__ = [
    "SolverStats",
    "Trajectory",
    "auto_path",
    "on_path",
    "on_path_for_a_command",
    "simulate",
    "step_limit_refusal",
]
