"""`mech-regulator bench speed`: the four paths side by side at equal achieved accuracy, how cost grows, the
start-up cost and (--ros) the lockstep ROS run. A thin layer over bench.speed: it prints each measurement as it
comes, then the tables with the targets, and writes speed.csv (also when interrupted), speed.json and speed.png
(and ros.png with --ros).

`mech-regulator bench startup`: the time to a first result as a user meets it, whole processes (bench.startup).

`mech-regulator bench first-run`: a fresh clone with an empty HOME, set-up, first command and first main job timed
(bench.first_run).

Light to import (the parser is built from it): the benchmarks load inside the run functions.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from mech_regulator.errors import EXIT_INTERRUPTED

BENCH_EXTRA = "pip install 'mech_regulator[bench]'"


def add_bench_speed_command(benchmarks) -> None:
    """The `bench speed` subcommand and its options, under `bench`'s subparsers."""
    speed = benchmarks.add_parser(
        "speed",
        help="speed benchmark: fast path, reference path, solve_ivp and MuJoCo at equal achieved accuracy",
        description="Measure, side by side at equal achieved accuracy (omega RMS error 1e-6, relative), the fast "
        "compiled path, the reference path, scipy's solve_ivp on the plain-Python right-hand side and "
        "MuJoCo simulating the crank-slider as a multibody model with a closed loop: CPU time, ratios, "
        "RHS evaluations per second, real-time factor; then the cost against simulated time, the number "
        "of effects and the number of scenes in a sweep, and the start-up cost. Writes speed.csv, "
        "speed.json and speed.png (with --ros also ros.png, the real-time factor against the exchange "
        "error); Ctrl-C keeps what was measured in speed.csv. Speeds are reported, "
        "never asserted.",
    )
    speed.add_argument(
        "--quick",
        action="store_true",
        help="few points and short runs (a check of the command end to end, well under a minute; not a measurement)",
    )
    speed.add_argument(
        "--scenes",
        metavar="NAME[,NAME...]",
        help="speed scenes to run, comma-separated (default: crank_slider_bench,startup,"
        "walking_beam_linkage; a wrong name lists them)",
    )
    speed.add_argument(
        "--out",
        type=Path,
        default=Path("docs/speed"),
        metavar="FOLDER",
        help="folder for the outputs (default docs/speed)",
    )
    speed.add_argument(
        "--ros",
        action="store_true",
        help="also time the lockstep ROS main job on the whole engine_direct for each exchange design "
        "(hold at 1 ms on both paths, waveform at 2 and 10 ms, corrected at 10, 20 and 40 ms) and "
        "on the other governed scenes at run's default, with each run's error against the monolithic "
        "run (needs rclpy; about 5 minutes)",
    )
    speed.add_argument(
        "--no-mujoco",
        action="store_true",
        help=f"leave MuJoCo's path out (without it, crank_slider_bench needs MuJoCo: {BENCH_EXTRA})",
    )


def add_bench_startup_command(benchmarks) -> None:
    """The `bench startup` subcommand and its options, under `bench`'s subparsers."""
    startup = benchmarks.add_parser(
        "startup",
        help="start-up benchmark: import, --help, a cold first run and a warm run, whole processes",
        description="Time whole processes as a user meets them, for the reference path, the fast path and a plain "
        "scipy solve_ivp script of the same machine (written to a temporary file): the import of the "
        "command line (python -c 'import mech_regulator.cli.main'; the script: numpy and "
        "scipy.integrate), `mech-regulator --help`, a cold first run of `mech-regulator simulate SCENE "
        "--quiet` (empty compile caches: MECH_REGULATOR_CACHE and NUMBA_CACHE_DIR in a new temporary "
        "folder each time), a warm run (the caches filled) in a process of its own and a warm run "
        "through the command server (one started in a temporary folder, stopped at the end). Wall time, "
        "median and minimum of the repeats, side by side with the ratios to the script. Numbers to "
        "read, never asserted.",
    )
    startup.add_argument(
        "--scene",
        default="crank_slider_bench",
        metavar="SCENE",
        help="the machine (default crank_slider_bench; lathe works too: a scene without governor, "
        "drive train, joint friction or load events, with no mechanism or a crank-slider)",
    )
    startup.add_argument(
        "--repeat",
        type=int,
        default=3,
        metavar="N",
        help="runs of each measurement (default 3; a cold fast run compiles, tens of seconds)",
    )
    startup.add_argument(
        "--skip-cold-fast",
        action="store_true",
        help="leave out the fast path's cold runs (the compiling ones); its warm runs then use the "
        "compile caches of this machine (MECH_REGULATOR_CACHE or ~/.cache), filled first by "
        "one run that is not counted",
    )
    startup.add_argument("--json", action="store_true", help="print the measurements as JSON")


