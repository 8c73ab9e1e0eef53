"""The speed benchmark's work–precision measurements (bench/speed.py): every path's accuracy setting swept on a speed
scene, each run's CPU time and achieved error; the work–precision front, each path's CPU time at TARGET_ERROR
interpolated along it, and the ratios of those times (the speed-ups)."""

from __future__ import annotations

import dataclasses
import importlib.util
import math
from collections.abc import Callable

import numpy as np

from mech_regulator.bench.accuracy import REFERENCE_METHOD, REFERENCE_RTOL, BenchScene, achieved_errors, error_scale
from mech_regulator.bench.mujoco_model import MujocoCrankSlider, mujoco_refusal
from mech_regulator.bench.speed_runs import (
    FAST,
    MUJOCO,
    PATHS,
    REFERENCE,
    SOLVE_IVP,
    Outcome,
    Row,
    SpeedBenchmark,
    median_cpu,
    ode_runner,
    solver_overrides,
)
from mech_regulator.model import MachineModel, build_model
from mech_regulator.solvers import simulate
from mech_regulator.solvers.compiled import fast_path_refusal

TARGET_ERROR = 1e-6  # common achieved error of the comparison (omega RMS, relative) [-]
TOLERANCES, QUICK_TOLERANCES = tuple(10.0**-k for k in range(4, 12)), (1e-5, 1e-7, 1e-9)
MUJOCO_STEPS = (4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4, 6.25e-5)  # [s]
QUICK_MUJOCO_STEPS = (1e-3, 5e-4, 2.5e-4)
MAX_ERROR_SAMPLES = 40_001  # MuJoCo's step times are thinned to at most this many for the error


def mujoco_runner(model: MachineModel, timestep: float) -> Callable[[], Outcome]:
    """A run of the scene's crank–slider in MuJoCo at a timestep [s] (bench.mujoco_model)."""
    multibody = MujocoCrankSlider(model.scene, timestep)
    duration = model.scene.scenario.duration

    def run() -> Outcome:
        result = multibody.run(duration)
        every = max(1, math.ceil(result.steps / MAX_ERROR_SAMPLES))
        return Outcome(result.times[::every], result.omega[::every], 4 * result.steps, result.steps)

    return run


def solve_ivp_refusal(model: MachineModel) -> str | None:
    """Why the plain solve_ivp baseline would not solve the scene's problem (None if it does): it has no
    events, restarts or modes."""
    if model.governor is not None or model.driven is not None or model.joint_friction is not None:
        return "modes and events (governor, drive train or joint friction) need the reference path's guards"
    if model.breakpoints() or model.switch_angles():
        return "moments that jump in t or phi need the reference path's restarts"
    return None


def work_precision_front(rows: list[Row]) -> list[Row]:
    """The runs of one path and method that no cheaper run beats in error, cheapest first."""
    front, best = [], math.inf
    for row in sorted((row for row in rows if row.error > 0.0 and math.isfinite(row.cpu_s)), key=lambda r: r.cpu_s):
        if row.error < best:
            front.append(row)
            best = row.error
    return front


def at_error(rows: list[Row], target: float, quantity: str = "cpu_s") -> float:
    """A quantity (cpu_s or nfev) needed to reach achieved error `target`: interpolated linearly in log-log along
    the work–precision front where it crosses the target; the cheapest run's when even that one is more accurate
    (then an upper bound: the sweep did not go looser); nan when no run reaches the target."""
    front = work_precision_front(rows)
    if not front or front[-1].error > target:
        return math.nan
    if front[0].error <= target:
        return float(getattr(front[0], quantity))
    errors = np.log10([row.error for row in front])[::-1]
    values = np.log10([getattr(row, quantity) for row in front])[::-1]
    return float(10.0 ** np.interp(math.log10(target), errors, values))


@dataclasses.dataclass(frozen=True)
class PathAtTarget:
    """A path and method on a scene at TARGET_ERROR: CPU time [s], RHS evaluations per CPU second and the
    real-time factor (simulated s per CPU s); nan where its front does not reach the target."""

    scene: str
    path: str
    method: str
    cpu_s: float
    rhs_per_s: float
    real_time_factor: float


