"""`mech-regulator bench speed`: the four paths side by side at equal achieved accuracy, how cost grows, the
start-up cost and (--ros) the lockstep ROS run. A thin layer over bench.speed: it prints each measurement as it
comes, then the tables with the targets, and writes speed.csv (also when interrupted), speed.json and speed.png.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from mech_regulator.cli.report import bench_scenes_and_folder, to_json

from mech_regulator.cli import EXIT_INTERRUPTED


def add_bench_speed_command(benchmarks) -> None:
    """The `bench speed` subcommand and its options, under `bench`'s subparsers."""
    speed = benchmarks.add_parser(
        "speed", help="speed benchmark: fast path, reference path, solve_ivp and MuJoCo at equal achieved accuracy",
        description="Measure, side by side at equal achieved accuracy (omega RMS error 1e-6, relative), the fast "
                    "compiled path, the reference path, scipy's solve_ivp on the plain-Python right-hand side and "
                    "MuJoCo simulating the crank-slider as a multibody model with a closed loop: CPU time, ratios, "
                    "RHS evaluations per second, real-time factor; then the cost against simulated time, the number "
                    "of effects and the number of scenes in a sweep, and the start-up cost. Writes speed.csv, "
                    "speed.json and speed.png; Ctrl-C keeps what was measured in speed.csv. Speeds are reported, "
                    "never asserted.")
    speed.add_argument("--quick", action="store_true", help="few points and short runs (a check of the command end "
                                                            "to end, well under a minute; not a measurement)")
    speed.add_argument("--scenes", metavar="NAME[,NAME...]",
                       help="speed scenes to run, comma-separated (default: crank_slider_bench,startup; a wrong name "
                            "lists them)")
    speed.add_argument("--out", type=Path, default=Path("docs/speed"), metavar="FOLDER",
                       help="folder for the outputs (default docs/speed)")
    speed.add_argument("--ros", action="store_true",
                       help="also time the lockstep ROS main job, reference and fast path at a 1 ms exchange step and "
                            "the fast path at 2, 5 and 10 ms, with each exchange step's error (needs rclpy; about "
                            "3 minutes)")


def run_bench_speed(args: argparse.Namespace) -> int:
    """bench speed: measure, print, then write speed.csv (also when interrupted), speed.json and speed.png."""
    from mech_regulator.bench.speed import (row_line, run_speed_benchmark, select_speed_scenes, summary, tables,
                                            write_rows_csv)

    scenes = select_speed_scenes(bench_scenes_and_folder(args.scenes, args.out, "crank_slider_bench,startup"))
    start = time.monotonic()
    benchmark = run_speed_benchmark(scenes, args.quick, args.ros, report=lambda row: print(row_line(row), flush=True))
    write_rows_csv(benchmark, args.out / "speed.csv")
    (args.out / "speed.json").write_text(to_json(summary(benchmark)) + "\n", encoding="utf-8")
    print(tables(benchmark))
    if benchmark.interrupted:
        print(f"mech-regulator: interrupted; what was measured is in {args.out / 'speed.csv'} and speed.json",
              file=sys.stderr)
        return EXIT_INTERRUPTED
    from mech_regulator.viz.speed import plot_speed

    plot_speed(benchmark, args.out / "speed.png")
    print(f"wrote {args.out}: speed.csv, speed.json, speed.png ({time.monotonic() - start:.0f} s)")
    return 0

