"""What speed costs (`mech-regulator bench speed`): four ways of simulating the same machine, side by side at
equal achieved accuracy, and how their cost grows.

Paths compared on each speed scene (SPEED_SCENES):

- fast: the compiled path (scene key solver.path: fast), RK45 and DOP853;
- reference: our reference path, `solvers.simulate` with DOP853 (restarts at breakpoints, guards, events);
- solve_ivp: scipy's solve_ivp on the model's plain-Python right-hand side `model.rhs(...)`, RK45 and DOP853,
  no events (so only scenes without a governor, drive train, external-load changes or moments that jump in phi);
- MuJoCo: the crank–slider as a multibody model with a closed loop (bench.mujoco_model), RK4 at fixed timesteps
  stepped natively by mujoco.rollout (only crank_slider_bench: the machine MuJoCo can express natively).

Each path's accuracy setting is swept (rtol, atol = rtol x the scene's state scale; MuJoCo's timestep) and every
run's ACHIEVED error is measured against a reference solution as in `bench accuracy` (DOP853 at rtol 1e-13 on
the reference path; the closed form for `startup`): RMS of omega - omega_ref relative to max |omega_ref|
(accuracy.achieved_errors) on a uniform 20 kHz grid (MuJoCo: at its step times). CPU time is time.process_time
of the run alone, the median of repeats. The CPU time at TARGET_ERROR is interpolated log-log along the path's
work–precision front (the runs no cheaper run beats in error), or is the cheapest run's when that one is already
more accurate; the ratios of those times are the speed-ups.

Also measured: the cost against simulated time (fast and reference), against the number of effects
(effect_cost.EFFECT_CHAIN, fast and reference per link; a link the fast path refuses is shown as such), against
the number of scenes in a sweep (analysis.sweep.run_sweep on 1 and 2 processes), the start-up
cost (cold: empty compile caches, and warm, each in a fresh Python process; the package's import time) and,
optionally (ros=True), the lockstep ROS main job on the whole engine_direct for each exchange design (coupling,
step, path) and on the other governed scenes at run's default, with the exchange's error (measure_ros). Numbers
to print, never to assert.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import importlib.util
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from mech_regulator.bench.accuracy import (
    REFERENCE_METHOD,
    REFERENCE_RTOL,
    SCENES,
    BenchScene,
    achieved_errors,
    environment,
    error_scale,
    time_grid,
    timed,
)
from mech_regulator.bench.effect_cost import BASE_SCENE, EFFECT_CHAIN, SCENARIO
from mech_regulator.bench.mujoco_model import MujocoCrankSlider, mujoco_refusal
from mech_regulator.model import MachineModel, build_model
from mech_regulator.scene import SceneError, load_scene
from mech_regulator.solvers import simulate
from mech_regulator.solvers.compiled import fast_path_refusal
from mech_regulator.solvers.cosim import DEFAULT_COUPLING, cosimulate

BENCH_SCENE = "crank_slider_bench"
SPEED_SCENES = (
    BenchScene(
        BENCH_SCENE,
        BENCH_SCENE,
        (),
        ("scenario.duration=0.5",),
        "motor-driven crank-slider from rest, 2 s: the machine MuJoCo also simulates",
        1.0,
        1e-3,
    ),
) + tuple(bench for bench in SCENES if bench.name in ("startup", "compressor"))
# general linkages (docs/linkages.md), solved group by group per right-hand side by mechanisms/linkage/flat.py, the same
# functions on both paths: nine links in four groups, and the shaper's four links in two (RPR, RRP)
LINKAGE_SCENE = BenchScene(
    "walking_beam_linkage",
    "walking_beam_linkage",
    ("scenario.duration=0.5",),
    ("scenario.duration=0.1",),
    "source 004's walking beam as a general linkage, 0.5 s",
    1.0,
    1e-3,
)
SHAPER_SCENE = BenchScene(
    "shaper",
    "shaper",
    ("scenario.duration=0.5",),
    ("scenario.duration=0.1",),
    "the shaper, a general linkage (slotted lever, RPR + RRP) with a cutting table, 0.5 s",
    1.0,
    1e-3,
)
SPEED_SCENES += (LINKAGE_SCENE, SHAPER_SCENE)
DEFAULT_SCENES = (BENCH_SCENE, "startup", LINKAGE_SCENE.name)  # the shaper by --scenes shaper
TARGET_ERROR = 1e-6  # common achieved error of the comparison (omega RMS, relative) [-]
TARGETS = {"fast : solve_ivp": 30.0, "fast : MuJoCo": 100.0, "ROS real-time factor": 10.0}
FAST, REFERENCE, SOLVE_IVP, MUJOCO = "fast", "reference", "solve_ivp", "MuJoCo"
PATHS = (
    (FAST, "RK45"),
    (FAST, "DOP853"),
    (REFERENCE, "DOP853"),
    (SOLVE_IVP, "RK45"),
    (SOLVE_IVP, "DOP853"),
    (MUJOCO, "RK4"),
)
TOLERANCES, QUICK_TOLERANCES = tuple(10.0**-k for k in range(4, 12)), (1e-5, 1e-7, 1e-9)
MUJOCO_STEPS = (4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4, 6.25e-5)  # [s]
QUICK_MUJOCO_STEPS = (1e-3, 5e-4, 2.5e-4)
DURATIONS, QUICK_DURATIONS = (1.0, 2.0, 4.0, 8.0, 16.0), (0.25, 0.5)  # simulated time [s]
SCALING_RTOL = 1e-9  # rtol of the cost-vs-duration and cost-vs-sweep runs
SWEEP_SIZES, QUICK_SWEEP_SIZES = (1, 2, 4, 8, 16), (1, 2)
SWEEP_JOBS = (1, 2)
REPEAT_BUDGET_S, MAX_REPEATS = 0.3, 7  # a run is repeated to about this much CPU time [s], at most this often
MAX_ERROR_SAMPLES = 40_001  # MuJoCo's step times are thinned to at most this many for the error
ROS_SCENE = "engine_direct"  # the whole scene (16 s), as `run` plays it
ROS_RUNS = (
    (REFERENCE, 1e-3, "hold"),
    (FAST, 1e-3, "hold"),
    (FAST, 2e-3, "waveform"),
    (FAST, 1e-2, "waveform"),
    (FAST, 1e-2, "corrected"),
    (FAST, 2e-2, "corrected"),
    (FAST, 4e-2, "corrected"),
)  # (path, exchange
# step [s], coupling: solvers.cosim); run's default (solvers.cosim.DEFAULT_EXCHANGE_STEP, DEFAULT_COUPLING) among them
ROS_OTHER_SCENES = ("engine_indirect_rigid", "engine_indirect_isodromic", "engine_indirect_none")  # the other
# governed bundled scenes, at run's default only
STARTUP_PROGRAM = """
import time
start = time.perf_counter()
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene
from mech_regulator.solvers import simulate
imported = time.perf_counter()
trajectory = simulate(build_model(load_scene({scene!r}, {overrides!r})))
print(imported - start, time.perf_counter() - start, trajectory.status)
"""


def _solver_overrides(path: str, method: str, rtol: float, state_scale: float) -> list[str]:
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


# ---------------------------------------------------------------------------------------------
# Measuring


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
                    quick, tuple(_solver_overrides(REFERENCE, REFERENCE_METHOD, REFERENCE_RTOL, bench.state_scale))
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
            model = build_model(bench.load(quick, tuple(_solver_overrides(path, method, rtol, bench.state_scale))))
            refusal = (
                solve_ivp_refusal(model) if path == SOLVE_IVP else fast_path_refusal(model) if path == FAST else None
            )
            if refusal is not None:
                refused(path, method, "rtol", refusal)
                break
            add(path, method, "rtol", rtol, ode_runner(path, method, model))
    return rows


def measure_durations(quick: bool, report: Callable[[Row], None]) -> list[Row]:
    """CPU time of crank_slider_bench over growing simulated times, fast and reference path, DOP853 at
    SCALING_RTOL."""
    rows = []
    for duration in QUICK_DURATIONS if quick else DURATIONS:
        for path in (FAST, REFERENCE):
            model = build_model(
                load_scene(
                    BENCH_SCENE,
                    [f"scenario.duration={duration!r}", *_solver_overrides(path, "DOP853", SCALING_RTOL, 1.0)],
                )
            )
            outcome, cpu, _repeats = median_cpu(ode_runner(path, "DOP853", model), quick)
            rows.append(
                Row(
                    "duration",
                    BENCH_SCENE,
                    path,
                    "DOP853",
                    "duration",
                    duration,
                    duration,
                    cpu,
                    outcome.nfev,
                    outcome.steps,
                    note="" if outcome.status == "complete" else outcome.status,
                )
            )
            report(rows[-1])
    return rows


def measure_effects(quick: bool, report: Callable[[Row], None]) -> list[Row]:
    """CPU time per simulated second of each link of effect_cost.EFFECT_CHAIN (its scenario: DOP853, rtol
    1e-8), reference and fast path; --quick: the first three links only."""
    rows = []
    for step in EFFECT_CHAIN[:3] if quick else EFFECT_CHAIN:
        for path in (FAST, REFERENCE):
            overrides = [*SCENARIO, *step.overrides] + (["solver.path=fast"] if path == FAST else [])
            row = Row("effects", BASE_SCENE, path, "DOP853", step.label, math.nan, math.nan)
            model = build_model(load_scene(BASE_SCENE, overrides))
            row.simulated_s = model.scene.scenario.duration
            refusal = fast_path_refusal(model) if path == FAST else None
            if refusal is not None:
                row.note = f"refused: {refusal}"
            else:
                outcome, row.cpu_s, _repeats = median_cpu(ode_runner(path, "DOP853", model), quick)
                row.nfev, row.steps = outcome.nfev, outcome.steps
                row.note = "" if outcome.status == "complete" else outcome.status
            rows.append(row)
            report(row)
    return rows


def measure_sweeps(quick: bool, report: Callable[[Row], None]) -> list[Row]:
    """Wall time of analysis.sweep.run_sweep over 1, 2, 4, 8, 16 variants of crank_slider_bench (its flywheel's
    inertia from 0.2 to 0.4 kg m^2; DOP853 at SCALING_RTOL) on 1 and 2 local processes, reference and fast path."""
    from mech_regulator.analysis.sweep import parse_grid, run_sweep, sweep_points

    rows = []
    for size in QUICK_SWEEP_SIZES if quick else SWEEP_SIZES:
        points = sweep_points(
            [BENCH_SCENE],
            _solver_overrides(REFERENCE, "DOP853", SCALING_RTOL, 1.0),
            [parse_grid(f"machine.flywheel.inertia=0.2:0.4:{size}")],
        )
        for path in (FAST, REFERENCE):
            path_points = (
                [
                    dataclasses.replace(point, scene={**point.scene, "solver": {**point.scene["solver"], "path": path}})
                    for point in points
                ]
                if path == FAST
                else points
            )
            for jobs in SWEEP_JOBS:
                start = time.perf_counter()
                results = run_sweep(path_points, jobs=jobs)
                failed = [result["message"] for result in results if result["status"] != "complete"]
                rows.append(
                    Row(
                        "sweep",
                        BENCH_SCENE,
                        path,
                        "DOP853",
                        f"{jobs} process(es)",
                        size,
                        size * 2.0,
                        time.perf_counter() - start,
                        note=failed[0] if failed else "",
                    )
                )
                report(rows[-1])
    return rows


def _python_wall(program: str, env: dict[str, str]) -> tuple[list[str], float]:
    """Run a Python program in a fresh interpreter: (its printed words, wall time [s] of the whole process)."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, env=env, check=False)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"start-up measurement failed: {done.stderr.strip().splitlines()[-1:]}")
    return done.stdout.split(), wall


