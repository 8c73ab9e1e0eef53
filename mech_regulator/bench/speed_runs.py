"""The runs every family of the speed benchmark's measurements (bench/speed.py) times: the paths compared, a run on
the fast or reference path or with solve_ivp and its outcome, its median CPU time, and the rows measured."""

from __future__ import annotations

import dataclasses
import functools
import math
import statistics
from collections.abc import Callable

import numpy as np
from scipy.integrate import solve_ivp

from mech_regulator.bench.accuracy import time_grid, timed
from mech_regulator.model import MachineModel
from mech_regulator.solvers import simulate

BENCH_SCENE = "crank_slider_bench"
FAST, REFERENCE, SOLVE_IVP, MUJOCO = "fast", "reference", "solve_ivp", "MuJoCo"
PATHS = (
    (FAST, "RK45"),
    (FAST, "DOP853"),
    (REFERENCE, "DOP853"),
    (SOLVE_IVP, "RK45"),
    (SOLVE_IVP, "DOP853"),
    (MUJOCO, "RK4"),
)
REPEAT_BUDGET_S, MAX_REPEATS = 0.3, 7  # a run is repeated to about this much CPU time [s], at most this often


def solver_overrides(path: str, method: str, rtol: float, state_scale: float) -> list[str]:
    """Scene overrides selecting a path's method and tolerances (atol = rtol x state_scale)."""
    overrides = [f"solver.method={method}", f"solver.rtol={rtol!r}", f"solver.atol={rtol * state_scale!r}"]
    return overrides + (["solver.path=fast"] if path == FAST else [])


@dataclasses.dataclass
class Outcome:
    """One run: its speed at `times` [s] (`speed`: omega [rad/s] there, or the dense output's omega(t), read only
    when `omega` is asked for, after the run's CPU time was taken: sampling 20 kHz of dense output is not
    simulation), right-hand-side evaluations (MuJoCo: 4 forward-dynamics evaluations per RK4 step), steps, and
    status ('complete' or why not)."""

    times: np.ndarray
    speed: np.ndarray | Callable[[np.ndarray], np.ndarray]
    nfev: int
    steps: int
    status: str = "complete"

    @functools.cached_property
    def omega(self) -> np.ndarray:
        """omega [rad/s] at `times` (empty for a run that did not complete)."""
        if self.status != "complete":
            return np.zeros(0)
        return self.speed(self.times) if callable(self.speed) else self.speed


def ode_runner(path: str, method: str, model: MachineModel) -> Callable[[], Outcome]:
    """A run of a model on the fast or reference path (solvers.simulate: the model's scene says which) or with
    solve_ivp on its plain-Python right-hand side, sampled on accuracy.time_grid."""
    grid = time_grid(model.scene.scenario.duration)
    if path != SOLVE_IVP:

        def run() -> Outcome:
            trajectory = simulate(model)
            complete = trajectory.status == "complete"
            return Outcome(
                grid,
                lambda times: trajectory(times)[1],
                trajectory.stats.nfev,
                trajectory.stats.steps,
                "complete" if complete else f"{trajectory.status}: {trajectory.message}",
            )

        return run
    y0 = model.initial_state()
    rhs = model.rhs(model.piece_at(0.0), None, model.initial_mode(y0))
    solver = model.scene.solver

    def run_ivp() -> Outcome:
        solution = solve_ivp(
            rhs,
            (0.0, model.scene.scenario.duration),
            y0,
            method=method,
            rtol=solver.rtol,
            atol=solver.atol,
            dense_output=True,
        )
        return Outcome(
            grid,
            lambda times: solution.sol(times)[1],
            solution.nfev,
            len(solution.t) - 1,
            "complete" if solution.success else f"failed: {solution.message}",
        )

    return run_ivp


def median_cpu(run: Callable[[], Outcome], quick: bool) -> tuple[Outcome, float, int]:
    """(outcome, median CPU time [s], repeats): run repeated until REPEAT_BUDGET_S of CPU time, at most
    MAX_REPEATS times (once when quick), after one run that is not counted (the fast path's first run in a process
    loads, or compiles, the scene's module: that is the start-up cost, measured on its own)."""
    run()
    outcome, cpu = timed(run)
    times = [cpu]
    if not quick:
        repeats = min(MAX_REPEATS, math.ceil(REPEAT_BUDGET_S / max(cpu, 1e-9)))
        times += [timed(run)[1] for _ in range(repeats - 1)]
    return outcome, statistics.median(times), len(times)


@dataclasses.dataclass
class Row:
    """One measurement: section ('precision', 'duration', 'effects', 'sweep', 'startup', 'ros'), scene, path,
    method, the setting varied and its value, simulated time [s], CPU time [s] (wall time [s] for 'startup',
    'sweep' and 'ros', which span processes), RHS evaluations, steps, achieved error [-] and a note."""

    section: str
    scene: str
    path: str
    method: str
    setting: str
    value: float
    simulated_s: float
    cpu_s: float = math.nan
    nfev: float = math.nan
    steps: float = math.nan
    error: float = math.nan
    note: str = ""


@dataclasses.dataclass
class SpeedBenchmark:
    """Every row measured, whether it ran quick, where (accuracy.environment), and whether interrupted."""

    rows: list[Row] = dataclasses.field(default_factory=list)
    quick: bool = False
    environment: dict[str, str] = dataclasses.field(default_factory=dict)
    interrupted: bool = False

    def of(self, section: str, **where) -> list[Row]:
        """The rows of a section whose fields equal `where`."""
        return [
            row
            for row in self.rows
            if row.section == section and all(getattr(row, key) == value for key, value in where.items())
        ]
