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

One module per family of measurements: bench/speed_precision.py (work–precision), speed_scaling.py (durations,
effects, sweeps), speed_startup.py, speed_ros.py, on the runs and rows of speed_runs.py; this module runs them and
makes the tables, the summary and the CSV.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import math
from collections.abc import Callable

from mech_regulator.bench.accuracy import SCENES, BenchScene, environment
from mech_regulator.bench.effect_cost import BASE_SCENE
from mech_regulator.bench.speed_precision import TARGET_ERROR, at_target, measure_precision, ratios
from mech_regulator.bench.speed_ros import measure_ros, ros_summary, ros_target
from mech_regulator.bench.speed_runs import BENCH_SCENE, FAST, Row, SpeedBenchmark
from mech_regulator.bench.speed_scaling import SCALING_RTOL, measure_durations, measure_effects, measure_sweeps
from mech_regulator.bench.speed_startup import measure_startup
from mech_regulator.scene import SceneError

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
TARGETS = {"fast : solve_ivp": 30.0, "fast : MuJoCo": 100.0, "ROS real-time factor": 10.0}


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
    "SPEED_SCENES",
    "TARGETS",
    "run_speed_benchmark",
    "select_speed_scenes",
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
