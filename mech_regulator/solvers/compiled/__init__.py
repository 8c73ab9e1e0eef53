"""The compiled fast path: the right-hand side a scene assembles (only its effects) generated as source,
compiled once by numba and cached on disk, stepped by compiled integrators (solvers/compiled/integrators.py).
The pure-Python path (solvers/time_domain.py) stays the reference it is tested against.

This package's own namespace stays light (no numba import): fast_path_refusal is what a sweep or a benchmark asks
before choosing a path."""

from __future__ import annotations

FAST_METHODS = ("RK45", "DOP853", "RK4", "Rosenbrock23")
AUTO_PATH_VARIABLE = "MECH_REGULATOR_AUTO_PATH"  # 'reference' or 'fast': what solver.path auto means on this machine


def runs_compiled(solver) -> bool:
    """Whether the core (solvers.simulate, the co-simulation's steppers) steps a scene's solver settings on the fast
    path: solver.path fast, or auto with Rosenbrock23 (which only the fast path has). Auto is otherwise the reference
    path here: the core never chooses by what happens to be compiled; commands resolve auto first
    (solvers.on_path_for_a_command)."""
    return solver.path == "fast" or (solver.path == "auto" and solver.method == "Rosenbrock23")


def fast_path_refusal(scene_or_model) -> str | None:
    """Why a scene (or its model) cannot run on the fast path, naming the key, its value and what the fast path
    has; None when it can (the fast path compiles every machine the scene format describes; the solver methods it
    has no compiled stepper for stay on the reference path)."""
    scene = getattr(scene_or_model, "scene", scene_or_model)
    method = scene.solver.method
    if method not in FAST_METHODS:
        return (
            f"solver.path: 'fast' does not run solver.method: '{method}'; expected one of "
            f"{', '.join(FAST_METHODS)}, or solver.path: reference"
        )
    return None
