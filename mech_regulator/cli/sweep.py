"""`mech-regulator sweep`: run a grid of scene values and/or a list of scenes as independent tasks, in this
process, on local worker processes or on a Dask cluster, and write one row per scene (sweep.csv) and a picture
(sweep.png).

A thin layer over analysis.sweep: the grid and the points are validated before anything runs (a bad key or value
exits 2 with a message naming the option), a progress bar counts the simulated seconds of the finished points,
and Ctrl-C writes the rows finished so far.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
import time
from collections.abc import Callable
from pathlib import Path

from mech_regulator.cli.report.terminal import terminal_text
from mech_regulator.errors import EXIT_INTERRUPTED

SHOWN_ROWS = 12  # the printed table shows all rows up to this many, else the first and last half of it
# analysis.sweep's ENGINES and METRICS, repeated here so that building the parser does not import the sweep (numpy,
# the scene schema, the compiled path); test/test_cli_startup.py checks that they stay equal.
ENGINES = ("local", "dask")
METRICS = (
    "delta",
    "omega_m",
    "omega_average",
    "omega_end",
    "oscillation_ratio",
    "stop_arrivals",
    "vyshnegradsky_A",
    "vyshnegradsky_B",
    "t_end",
    "wall_time",
    "rhs_evaluations",
)
DASK_EXTRA = "pip install 'mech_regulator[distributed]'"


def add_sweep_command(scene_command: Callable[..., argparse.ArgumentParser]) -> None:
    """The `sweep` subcommand and its options; scene_command (cli.parser) makes a subcommand with the SCENE and --set
    arguments of every scene command (SCENE optional here: --scenes may name them all)."""
    text = (
        "run many scenes: a grid of scene values (the Cartesian product of the --grid options) and/or a list of "
        "scenes, on both cores or a Dask cluster; writes sweep.csv (one row per scene: final and mean speed, "
        "delta, the governor's stability by simulation and Vyshnegradsky's A and B) and sweep.png"
    )
    parser = scene_command("sweep", text, scene_required=False)
    parser.add_argument(
        "--grid",
        action="append",
        default=[],
        metavar="KEY=SPEC",
        help="a scene key and its values: KEY=START:STOP:N (linear), KEY=START:STOP:N:log "
        "(geometric), KEY=V1,V2,... (a list); the keys of --set, e.g. "
        "--grid governor.damping=10:300:5:log; repeatable (the Cartesian product)",
    )
    parser.add_argument(
        "--scenes",
        nargs="+",
        default=[],
        metavar="SCENE",
        help="more scene files or bundled scene names to run (after SCENE), each with the grid",
    )
    parser.add_argument(
        "--jobs",
        type=int,
        metavar="N",
        help=f"worker processes (default: the number of cores, {os.cpu_count()}; 1: in this process)",
    )
    parser.add_argument(
        "--engine",
        choices=ENGINES,
        default="local",
        help="local: a pool of processes on this machine; dask: the scenes as tasks on a Dask "
        "cluster (pip install 'mech_regulator[distributed]')",
    )
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="with --engine dask: the scheduler of a running cluster, e.g. tcp://10.0.0.5:8786 "
        "(default: a local cluster of --jobs processes)",
    )
    parser.add_argument(
        "--out", type=Path, metavar="DIR", help="folder for sweep.csv and sweep.png (default runs/sweep-<scene>)"
    )
    parser.add_argument(
        "--metric",
        choices=METRICS,
        metavar="NAME",
        help=f"the column the picture draws: {', '.join(METRICS)} (default: oscillation_ratio for "
        "a governed scene, else delta)",
    )
    parser.add_argument(
        "--path",
        choices=("fast", "reference", "scene"),
        default="fast",
        help="fast (default): every scene the compiled fast path runs goes on it, the others on the "
        "reference path (the row's path column says which); reference: all on the reference "
        "path; scene: as each scene's solver.path says",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def warm_fast_path(points, engine: str, quiet: bool) -> None:
    """Compile, here and before any point runs, the fast-path steppers the sweep's points need and this machine has
    not compiled yet, saying so: the local worker processes then load them from the disk cache instead of each
    compiling them. Dask workers on other machines compile for themselves, once each (said too)."""
    methods = sorted(
        {
            point.scene.get("solver", {}).get("method", "DOP853")
            for point in points
            if point.scene.get("solver", {}).get("path") == "fast"
        }
    )
    if not methods:
        return
    from mech_regulator.solvers.compiled.warm import FIRST_COMPILE_ESTIMATE, compile_steppers, stepper_cached

    cold = [method for method in methods if not stepper_cached(method)]
    report = (lambda line: None) if quiet else (lambda line: print(f"mech-regulator: {line}", file=sys.stderr))
    if cold:
        compile_steppers(cold, report)
    if engine == "dask":
        report(
            f"note: Dask workers on other machines compile the fast path's {', '.join(methods)} stepper(s) once "
            f"each (the first {FIRST_COMPILE_ESTIMATE}) before their first point"
        )


def run_sweep_command(args: argparse.Namespace) -> int:
    """Run the command; a user's mistake raises SceneError (exit 2 in cli.main) before any point runs, and so does
    --engine dask without Dask installed (the message names the pip extra)."""
    from mech_regulator.analysis.sweep import check_executor, parse_grid, run_sweep, sweep_points
    from mech_regulator.cli.report.data import write_rows_csv
    from mech_regulator.cli.report.outputs import OutputWriter, check_output_paths, output_folder
    from mech_regulator.cli.report.terminal import progress_bar
    from mech_regulator.scene import SceneError
    from mech_regulator.scene.limits import output_stem
    from mech_regulator.scene.loading import key_description

    if args.engine == "dask" and not dask_installed():
        raise SceneError(f"--engine dask needs Dask distributed: {DASK_EXTRA} (or pip install 'dask[distributed]')")
    scenes = ([args.scene] if args.scene is not None else []) + args.scenes
    axes = [parse_grid(spec) for spec in args.grid]
    points = sweep_points(scenes, args.overrides, axes, args.path)
    jobs = check_executor(args.jobs, args.engine, args.scheduler)
    governed = any(point.scene.get("governor") for point in points)
    metric = args.metric or ("oscillation_ratio" if governed else "delta")
    out = args.out if args.out is not None else Path("runs") / f"sweep-{output_stem(points[0].scene['name'])}"
    check_output_paths(output_folder(out) / "sweep.csv", out / "sweep.png")  # once the points are valid
    warm_fast_path(points, args.engine, args.quiet)
    durations = [float(point.scene["scenario"]["duration"]) for point in points]
    start = time.perf_counter()
    label = f"sweep of {len(points)} point{'s' if len(points) != 1 else ''}"
    with progress_bar(sum(durations), args.quiet, label, quantity=None, unit="s simulated") as bar:
        rows = run_sweep(
            points,
            jobs,
            args.engine,
            args.scheduler,
            progress=lambda point, row: bar.update(float(point.scene["scenario"]["duration"])),
        )
    wall_time = time.perf_counter() - start
    written: dict[str, str] = {}
    outputs = OutputWriter(written)
    outputs.write("csv", out / "sweep.csv", lambda path: write_rows_csv(path, rows))
    print(format_rows(rows, [axis.key for axis in axes]))
    not_run = sum(row["status"] == "not run" for row in rows)
    where = (
        f"on a Dask cluster at {args.scheduler}"
        if args.scheduler
        else (
            f"on a Dask local cluster of {jobs} processes"
            if args.engine == "dask"
            else "in this process"
            if jobs == 1 or len(points) == 1
            else f"on {jobs} local processes"
        )
    )
    print(f"{len(rows) - not_run} of {len(rows)} points in {wall_time:.3g} s {where}")
    if "csv" in written:
        print(terminal_text(f"wrote {written['csv']}"))
    if not_run:
        print(
            terminal_text(
                f"mech-regulator: interrupted; the {len(rows) - not_run} finished points are in {out / 'sweep.csv'}"
            ),
            file=sys.stderr,
        )
        return outputs.exit_code(EXIT_INTERRUPTED)
    from mech_regulator.viz.sweep import plot_sweep

    permitted = points[0].scene.get("analysis", {}).get("permitted_delta")
    names = ", ".join(dict.fromkeys(str(point.scene["name"]) for point in points))
    units = {axis.key: _unit_of(key_description(axis.key, points[0].scene)) for axis in axes}
    try:
        outputs.write(
            "plot",
            out / "sweep.png",
            lambda path: plot_sweep(
                rows,
                axes,
                metric,
                f"sweep of {names}: {len(rows)} points",
                path,
                permitted,
                {key: f"{key} {unit}".strip() for key, unit in units.items()},
            ),
        )
    except KeyboardInterrupt:
        print(
            terminal_text(
                f"mech-regulator: interrupted while drawing the picture; every row is in {out / 'sweep.csv'}"
            ),
            file=sys.stderr,
        )
        return outputs.exit_code(EXIT_INTERRUPTED)
    if "plot" in written:
        print(terminal_text(f"wrote {written['plot']}"))
    failed = [row for row in rows if row["status"] != "complete"]
    for row in failed[:5]:
        print(
            terminal_text(
                f"mech-regulator: point {_label(row, [axis.key for axis in axes])}: {row['status']}: {row['message']}"
            ),
            file=sys.stderr,
        )
    return outputs.exit_code(0)


def dask_installed() -> bool:
    """Whether dask.distributed can be imported (its spec found; only the dask package itself is imported)."""
    import importlib.util

    try:
        return importlib.util.find_spec("dask.distributed") is not None
    except (ImportError, ValueError):  # dask itself missing, or a module without a spec
        return False


def _unit_of(description: str) -> str:
    """The unit that ends a key's description, brackets and all ("[rad/s]"), or "" without one."""
    unit = re.search(r"\[[^\]]*\]$", description)
    return unit.group(0) if unit else ""


