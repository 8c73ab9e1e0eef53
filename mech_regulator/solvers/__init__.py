"""Solvers: integration in time (scipy's adaptive methods, fixed-step RK4) and the textbook energy
method in phi. All return a dense Trajectory with the solver's statistics."""

from __future__ import annotations

from mech_regulator.model import MachineModel
from mech_regulator.scene import SceneError
from mech_regulator.solvers.advice import rk4_stability_refusal
from mech_regulator.solvers.energy_method import integrate_energy_method
from mech_regulator.solvers.time_domain import integrate_time_domain
from mech_regulator.solvers.trajectory import Progress, SolverStats, Trajectory


def simulate(model: MachineModel, progress: Progress | None = None) -> Trajectory:
    """Run the scene's scenario with the scene's solver (solver.method) on its path (solver.path: the reference
    path, or the compiled fast path, solvers/compiled/run.py, which refuses what it cannot run with a SceneError). An
    RK4 step outside the stability region of the scene's coupling is refused with a SceneError (advice.py)."""
    reason = rk4_stability_refusal(model)
    if reason is not None:
        raise SceneError(reason)
    if model.scene.solver.path == "fast":
        from mech_regulator.solvers.compiled.run import integrate_compiled

        return integrate_compiled(model, progress)
    if model.scene.solver.method == "energy":
        return integrate_energy_method(model, progress)
    return integrate_time_domain(model, progress)


__all__ = ["SolverStats", "Trajectory", "simulate"]