def add_bench_first_run_command(benchmarks) -> None:
    """The `bench first-run` subcommand and its options, under `bench`'s subparsers."""
    first_run = benchmarks.add_parser(
        "first-run",
        help="first-run benchmark: a fresh clone with an empty HOME, its set-up, first command and "
        "first main job timed",
        description="Clone this checkout's repository into a new folder and time, as a newcomer meets them, with an "
        "empty HOME and no pip cache (unless --pip-cache): the set-up (`./dev run --help`: the venv and "
        "the main job's packages), the first command (`mech-regulator scenes`), the first main job "
        "(`./dev run SCENE`, its stepper compiled first) with its real-time factor and path, and the "
        "same run again warm; prints a table and the first run's pace as a share of the warm one's. Takes "
        "minutes and about 1.5 GB of disk, removed at the end unless --keep. Numbers to read, never "
        "asserted.",
    )
    first_run.add_argument(
        "--scene",
        default="engine_direct",
        metavar="SCENE",
        help="the main job's scene (default engine_direct, `./dev run`'s)",
    )
    first_run.add_argument(
        "--pip-cache",
        type=Path,
        metavar="FOLDER",
        help="pip's cache folder for the set-up (default: none, PIP_NO_CACHE_DIR)",
    )
    first_run.add_argument(
        "--folder",
        type=Path,
        metavar="FOLDER",
        help="where to clone and run (a new folder; default: a new temporary folder)",
    )
    first_run.add_argument("--keep", action="store_true", help="keep the folder (the clone, its venv, the runs)")
    first_run.add_argument("--dry-run", action="store_true", help="print the steps and their commands, run nothing")


