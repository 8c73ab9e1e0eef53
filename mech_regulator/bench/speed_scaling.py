"""How the speed benchmark's cost grows (bench/speed.py): against simulated time, against the number of effects
(effect_cost.EFFECT_CHAIN) and against the number of scenes in a sweep (analysis.sweep.run_sweep on 1 and 2
processes), fast and reference path."""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

from mech_regulator.bench.effect_cost import BASE_SCENE, EFFECT_CHAIN, SCENARIO
from mech_regulator.bench.speed_runs import BENCH_SCENE, FAST, REFERENCE, Row, median_cpu, ode_runner, solver_overrides
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene
from mech_regulator.solvers.compiled import fast_path_refusal

DURATIONS, QUICK_DURATIONS = (1.0, 2.0, 4.0, 8.0, 16.0), (0.25, 0.5)  # simulated time [s]
SCALING_RTOL = 1e-9  # rtol of the cost-vs-duration and cost-vs-sweep runs
SWEEP_SIZES, QUICK_SWEEP_SIZES = (1, 2, 4, 8, 16), (1, 2)
SWEEP_JOBS = (1, 2)


def measure_durations(quick: bool, report: Callable[[Row], None]) -> list[Row]:
    """CPU time of crank_slider_bench over growing simulated times, fast and reference path, DOP853 at
    SCALING_RTOL."""
    rows = []
    for duration in QUICK_DURATIONS if quick else DURATIONS:
        for path in (FAST, REFERENCE):
            model = build_model(
                load_scene(
                    BENCH_SCENE,
                    [f"scenario.duration={duration!r}", *solver_overrides(path, "DOP853", SCALING_RTOL, 1.0)],
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
            solver_overrides(REFERENCE, "DOP853", SCALING_RTOL, 1.0),
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
