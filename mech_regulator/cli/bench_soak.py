"""`mech-regulator bench soak`: the main job played for an hour of simulated time (by default), watched from outside:
each node's memory and the exchange rate every interval of wall time, the energy balance and a verdict at the end
(bench.soak). Light to import (the parser is built from it): the benchmark loads inside run_bench_soak.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
from pathlib import Path

from mech_regulator.errors import EXIT_INTERRUPTED

SOAK_DURATION = 3600.0  # [s] of simulated time a soak plays by default
SOAK_INTERVAL = 30.0  # [s] of wall time between two rows by default


def add_bench_soak_command(benchmarks) -> None:
    """The `bench soak` subcommand and its options, under `bench`'s subparsers."""
    soak = benchmarks.add_parser(
        "soak",
        help="soak benchmark: the main job (the ROS nodes) for an hour of simulated time, each node's memory "
        "and the exchange rate at intervals, the energy balance",
        description="Play a scene on the ROS nodes as `mech-regulator run` does (a subprocess) for a long simulated "
        "time and print, every interval of wall time, the resident memory (RSS) of each process "
        "(machine, governor, scenario, recorder, launcher) and the exchange rate over the interval "
        "(exchanges per second of wall time and the real-time factor); at the end the run's summary, "
        "the energy balance of its samples over the whole run and its first and last tenth, and a "
        "verdict: each process's memory at the start and the end of the run, the real-time factor in "
        "the first and the last interval, and 'memory flat' when no process's memory grew faster "
        "than the bound it states (in kB per simulated minute) over the second half of the run. "
        "Ctrl-C stops the run as it stops `run` and prints what was measured. Needs rclpy (pip install 'mech_regulator[ros]'). Numbers to read, never asserted.",
    )
    soak.add_argument(
        "--scene",
        default="engine_direct",
        metavar="SCENE",
        help="scene file or bundled scene to play (default engine_direct, the main job's)",
    )
    soak.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="change a scene value, as `run --set` (repeatable)",
    )
    soak.add_argument(
        "--duration",
        type=float,
        default=SOAK_DURATION,
        metavar="T",
        help=f"simulated time to play [s] (default {SOAK_DURATION:g}: an hour)",
    )
    soak.add_argument(
        "--interval",
        type=float,
        default=SOAK_INTERVAL,
        metavar="S",
        help=f"wall time between two rows [s] (default {SOAK_INTERVAL:g}; the machine reports its "
        "time once a second, so a shorter interval can read 0 for want of a report)",
    )
    soak.add_argument(
        "--out",
        type=Path,
        help="the run's recording (default runs/<scene>-<time>.rrd, as `run`); its CSV, summary and log go next to it",
    )
    soak.add_argument("--domain-id", type=int, help="ROS domain of the run (default: `run`'s, a random one)")


def run_bench_soak(args: argparse.Namespace) -> int:
    """bench soak: play the run, printing the rows as they come, then the closing lines; the launcher's exit code
    (130 when interrupted)."""
    import importlib.util

    from mech_regulator.scene import SceneError, load_scene

    if importlib.util.find_spec("rclpy") is None:
        raise SceneError(
            "bench soak plays the main job, which needs ROS 2's rclpy: source a ROS 2 installation, or "
            "pip install 'mech_regulator[ros]'"
        )
    if importlib.util.find_spec("psutil") is None:
        raise SceneError("bench soak reads each node's memory with psutil: pip install 'mech_regulator[bench]'")
    if not 0.0 < args.duration <= 1e7:
        raise SceneError(f"--duration {args.duration:g}: expected a simulated time in (0, 1e7] s")
    if not (math.isfinite(args.interval) and args.interval > 0.0):
        raise SceneError(f"--interval {args.interval:g}: expected a wall time > 0 s")

    from mech_regulator.bench.soak import format_soak, run_energy, run_soak
    from mech_regulator.model import build_model

    model = build_model(load_scene(args.scene, args.overrides))  # a wrong scene or value: told here, before the run
    print(
        f"soak: {args.scene} on the nodes for {args.duration:g} s of simulated time, a row every "
        f"{args.interval:g} s of wall time",
        flush=True,
    )
    signal.signal(signal.SIGTERM, signal.default_int_handler)  # `kill` or a timeout stops the run as Ctrl-C does
    soak = run_soak(
        args.scene,
        args.duration,
        args.interval,
        args.overrides,
        args.out,
        args.domain_id,
        report=lambda line: print(line, flush=True),
        passed_on=lambda line: print(line, file=sys.stderr, flush=True),
    )
    try:
        soak.energy = run_energy(soak, model)
    except KeyboardInterrupt:  # the balance of a long run takes a while: the rest is printed without it
        soak.interrupted = True
    print(format_soak(soak), flush=True)
    if soak.interrupted:
        print("mech-regulator: interrupted; the rows above are what was measured", file=sys.stderr)
        return EXIT_INTERRUPTED
    return soak.exit_code if soak.exit_code is not None else 1
