"""`mech-regulator bench long`: the long-run matrix, bundled scenes x paths x methods through simulate and the
in-process co-simulation for a long simulated time (bench.long), printed as a Markdown table row by row. Light to
import (the parser is built from it): the benchmark loads inside run_bench_long.
"""

from __future__ import annotations

import argparse
import math
import sys

from mech_regulator.errors import EXIT_INTERRUPTED

LONG_DURATION = 1000.0  # [s] of simulated time of each row by default
ROW_BUDGET = 3600.0  # [s] of wall time a row may take by default before it is stopped
ROW_KEYS = {"solver.path": "--paths", "solver.method": "--methods", "scenario.duration": "--duration"}
"""The scene keys each row sets itself, and the option that chooses them (a `--set` of them is refused)."""


def add_bench_long_command(benchmarks) -> None:
    """The `bench long` subcommand and its options, under `bench`'s subparsers."""
    long = benchmarks.add_parser(
        "long",
        help="long-run matrix: bundled scenes x paths x methods, through simulate and the co-simulation, "
        "for a long simulated time",
        description="Run every bundled scene (or those given) on each path with each method, through simulate "
        "(streamed, as the simulate command runs it) and through the in-process co-simulation (exchange "
        "step 0.02 s), for a long simulated time, its scene changed by the --set options, and "
        "print a Markdown row per run: how it ended (complete, failed, refused before the start, or "
        "stopped when its wall-time budget ran out), wall time, steps (exchanges), the energy balance's "
        "relative residual and the last dynamic period's omega_m and delta against the scene's own "
        "duration. Numbers to read, never asserted.",
    )
    long.add_argument(
        "--duration",
        type=float,
        default=LONG_DURATION,
        metavar="T",
        help=f"simulated time of each row [s] (default {LONG_DURATION:g})",
    )
    long.add_argument("--scenes", help="comma-separated bundled scenes (default: every one)")
    long.add_argument("--paths", help="comma-separated paths: fast, reference (default both)")
    long.add_argument(
        "--methods",
        help="comma-separated methods (default DOP853,RK45,RK4,Radau,energy; the fast path "
        "runs no Radau nor energy method)",
    )
    long.add_argument("--modes", help="comma-separated: simulate, cosim (default both)")
    long.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="change a scene value in every row, as `simulate --set` (repeatable), e.g. "
        "--set solver.sample_rate=2000; the rows set solver.path, solver.method and scenario.duration",
    )
    long.add_argument(
        "--budget",
        type=float,
        default=ROW_BUDGET,
        metavar="S",
        help=f"wall time a row may take before it is stopped [s] (default {ROW_BUDGET:g})",
    )


def run_bench_long(args: argparse.Namespace) -> int:
    """bench long: the rows asked for, each printed as it ends, each row's progress on stderr as it runs (a bar on a
    terminal, a line every few seconds in a log: report.terminal.progress_bar); 130 when interrupted (the rows so far
    printed)."""
    from mech_regulator.bench.long import METHODS, MODES, PATHS, format_header, format_row, matrix, run_row
    from mech_regulator.cli.report.terminal import progress_bar
    from mech_regulator.scene import SceneError, bundled_scenes
    from mech_regulator.scene.limits import MAX_DURATION

    if not 0.0 < args.duration <= MAX_DURATION:
        raise SceneError(f"--duration {args.duration:g}: expected a simulated time in (0, {MAX_DURATION:g}] s")
    if not (math.isfinite(args.budget) and args.budget > 0.0):
        raise SceneError(f"--budget {args.budget:g}: expected a wall time > 0 s")
    chosen = {}
    for option, text, allowed in (
        ("--scenes", args.scenes, list(bundled_scenes())),
        ("--paths", args.paths, PATHS),
        ("--methods", args.methods, METHODS),
        ("--modes", args.modes, MODES),
    ):
        names = [name.strip() for name in text.split(",") if name.strip()] if text else list(allowed)
        unknown = [name for name in names if name not in allowed]
        if unknown or not names:
            raise SceneError(f"{option} {text!r}: {', '.join(unknown) or 'nothing'} is not one of {', '.join(allowed)}")
        chosen[option] = names
    _check_overrides(args.overrides, chosen["--scenes"])
    rows = matrix(chosen["--scenes"], tuple(chosen["--paths"]), tuple(chosen["--methods"]), tuple(chosen["--modes"]))
    print(format_header(args.duration), flush=True)
    try:
        for row in rows:
            with progress_bar(args.duration, False, " ".join(row)) as bar:
                result = run_row(
                    *row,
                    args.duration,
                    args.budget,
                    tuple(args.overrides),
                    lambda t: bar.update(min(t, args.duration) - bar.n),
                )
            print(format_row(result), flush=True)
    except KeyboardInterrupt:
        print("mech-regulator: interrupted; the rows above are what was measured", file=sys.stderr)
        return EXIT_INTERRUPTED
    return 0


def _check_overrides(overrides: list[str], scenes: list[str]) -> None:
    """Refuse, before any row runs, a `--set` of a key the rows set themselves (ROW_KEYS) and one that does not
    load (SceneError naming it): each scene is loaded with the overrides, as `simulate --set` loads it."""
    from mech_regulator.scene import SceneError, load_scene

    for assignment in overrides:
        key = assignment.split("=", 1)[0].strip()
        if key in ROW_KEYS:
            raise SceneError(f"--set {assignment!r}: each row sets {key}; choose it with {ROW_KEYS[key]}")
    if overrides:
        for scene in scenes:
            load_scene(scene, overrides)