def _label(row: dict, keys: list[str]) -> str:
    return " ".join([str(row["scene"])] + [f"{key}={_text(row[key])}" for key in keys])


def _text(value) -> str:
    if isinstance(value, bool) or value is None:
        return "-" if value is None else ("yes" if value else "no")
    if isinstance(value, float):
        return f"{value:.6g}" if math.isfinite(value) else str(value)
    return str(value)


def format_rows(rows: list[dict], keys: list[str]) -> str:
    """A short table of the rows: the scene, the grid values, status, omega_end, delta and, for governed scenes,
    the stability by simulation and by the linear model with A and B; the first and last rows of a long sweep."""
    columns = ["scene", *keys, "status", "omega_end", "delta"]
    if any(row.get("stable_by_simulation") is not None for row in rows):
        columns += ["stable_by_simulation", "oscillation_ratio", "stable_linear", "vyshnegradsky_A", "vyshnegradsky_B"]
    shown: list[dict | None] = (
        [*rows] if len(rows) <= SHOWN_ROWS else [*rows[: SHOWN_ROWS // 2], None, *rows[-SHOWN_ROWS // 2 :]]
    )
    table = [[name.split(".")[-1] if name in keys else name.replace("vyshnegradsky_", "") for name in columns]]
    table += [
        ["..."] + [""] * (len(columns) - 1) if row is None else [terminal_text(_text(row[name])) for name in columns]
        for row in shown
    ]
    widths = [max(len(line[i]) for line in table) for i in range(len(columns))]
    return "\n".join("  ".join(cell.rjust(width) for cell, width in zip(line, widths)) for line in table)