def at_target(benchmark: SpeedBenchmark, scene: str, duration: float) -> list[PathAtTarget]:
    """Every path and method measured on a scene, at TARGET_ERROR."""
    results = []
    for path, method in PATHS:
        rows = benchmark.of("precision", scene=scene, path=path, method=method)
        if not rows:
            continue
        cpu = at_error(rows, TARGET_ERROR)
        results.append(
            PathAtTarget(scene, path, method, cpu, at_error(rows, TARGET_ERROR, "nfev") / cpu, duration / cpu)
        )
    return results


def ratios(results: list[PathAtTarget]) -> dict[str, float]:
    """CPU time of each other path's best method at TARGET_ERROR over the fast path's best (nan if either is
    missing): 'fast : solve_ivp', 'fast : reference', 'fast : MuJoCo'."""
    best: dict[str, float] = {}
    for result in results:
        if math.isfinite(result.cpu_s):
            best[result.path] = min(best.get(result.path, math.inf), result.cpu_s)
    fast = best.get(FAST, math.nan)
    return {f"fast : {path}": best.get(path, math.nan) / fast for path in (SOLVE_IVP, REFERENCE, MUJOCO)}


def measure_precision(bench: BenchScene, quick: bool, report: Callable[[Row], None], mujoco: bool = True) -> list[Row]:
    """Sweep every path's setting on a speed scene and measure each run's CPU time and achieved error (MuJoCo's
    path left out, with a note, when not `mujoco`)."""
    scene = bench.load(quick)
    duration = scene.scenario.duration
    if bench.closed_form is not None:
        reference = bench.closed_form(build_model(scene))
    else:
        reference = simulate(
            build_model(
                bench.load(
                    quick, tuple(solver_overrides(REFERENCE, REFERENCE_METHOD, REFERENCE_RTOL, bench.state_scale))
                )
            )
        )
    rows = []

    def add(path: str, method: str, setting: str, value: float, run: Callable[[], Outcome]) -> None:
        outcome, cpu, _repeats = median_cpu(run, quick)
        row = Row("precision", bench.name, path, method, setting, value, duration, cpu, outcome.nfev, outcome.steps)
        if outcome.status == "complete":
            omega_ref = reference(outcome.times)[1]
            scale = np.array([error_scale("omega", omega_ref)])
            row.error = achieved_errors(("omega",), scale, outcome.omega[None], omega_ref[None])["omega"][0]
        else:
            row.note = outcome.status
        rows.append(row)
        report(row)

    def refused(path: str, method: str, setting: str, refusal: str) -> None:
        """A path that does not run the scene: a row with the reason as its note (the tables list it)."""
        rows.append(Row("precision", bench.name, path, method, setting, math.nan, duration, note=refusal))
        report(rows[-1])

    for path, method in PATHS:
        if path == MUJOCO:
            refusal = (
                "left out (--no-mujoco)"
                if not mujoco
                else mujoco_refusal(scene)
                or (
                    None
                    if importlib.util.find_spec("mujoco")
                    else "mujoco is not installed: pip install 'mech_regulator[bench]'"
                )
            )
            steps = () if refusal is not None else QUICK_MUJOCO_STEPS if quick else MUJOCO_STEPS
            for timestep in steps:
                add(path, method, "timestep", timestep, mujoco_runner(build_model(scene), timestep))
            if refusal is not None:
                refused(path, method, "timestep", refusal)
            continue
        for rtol in QUICK_TOLERANCES if quick else TOLERANCES:
            model = build_model(bench.load(quick, tuple(solver_overrides(path, method, rtol, bench.state_scale))))
            refusal = (
                solve_ivp_refusal(model) if path == SOLVE_IVP else fast_path_refusal(model) if path == FAST else None
            )
            if refusal is not None:
                refused(path, method, "rtol", refusal)
                break
            add(path, method, "rtol", rtol, ode_runner(path, method, model))
    return rows
