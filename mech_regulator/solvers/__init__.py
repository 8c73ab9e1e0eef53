"""Solvers: integration in time (scipy's adaptive methods, fixed-step RK4) and the textbook energy
method in phi. All return a dense Trajectory with the solver's statistics."""

from __future__ import annotations

from collections.abc import Callable

from mech_regulator.model import MachineModel
from mech_regulator.scene import SceneError
from mech_regulator.solvers.advice import energy_step_refusal, rk4_stability_refusal, stiffness_refusal
from mech_regulator.solvers.energy_method import integrate_energy_method
from mech_regulator.solvers.time_domain import integrate_time_domain
from mech_regulator.solvers.trajectory import Progress, SolverStats, Trajectory


def simulate(model: MachineModel, progress: Progress | None = None) -> Trajectory:
    """Run the scene's scenario with the scene's solver (solver.method) on its path (solver.path: the reference
    path, or the compiled fast path, solvers/compiled/run.py, which refuses what it cannot run with a SceneError). An
    RK4 step outside the stability region of the scene's coupling, an explicit adaptive method that stability alone
    would hold to more steps than limits.MAX_STEPS, and an energy method's step that would take more, are refused
    with a SceneError (advice.py)."""
    reason = rk4_stability_refusal(model) or stiffness_refusal(model) or energy_step_refusal(model)
    if reason is not None:
        raise SceneError(reason)
    if model.scene.solver.path == "fast":
        from mech_regulator.solvers.compiled.run import integrate_compiled

        return integrate_compiled(model, progress)
    if model.scene.solver.method == "energy":
        return integrate_energy_method(model, progress)
    return integrate_time_domain(model, progress)


def on_path_for_a_command(model: MachineModel, report: Callable[[str], None]) -> MachineModel:
    """The model a command (simulate, sweep, flywheel, the nodes) runs: the scene's own, except that a scene asking
    for the fast path is served by the reference path — with a one-line note to `report` — where the fast path does
    not cover it (fast_path_refusal), or while its method's stepper is not compiled yet on this machine: that is then
    compiled by a background process for the next run (compiled/warm.py), so a first run is never a wait of half a
    minute. Rosenbrock23, which only the fast path has, is compiled in the foreground, announced."""
    if model.scene.solver.path != "fast":
        return model
    from mech_regulator.solvers.compiled import fast_path_refusal

    refusal = fast_path_refusal(model)
    if refusal is not None:
        report(f"note: {refusal}; this run uses the reference path")
        return on_reference_path(model)
    from mech_regulator.solvers.compiled.warm import compile_in_background, stepper_cached

    method = model.scene.solver.method
    if stepper_cached(method):
        return model
    if method == "Rosenbrock23":
        report(f"note: compiling the fast path's {method} stepper once (about 10-30 s); later runs start at once")
        return model
    started = compile_in_background([method])
    report(f"note: the fast path's {method} stepper is {'now compiling' if started else 'compiling'} in the "
           "background (once, about 10-30 s); this run uses the reference path, later runs the fast path")
    return on_reference_path(model)


def on_reference_path(model: MachineModel) -> MachineModel:
    """The same scene with solver.path: reference."""
    from mech_regulator.model import build_model

    solver = model.scene.solver.model_copy(update={"path": "reference"})
    return build_model(model.scene.model_copy(update={"solver": solver}))


__all__ = ["SolverStats", "Trajectory", "on_path_for_a_command", "on_reference_path", "simulate"]
