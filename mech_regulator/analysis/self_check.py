"""Every run checks itself: a run whose own bookkeeping shows more error than its tolerance allows is not
"complete" but "inaccurate" (the command line says which check, its value, what is allowed and how to fix it).

Two checks:

- the energy balance (analysis/energy.py): the works of all moments minus the change of the stored energy, relative
  to the largest energy involved. It is the run's global integration error seen through a conservation law, so it
  grows with the tolerance: an adaptive method's tolerance rtol allows ENERGY_PER_RTOL * rtol (errors accumulate
  over thousands of steps, and tables with kinks cost the bundled engines up to 7.7e-6 at rtol 1e-9 — inside the
  bound; a table with near-vertical steps costs 1e-2, far outside it); the fixed-step methods (RK4, the energy
  method) have no tolerance: FIXED_STEP_RESIDUAL;
- the mode log (a missed event): inside every stretch the run spent in one mode of the governor or the drive train
  (a sleeve sliding up, stuck, on a stop; a clutch slipping...), each guard of that mode must stay >= 0 — a guard
  below 0 is an event the run did not see (a sleeve that should have broken away, a pass through a stop). Checked on
  the dense output at MODE_SAMPLES_PER_RUN samples at most (the scene's sample rate when that gives fewer), the
  deepest violation relative to the guard's own largest |value| in the stretch; allowed MODE_PER_RTOL * rtol
  (fixed-step methods: FIXED_STEP_MODE).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mech_regulator.model import MachineModel
from mech_regulator.solvers.trajectory import SampledTrajectory, Trajectory

ENERGY_PER_RTOL = 1e4  # [-] the relative energy residual an adaptive method's rtol allows, per unit of rtol
FIXED_STEP_RESIDUAL = 1e-4  # [-] the relative energy residual allowed to RK4 and the energy method
FIXED_STEP_METHODS = ("RK4", "energy")
MODE_PER_RTOL = 100.0  # [-] how far below 0 a mode's guard may dip, relative to its largest |value|, per unit of rtol
FIXED_STEP_MODE = 1e-4  # [-] the same for RK4 and the energy method
MODE_SAMPLES_PER_RUN = 5_000  # dense samples the mode-log check reads at most (its cost: about 0.1 s)
FIX_ADAPTIVE = (
    "tighten solver.rtol, limit solver.max_step (a load switched on and off within a step needs it), "
    "or choose another method (Radau or BDF for a stiff scene)"
)


def self_checks(
    model: MachineModel, summary: dict, trajectory: Trajectory | None = None, mode_log: ModeLogSoFar | None = None
) -> list[dict]:
    """The checks a run fails, each {check, value, allowed, fix}: the energy balance of its summary
    (analysis.summarise; none when nothing was computed) and, given its dense trajectory, its mode log
    (mode_log_check; mode_log: what a streamed run checked already). Empty when it passes."""
    return [
        check
        for check in (
            _energy_check(model, summary),
            mode_log_check(model, trajectory, mode_log) if trajectory is not None else None,
        )
        if check is not None
    ]


def _energy_check(model: MachineModel, summary: dict) -> dict | None:
    """The energy-residual check of a run's summary, or None when it passes or has no energy balance."""
    energy = summary.get("energy")
    if energy is None or energy["relative_residual"] != energy["relative_residual"]:  # none, or NaN
        return None
    solver = model.scene.solver
    if solver.method in FIXED_STEP_METHODS:
        allowed = FIXED_STEP_RESIDUAL
        fix = (
            "shorten solver.step" if solver.method == "RK4" else "shorten solver.phi_step_deg"
        ) + ", or choose an adaptive method (e.g. DOP853)"
    else:
        allowed, fix = ENERGY_PER_RTOL * solver.rtol, FIX_ADAPTIVE
    value = abs(energy["relative_residual"])
    if value <= allowed:
        return None
    return {"check": "energy residual (relative)", "value": value, "allowed": allowed, "fix": fix}


@dataclass
class ModeLogSoFar:
    """The mode-log check of a streamed run (analysis/stream.py) up to t_done [s]: the deepest guard found, (relative
    depth, guard name, time [s]) or None, and the spacing [s] of its samples (mode_log_spacing of the planned run)."""

    spacing: float
    t_done: float
    worst: tuple[float, str, float] | None = None


def mode_log_spacing(model: MachineModel, duration: float) -> float:
    """The spacing [s] of the mode-log check's samples over a run of duration [s]: MODE_SAMPLES_PER_RUN at most, the
    scene's sample rate when that gives fewer."""
    return max(1.0 / model.scene.solver.sample_rate, duration / MODE_SAMPLES_PER_RUN)


def mode_log_check(model: MachineModel, trajectory: Trajectory, so_far: ModeLogSoFar | None = None) -> dict | None:
    """The missed-event check of a dense run (module docstring): None when every mode's guards stay >= 0 within the
    allowance inside every stretch of the run's mode log (and for runs without modes, or known only at samples: a
    co-simulation's linear interpolation between exchanges is not the motion). so_far: what a streamed run checked
    before the dense output its trajectory still holds."""
    if not trajectory.modes or not trajectory.interpolants or isinstance(trajectory, SampledTrajectory):
        return None
    solver = model.scene.solver
    fixed = solver.method in FIXED_STEP_METHODS
    allowed = FIXED_STEP_MODE if fixed else MODE_PER_RTOL * solver.rtol
    if so_far is None:
        spacing = mode_log_spacing(model, trajectory.t_end - trajectory.t_start)
        so_far = ModeLogSoFar(spacing, trajectory.t_start)
    worst = deepest_guard(model, trajectory, so_far, trajectory.t_end)
    if worst is None or worst[0] <= allowed:
        return None
    depth, name, time = worst
    fix = "shorten " + ("solver.step" if solver.method == "RK4" else "solver.phi_step_deg") if fixed else FIX_ADAPTIVE
    return {
        "check": f"missed event ('{name}' below 0 at t = {time:.6g} s, relative to its range)",
        "value": depth,
        "allowed": allowed,
        "fix": fix,
    }


def deepest_guard(
    model: MachineModel, trajectory: Trajectory, so_far: ModeLogSoFar, t_to: float
) -> tuple[float, str, float] | None:
    """The deepest guard (relative depth, guard name, time [s]) below 0 in the stretches of the run's mode log, each
    read from so_far.t_done to t_to [s] at so_far.spacing, or so_far.worst when none is deeper."""
    worst = so_far.worst
    ends = [start for start, _ in trajectory.modes[1:]] + [trajectory.t_end]
    for (start, mode), end in zip(trajectory.modes, ends):
        start, end = max(start, so_far.t_done), min(end, t_to)
        guards = model.guards(mode)
        if end - start <= so_far.spacing or not guards:
            continue
        times = np.linspace(start, end, int((end - start) / so_far.spacing) + 2)[1:-1]
        states = trajectory(times)
        for guard in guards:
            levels = np.array([guard.level(t, states[:, i]) for i, t in enumerate(times)])
            scale = float(np.max(np.abs(levels)))
            lowest = int(np.argmin(levels))
            if scale > 0.0 and levels[lowest] < 0.0 and (worst is None or -levels[lowest] / scale > worst[0]):
                worst = (float(-levels[lowest] / scale), guard.name, float(times[lowest]))
    return worst