def measure_startup(quick: bool, report: Callable[[Row], None]) -> list[Row]:
    """Time to the first result of crank_slider_bench (import + build + first run, wall time inside a fresh
    Python process) and the package's import time: reference path, and fast path cold (empty compile caches
    MECH_REGULATOR_CACHE and NUMBA_CACHE_DIR) then warm (the caches the cold run filled). quick: the fast path warm
    only, on this process's caches (where measure_durations compiled its DOP853 stepper), not the cold compile
    of some 50 s (solvers/compiled/warm.py)."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="mech-regulator-cache-") as cache:
        env = dict(os.environ) if quick else dict(os.environ, MECH_REGULATOR_CACHE=cache, NUMBA_CACHE_DIR=cache)
        cold = [] if quick else [(FAST, "cold", ["solver.path=fast"])]
        runs = [(REFERENCE, "warm", []), *cold, (FAST, "warm", ["solver.path=fast"])]
        for path, phase, overrides in runs:
            (imported, first, status), wall = _python_wall(
                STARTUP_PROGRAM.format(scene=BENCH_SCENE, overrides=overrides), env
            )
            rows.append(
                Row(
                    "startup",
                    BENCH_SCENE,
                    path,
                    "DOP853",
                    phase,
                    float(imported),
                    2.0,
                    float(first),
                    note=f"import {float(imported):.3g} s, process {wall:.3g} s, run {status}",
                )
            )
            report(rows[-1])
    return rows


@functools.cache
def default_exchange_step(scene: str) -> float:
    """run's exchange step for a bundled scene [s]: its solver.exchange_step (solvers.cosim.DEFAULT_EXCHANGE_STEP
    unless the scene sets another)."""
    return load_scene(scene).solver.exchange_step


def failure_text(stderr: str) -> str:
    """What a failed `mech-regulator run` says of its failure, in one line: the launcher's lines naming the nodes that
    ended and how, and a fatal error's first line from the nodes' log it prints (a crash's traceback ends in the list
    of extension modules, which says nothing); else its last line."""
    lines = stderr.strip().splitlines()
    telling = [
        line.strip()
        for line in lines
        if line.startswith("mech-regulator: the ") or line.startswith("Fatal Python error")
    ]
    return "; ".join(telling) or (lines or [""])[-1]


def measure_ros(report: Callable[[Row], None]) -> list[Row]:
    """The lockstep ROS main job (`mech-regulator run`, four node processes) on the whole engine_direct, for each
    (path, exchange step, coupling) of ROS_RUNS, and on each of ROS_OTHER_SCENES at run's default (method 'nodes',
    setting the coupling): the wall time of the exchanges as the recorder measured it (from the first machine state
    to the last; the run's summary), the process's wall time with the nodes' start-up in the note; and the same
    co-simulation in this process (solvers.cosim.cosimulate, number for number what the nodes compute; method 'in
    process'): its CPU time and its achieved error, omega's largest difference from the monolithic run at
    REFERENCE_RTOL (fast path) at the exchange times, relative to max |omega| (the issue's bound is on it; the nodes'
    is the same), with the RMS difference in the note."""
    runs = [(ROS_SCENE, *run) for run in ROS_RUNS]
    runs += [(scene, FAST, default_exchange_step(scene), DEFAULT_COUPLING) for scene in ROS_OTHER_SCENES]
    rows, exact = [], {}
    with tempfile.TemporaryDirectory(prefix="mech-regulator-ros-") as folder:
        for scene, path, exchange, coupling in runs:
            settings = ["solver.path=fast"] if path == FAST else ["solver.path=reference"]
            output = os.path.join(folder, f"{scene}{path}{exchange:g}{coupling}.rrd")
            command = [
                sys.executable,
                "-m",
                "mech_regulator",
                "run",
                scene,
                "--quiet",
                "--exchange-step",
                repr(exchange),
                "--coupling",
                coupling,
                "--out",
                output,
            ] + [item for setting in settings for item in ("--set", setting)]
            start = time.perf_counter()
            done = subprocess.run(command, capture_output=True, text=True, check=False)
            process_wall = time.perf_counter() - start
            model = build_model(load_scene(scene, settings))
            duration = model.scene.scenario.duration
            default = (
                " (run's default)"
                if (path, exchange, coupling) == (FAST, default_exchange_step(scene), DEFAULT_COUPLING)
                else ""
            )
            row = Row(
                "ros",
                scene,
                path,
                "nodes",
                coupling,
                exchange,
                duration,
                steps=round(duration / exchange),
                note=f"process {process_wall:.3g} s with start-up{default}",
            )
            summary_path = Path(output).with_suffix(".json")
            pace = json.loads(summary_path.read_text()) if summary_path.exists() else {}
            if done.returncode != 0 or "wall_time_s" not in pace:
                row.note = f"exit {done.returncode}: {failure_text(done.stderr)}"
            else:
                row.cpu_s, row.simulated_s = pace["wall_time_s"], pace["t_end"]
            rows.append(row)
            report(row)
            run, cpu = timed(lambda: cosimulate(model, exchange, coupling=coupling))
            if scene not in exact:
                exact[scene] = simulate(
                    build_model(
                        load_scene(
                            scene,
                            [
                                "solver.path=fast",
                                f"solver.rtol={REFERENCE_RTOL!r}",
                                f"solver.atol={REFERENCE_RTOL * 1e2!r}",
                            ],
                        )
                    )
                )
            reference = exact[scene](run.times)[1]
            scale = np.max(np.abs(reference))
            largest = float(np.max(np.abs(run.states[1] - reference)) / scale)
            rms = float(np.sqrt(np.mean((run.states[1] - reference) ** 2)) / scale)
            rows.append(
                Row(
                    "ros",
                    scene,
                    path,
                    "in process",
                    coupling,
                    exchange,
                    duration,
                    cpu,
                    steps=run.times.size - 1,
                    error=largest,
                    note=f"RMS error {rms:.2g}{default}",
                )
            )
            report(rows[-1])
    return rows


def ros_summary(benchmark: SpeedBenchmark) -> list[dict[str, float | str]]:
    """Per (path, exchange step) of the ROS rows: the nodes' real-time factor over their exchanges (start-up
    excluded; missing when the run failed) and the in-process co-simulation's real-time factor (CPU) and achieved
    error."""
    found = []
    for scene, path, exchange, coupling in dict.fromkeys(
        (row.scene, row.path, row.value, row.setting) for row in benchmark.of("ros")
    ):
        item: dict[str, float | str] = {"scene": scene, "path": path, "exchange_step_s": exchange, "coupling": coupling}
        for row in benchmark.of("ros", scene=scene, path=path, value=exchange, setting=coupling):
            if row.method == "nodes" and math.isfinite(row.cpu_s):
                item["real_time_factor"] = row.simulated_s / row.cpu_s
            elif row.method == "in process":
                item.update(in_process_real_time_factor=row.simulated_s / row.cpu_s, max_error=row.error)
        item["default"] = (path, exchange, coupling) == (FAST, default_exchange_step(scene), DEFAULT_COUPLING)
        found.append(item)
    return found


def ros_target(benchmark: SpeedBenchmark) -> float:
    """The ROS target's measure: the lockstep nodes' real-time factor on the whole engine_direct at run's defaults
    (nan when not measured)."""
    for item in ros_summary(benchmark):
        if item["scene"] == ROS_SCENE and item.get("default"):
            return float(item.get("real_time_factor", math.nan))
    return math.nan


def run_speed_benchmark(
    scenes: list[BenchScene],
    quick: bool = False,
    ros: bool = False,
    report: Callable[[Row], None] = print,
    mujoco: bool = True,
) -> SpeedBenchmark:
    """Measure everything (see the module docstring; MuJoCo's path only when `mujoco`); report(row) is called as
    each row is measured. Ctrl-C returns what was measured, with `interrupted` set."""
    benchmark = SpeedBenchmark(quick=quick, environment=environment(1))

    def keep(row: Row) -> None:
        benchmark.rows.append(row)
        report(row)

    parts: list[Callable[[], list[Row]]] = [
        functools.partial(measure_precision, bench, quick, keep, mujoco) for bench in scenes
    ]
    parts += [
        functools.partial(measure_durations, quick, keep),
        functools.partial(measure_effects, quick, keep),
        functools.partial(measure_sweeps, quick, keep),
        functools.partial(measure_startup, quick, keep),
    ]
    if ros:
        parts.append(functools.partial(measure_ros, keep))
    try:
        for part in parts:
            part()
    except KeyboardInterrupt:
        benchmark.interrupted = True
    return benchmark


def select_speed_scenes(names: list[str] | None) -> list[BenchScene]:
    """The speed scenes named (DEFAULT_SCENES if None); an unknown one is a SceneError naming the choices."""
    by_name = {bench.name: bench for bench in SPEED_SCENES}
    names = list(DEFAULT_SCENES) if names is None else names
    unknown = [name for name in names if name not in by_name]
    if unknown:
        raise SceneError(f"--scenes: no speed scene '{unknown[0]}'; choose from {', '.join(by_name)}")
    return [by_name[name] for name in dict.fromkeys(names)]


__all__ = [
    "FAST",
    "MUJOCO",
    "PATHS",
    "REFERENCE",
    "SOLVE_IVP",
    "SPEED_SCENES",
    "TARGETS",
    "TARGET_ERROR",
    "PathAtTarget",
    "Row",
    "SpeedBenchmark",
    "at_error",
    "at_target",
    "ratios",
    "ros_summary",
    "ros_target",
    "run_speed_benchmark",
    "select_speed_scenes",
    "work_precision_front",
]


# ---------------------------------------------------------------------------------------------
# What was found: summary, tables, CSV


def _scene_duration(benchmark: SpeedBenchmark, scene: str) -> float:
    return next(row.simulated_s for row in benchmark.of("precision", scene=scene))


def targets(benchmark: SpeedBenchmark) -> list[dict]:
    """The issue's targets with the measured values on crank_slider_bench (and the ROS run) and 'met', 'missed'
    or 'not measured'."""
    found = {}
    if benchmark.of("precision", scene=BENCH_SCENE):
        found = ratios(at_target(benchmark, BENCH_SCENE, _scene_duration(benchmark, BENCH_SCENE)))
    found["ROS real-time factor"] = ros_target(benchmark)
    rows = []
    for name, wanted in TARGETS.items():
        measured = found.get(name, math.nan)
        status = "not measured" if not math.isfinite(measured) else "met" if measured >= wanted else "missed"
        rows.append({"target": name, "at_least": wanted, "measured": measured, "status": status})
    return rows


def summary(benchmark: SpeedBenchmark) -> dict:
    """Everything the benchmark found, for speed.json: per scene each path at TARGET_ERROR and the ratios, the
    targets, the start-up and ROS numbers, the environment."""
    scenes = {}
    for scene in dict.fromkeys(row.scene for row in benchmark.of("precision")):
        results = at_target(benchmark, scene, _scene_duration(benchmark, scene))
        scenes[scene] = {"at_target": [vars(result) for result in results], "ratios": ratios(results)}
    startup = {
        f"{row.path} {row.setting}": {"first_result_s": row.cpu_s, "import_s": row.value}
        for row in benchmark.of("startup")
    }
    return {
        "target_error": TARGET_ERROR,
        "quick": benchmark.quick,
        "interrupted": benchmark.interrupted,
        "environment": benchmark.environment,
        "scenes": scenes,
        "targets": targets(benchmark),
        "startup": startup,
        "ros": ros_summary(benchmark),
    }


def _number(value: float, digits: int = 3) -> str:
    return "-" if not math.isfinite(value) else f"{value:.{digits}g}"


def tables(benchmark: SpeedBenchmark) -> str:
    """The findings as markdown tables: each path at TARGET_ERROR per scene, the targets, cost against
    simulated time, against the effects, against the sweep's size, start-up and ROS."""
    lines = []
    for scene, found in summary(benchmark)["scenes"].items():
        best_fast = min((item["cpu_s"] for item in found["at_target"] if item["path"] == FAST), default=math.nan)
        lines += [
            "",
            f"{scene}: at achieved error {TARGET_ERROR:g} (omega RMS, relative)",
            "",
            "| path | method | CPU [ms] | RHS evaluations / CPU s | real-time factor | x fast |",
            "| --- | --- | ---: | ---: | ---: | ---: |",
        ]
        lines += [
            f"| {item['path']} | {item['method']} | {_number(item['cpu_s'] * 1e3)} | "
            f"{_number(item['rhs_per_s'])} | {_number(item['real_time_factor'])} | "
            f"{_number(item['cpu_s'] / best_fast)} |"
            for item in found["at_target"]
        ]
        notes = {row.note for row in benchmark.of("precision", scene=scene) if row.note}
        lines += [f"- {note}" for note in sorted(notes)]
    lines += [
        "",
        f"targets (on {BENCH_SCENE}; a report, not a test)",
        "",
        "| target | at least | measured | |",
        "| --- | ---: | ---: | --- |",
    ]
    lines += [
        f"| {item['target']} | {item['at_least']:g} | {_number(item['measured'])} | {item['status']} |"
        for item in targets(benchmark)
    ]
    lines += [
        "",
        f"cost against simulated time ({BENCH_SCENE}, DOP853, rtol {SCALING_RTOL:g})",
        "",
        "| simulated [s] | path | CPU [s] | CPU / simulated s | RHS evaluations |",
        "| ---: | --- | ---: | ---: | ---: |",
    ]
    lines += [
        f"| {row.value:g} | {row.path} | {_number(row.cpu_s)} | {_number(row.cpu_s / row.value)} | "
        f"{_number(row.nfev, 6)} |"
        for row in benchmark.of("duration")
    ]
    lines += [
        "",
        f"cost against the effects ({BASE_SCENE} built up one effect at a time, DOP853, rtol 1e-8)",
        "",
        "| effects | path | CPU / simulated s | note |",
        "| --- | --- | ---: | --- |",
    ]
    lines += [
        f"| {row.setting} | {row.path} | {_number(row.cpu_s / row.simulated_s)} | {row.note} |"
        for row in benchmark.of("effects")
    ]
    lines += [
        "",
        "cost against the number of scenes in a sweep (wall time)",
        "",
        "| path | points | processes | wall [s] | note |",
        "| --- | ---: | --- | ---: | --- |",
    ]
    lines += [
        f"| {row.path} | {_number(row.value)} | {row.setting} | {_number(row.cpu_s)} | {row.note} |"
        for row in benchmark.of("sweep")
    ]
    lines += [
        "",
        f"start-up: a fresh Python process to the first result of {BENCH_SCENE} (wall time)",
        "",
        "| path | caches | import [s] | first result [s] | note |",
        "| --- | --- | ---: | ---: | --- |",
    ]
    lines += [
        f"| {row.path} | {row.setting} | {_number(row.value)} | {_number(row.cpu_s)} | {row.note} |"
        for row in benchmark.of("startup")
    ]
    if benchmark.of("ros"):
        lines += [
            "",
            "lockstep ROS main job (four node processes: wall time of the exchanges, start-up excluded) "
            "and the same co-simulation in one process (CPU time); omega's error against the monolithic run "
            "(max, relative to max |omega|; the nodes' numbers are the in-process ones)",
            "",
            "| scene | path | coupling | exchange step [ms] | simulated [s] | how | time [s] | real-time factor "
            "| omega error (max) | note |",
            "| --- | --- | --- | ---: | ---: | --- | ---: | ---: | ---: | --- |",
        ]
        lines += [
            f"| {row.scene} | {row.path} | {row.setting} | {row.value * 1e3:g} | {row.simulated_s:g} | "
            f"{row.method} | {_number(row.cpu_s)} | {_number(row.simulated_s / row.cpu_s)} | "
            f"{_number(row.error)} | {row.note} |"
            for row in benchmark.of("ros")
        ]
    return "\n".join(lines) + "\n"


def row_line(row: Row) -> str:
    """One measured row as a progress line."""
    what = f"{row.section:<9} {row.scene:<20} {row.path:<12} {row.method:<7} {row.setting} {_number(row.value)}"
    if row.note and not math.isfinite(row.cpu_s):
        return f"{what}: {row.note}"
    error = f"  error {row.error:.3g}" if math.isfinite(row.error) else ""
    return f"{what}: {row.cpu_s:.4g} s{error}"


def write_rows_csv(benchmark: SpeedBenchmark, path) -> None:
    """Every row as CSV, the Row fields as columns (empty where not measured)."""
    names = [item.name for item in dataclasses.fields(Row)]
    with open(path, "w", newline="", encoding="utf-8") as stream:
        writer = csv.DictWriter(stream, fieldnames=names)
        writer.writeheader()
        for row in benchmark.rows:
            writer.writerow(
                {
                    name: "" if isinstance(value, float) and not math.isfinite(value) else value
                    for name, value in vars(row).items()
                }
            )