def run_bench_speed(args: argparse.Namespace) -> int:
    """bench speed: measure, print, then write speed.csv (also when interrupted), speed.json and speed.png."""
    import importlib.util

    from mech_regulator.bench.mujoco_model import mujoco_refusal
    from mech_regulator.bench.speed import (
        row_line,
        run_speed_benchmark,
        select_speed_scenes,
        summary,
        tables,
        write_rows_csv,
    )
    from mech_regulator.cli.report.data import to_json
    from mech_regulator.cli.report.outputs import bench_scenes_and_folder, check_output_paths
    from mech_regulator.scene import SceneError

    scenes = select_speed_scenes(bench_scenes_and_folder(args.scenes, args.out, "crank_slider_bench,startup"))
    check_output_paths(*(args.out / name for name in ("speed.csv", "speed.json", "speed.png", "ros.png")))
    mujoco = not args.no_mujoco
    if mujoco and importlib.util.find_spec("mujoco") is None:
        needing = [bench.name for bench in scenes if mujoco_refusal(bench.load(args.quick)) is None]
        if needing:
            raise SceneError(
                f"bench speed: {', '.join(needing)} runs on MuJoCo too, and MuJoCo is not installed: "
                f"{BENCH_EXTRA} (or give --no-mujoco to leave MuJoCo's path out)"
            )
    start = time.monotonic()
    benchmark = run_speed_benchmark(
        scenes, args.quick, args.ros, report=lambda row: print(row_line(row), flush=True), mujoco=mujoco
    )
    write_rows_csv(benchmark, args.out / "speed.csv")
    (args.out / "speed.json").write_text(to_json(summary(benchmark)) + "\n", encoding="utf-8")
    print(tables(benchmark))
    if benchmark.interrupted:
        print(
            f"mech-regulator: interrupted; what was measured is in {args.out / 'speed.csv'} and speed.json",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    from mech_regulator.viz.speed import plot_ros_speed, plot_speed

    plot_speed(benchmark, args.out / "speed.png")
    written = ["speed.csv", "speed.json", "speed.png"]
    if plot_ros_speed(benchmark, args.out / "ros.png"):
        written.append("ros.png")
    print(f"wrote {args.out}: {', '.join(written)} ({time.monotonic() - start:.0f} s)")
    return 0


def run_bench_startup(args: argparse.Namespace) -> int:
    """bench startup: measure, printing each measurement on stderr as it comes, then the table (or JSON)."""
    from mech_regulator.bench.startup import format_table, measure_startup, script_refusal, startup_summary
    from mech_regulator.cli.report.data import to_json
    from mech_regulator.scene import SceneError, load_scene

    if not 1 <= args.repeat <= 100:
        raise SceneError(f"--repeat {args.repeat}: expected 1 to 100 runs of each measurement")
    refusal = script_refusal(load_scene(args.scene))
    if refusal is not None:
        raise SceneError(
            f"bench startup: scene '{args.scene}': the plain solve_ivp script cannot reproduce it: "
            f"{refusal}; choose e.g. crank_slider_bench or lathe"
        )
    try:
        benchmark = measure_startup(
            args.scene,
            args.repeat,
            cold_fast=not args.skip_cold_fast,
            report=lambda line: print(line, file=sys.stderr, flush=True),
        )
    except KeyboardInterrupt:
        print("mech-regulator: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except RuntimeError as error:  # a measured command failed: its own message
        print(f"mech-regulator: bench startup: {error}", file=sys.stderr)
        return 1
    print(to_json(startup_summary(benchmark)) if args.json else format_table(benchmark))
    return 0


def run_bench_first_run(args: argparse.Namespace) -> int:
    """bench first-run: the steps (or with --dry-run their commands), a line before and after each on stderr, then
    the table; exit 1 if a step failed, 130 if interrupted (the table of what was measured printed first)."""
    import tempfile

    from mech_regulator.bench.first_run import format_table, measure_first_run, plan, remove, repository_root
    from mech_regulator.scene import SceneError, load_scene

    load_scene(args.scene)  # a wrong name lists the scenes before anything is cloned
    try:
        repository_root()
    except ValueError as error:
        raise SceneError(f"bench first-run: {error}") from None
    if args.pip_cache is not None and not args.pip_cache.is_dir():
        raise SceneError(f"--pip-cache '{args.pip_cache}': expected an existing folder (pip's cache)")
    if args.folder is not None and args.folder.exists():
        raise SceneError(f"--folder '{args.folder}': expected a new folder (it exists)")
    if args.dry_run:
        for step in plan(args.folder or Path("FOLDER"), args.scene):
            print(f"{step.title}: (in {step.cwd}) {' '.join(step.command)}")
        return 0
    folder = args.folder or Path(tempfile.mkdtemp(prefix="mech-regulator-first-run-")) / "work"
    try:
        result = measure_first_run(
            folder, args.scene, args.pip_cache, report=lambda line: print(line, file=sys.stderr, flush=True)
        )
    finally:
        if not args.keep:
            remove(folder.parent if args.folder is None else folder)
    print(format_table(result, args.pip_cache))
    if result.interrupted:
        return EXIT_INTERRUPTED
    return 0 if all(step.exit_code == 0 for step in result.steps) else 1
