"""The `mech-regulator` command: simulate, describe and list scenes, analyse governors and engines, print the
scene schema.

A user's mistake in a scene or an option ends in a message and exit code 2, never a traceback; a run
that fails or is interrupted still writes what it computed.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from mech_regulator import __version__
from mech_regulator.cli.bench_long import add_bench_long_command
from mech_regulator.cli.bench_soak import add_bench_soak_command
from mech_regulator.cli.bench_speed import (
    add_bench_first_run_command,
    add_bench_speed_command,
    add_bench_startup_command,
)
from mech_regulator.cli.flywheel import add_flywheel_command
from mech_regulator.cli.report import note, terminal_text
from mech_regulator.cli.start import STARTED
from mech_regulator.cli.structure import add_structure_command
from mech_regulator.cli.sweep import add_sweep_command
from mech_regulator.errors import EXIT_INACCURATE, EXIT_INTERRUPTED, EXIT_RUN_FAILED
from mech_regulator.nodes.controller import CONTROLLERS

COUPLING_HELP = (
    "how machine and governor see each other over an exchange step: hold (each holds the other's last "
    "value, first order in H), waveform (the governor follows the machine's speed over the step, the "
    "machine the throttle extrapolated from the governor's last answers) or corrected (waveform's "
    "prediction, then the step done again with the governor's own throttle over it, the governor "
    "following the machine's speed sampled every 1.25 ms, a ramp of the load followed; the default; "
    "docs/ros.md)"
)

if TYPE_CHECKING:
    import numpy as np

# The parser is built from light modules only (the standard library and the cli's own parser builders), so that
# `--help` and a mistyped option answer at once; each command imports what it needs (numpy, scipy, numba,
# pydantic, matplotlib, rerun) inside its function. test/test_cli_startup.py checks it.

EXIT_BAD_INPUT = 2
SAMPLE_CHUNK = 200_000  # output samples whose columns simulate computes and writes at once (_sample_columns)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mech-regulator",
        description="Real motion of machines and the regulation "
        "of their speed: simulate a machine described in a scene file.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def scene_command(name: str, help_text: str, scene_required: bool = True) -> argparse.ArgumentParser:
        sub = commands.add_parser(name, help=help_text, description=help_text)
        sub.add_argument(
            "scene",
            nargs=None if scene_required else "?",
            metavar="SCENE",
            help="scene file, or the name of a bundled scene (see 'scenes')",
        )
        sub.add_argument(
            "--set",
            dest="overrides",
            action="append",
            default=[],
            metavar="KEY=VALUE",
            help="change a scene value, e.g. --set machine.flywheel.inertia=0.5 "
            "(list items by index: machine.loads.0.coefficient=0.02); repeatable",
        )
        return sub

    simulate = scene_command("simulate", "simulate a scene and print its summary")
    simulate.add_argument(
        "--out", type=Path, help="write the sampled run as CSV (t, phi, omega, epsilon, J, moments, ...)"
    )
    simulate.add_argument("--plot", type=Path, help="write a PNG picture of the run")
    simulate.add_argument(
        "--record",
        type=Path,
        metavar="RUN.rrd",
        help="write a Rerun recording of the run (speed, throttle, sleeve, moments, the mechanism "
        "and governor animated, events); open it with `rerun RUN.rrd`",
    )
    simulate.add_argument(
        "--bag",
        type=Path,
        metavar="FOLDER",
        help="write the run as a rosbag2 recording (MCAP; a new folder) of the topics the ROS nodes "
        "publish, for ros2 bag, Foxglove or PlotJuggler (docs/ros.md, Bags)",
    )
    simulate.add_argument("--json", action="store_true", help="print the summary as JSON")
    simulate.add_argument("--quiet", action="store_true", help="no progress bar")
    simulate.add_argument(
        "--strict",
        action="store_true",
        help="exit 3 when the run fails a self-check (status inaccurate: its energy residual "
        "exceeds what its tolerance allows, or its mode log missed an event)",
    )
    simulate.add_argument(
        "--exchange-step",
        type=float,
        metavar="H",
        help="co-simulate machine and governor as the ROS nodes do in lockstep, exchanging "
        "speed, throttle and load every H seconds (the same numbers as `run`)",
    )
    simulate.add_argument(
        "--coupling",
        choices=("hold", "waveform", "corrected"),
        default="corrected",
        help="with --exchange-step: " + COUPLING_HELP,
    )
    simulate.add_argument(
        "--overspeed-trip",
        type=float,
        default=0.0,
        metavar="OMEGA",
        help="with --exchange-step: trip speed [rad/s] closing the throttle for good, as `run` "
        "has; the run then ends `tripped` (default 0: none)",
    )
    scene_command("describe", "print the effects, state vector and solver a scene uses, without running it")
    governor = scene_command(
        "governor",
        "statics and stability of a governed scene: static characteristic, "
        "statism, insensitivity, operating points, droop, eigenvalues, "
        "Vyshnegradsky A and B, Floquet multipliers",
    )
    governor.add_argument("--plot", type=Path, help="write a PNG picture of the statics and stability")
    governor.add_argument("--json", action="store_true", help="print the analysis as JSON")
    coupling = scene_command(
        "coupling",
        "the inverse problem of the two-mass machine (source 003): the coupling "
        "characteristic M_m(twist) a prescribed driven speed law needs - a linear "
        "run-up from rest to omega_m in T, then omega_m + A sin(k (t - T)), "
        "A = delta omega_m / 2",
    )
    coupling.add_argument("--run-up", type=float, required=True, metavar="T", help="run-up time T [s]")
    coupling.add_argument(
        "--delta",
        type=float,
        required=True,
        metavar="D",
        help="coefficient of speed fluctuation of the driven part in steady motion, 0 < D < 2 [-]",
    )
    coupling.add_argument(
        "--frequency",
        type=float,
        metavar="K",
        help="k of the sine [rad/s] (default: once per dynamic period at omega_m)",
    )
    coupling.add_argument(
        "--speed",
        type=float,
        metavar="OMEGA",
        help="mean speed omega_m [rad/s] (default: the speed at which the drive balances the loads)",
    )
    coupling.add_argument("--points", type=int, default=201, metavar="N", help="points of the table (default 201)")
    coupling.add_argument("--out", type=Path, help="write the characteristic as CSV (twist, moment)")
    coupling.add_argument(
        "--scene-out",
        type=Path,
        metavar="FILE.yaml",
        help="write the scene with this characteristic, started where the table begins, to run "
        "it forward with `simulate`",
    )
    coupling.add_argument("--plot", type=Path, help="write a PNG picture: the law, the twist, the characteristic")
    coupling.add_argument("--json", action="store_true", help="print the answer as JSON")
    kinematics = scene_command(
        "kinematics",
        "positions, velocities and accelerations of the mechanism's joints over "
        "one turn at constant crank speed, and the joint reactions where they "
        "are determinate: any linkage (type: linkage, docs/linkages.md) or a "
        "preset (crank_slider, four_bar, walking_beam)",
    )
    kinematics.add_argument("--omega", type=float, default=10.0, help="constant crank speed [rad/s] (default 10)")
    kinematics.add_argument(
        "--points",
        type=int,
        default=361,
        metavar="N",
        help="crank angles over the turn, both ends included (default 361: every degree)",
    )
    kinematics.add_argument(
        "--out",
        type=Path,
        help="write the table as CSV (phi, t, then per point P: P_x, P_y [m], "
        "P_vx, P_vy, P_v [m/s], P_ax, P_ay, P_a [m/s^2])",
    )
    kinematics.add_argument(
        "--plot",
        type=Path,
        help="write a PNG picture: paths with the mechanism at a few positions, speeds and accelerations",
    )
    kinematics.add_argument("--json", action="store_true", help="print the summary as JSON")
    engine = scene_command(
        "engine",
        "an engine scene at constant crank speed: dead centres, stroke, piston "
        "kinematics (exact and source 002's approximation), cylinders and firing, "
        "torque curves per cylinder and total, mean indicated torque and power, harmonics",
    )
    engine.add_argument(
        "--omega", type=float, metavar="W", help="crank speed [rad/s] (default: the scene's initial speed)"
    )
    engine.add_argument(
        "--plot",
        type=Path,
        help="write a PNG picture: piston x, v, a over the turn; torque curves over the cycle; harmonic spectrum",
    )
    engine.add_argument("--out", type=Path, help="write the curves over the working cycle as CSV")
    engine.add_argument("--json", action="store_true", help="print the analysis as JSON")
    add_flywheel_command(scene_command)
    add_structure_command(scene_command)
    add_sweep_command(scene_command)
    main_job = scene_command(
        "run",
        "the main job: run the ROS nodes (machine, governor, scenario, recorder) as "
        "separate processes on a private ROS domain, record the run to a Rerun file "
        "and print its summary (needs rclpy: pip install 'mech_regulator[ros]')",
    )
    main_job.add_argument(
        "--exchange-step",
        type=float,
        metavar="H",
        help="simulation time between exchanges of the nodes [s] (default: the scene's "
        "solver.exchange_step, 0.02 unless the scene sets it)",
    )
    main_job.add_argument(
        "--coupling", choices=("hold", "waveform", "corrected"), default="corrected", help=COUPLING_HELP
    )
    main_job.add_argument(
        "--duration",
        type=float,
        metavar="T",
        help="simulated time to play [s] (default: the scene's scenario.duration); a shorter run "
        "keeps the scene's load events as they are",
    )
    main_job.add_argument(
        "--time-mode",
        choices=("lockstep", "realtime"),
        default="lockstep",
        help="lockstep: as fast as possible and reproducible; realtime: follow the wall clock",
    )
    main_job.add_argument(
        "--real-time-factor",
        type=float,
        default=1.0,
        metavar="X",
        help="realtime: simulated seconds per wall-clock second",
    )
    main_job.add_argument(
        "--overspeed-trip",
        type=float,
        default=0.0,
        metavar="OMEGA",
        help="trip speed [rad/s]: above it the machine's throttle closes for good and the run "
        "ends `tripped` (default 0: no trip)",
    )
    main_job.add_argument("--out", type=Path, help="the recording to write (default runs/<scene>-<time>.rrd)")
    main_job.add_argument(
        "--bag",
        type=Path,
        metavar="FOLDER",
        help="also write the run as a rosbag2 recording (MCAP; a new folder; docs/ros.md, Bags)",
    )
    main_job.add_argument(
        "--controller",
        choices=CONTROLLERS,
        default="governor",
        help="what gives the throttle: the scene's governor (governor_node, default) or external: "
        "your own node, started by you, that answers joint_states with throttle; the scene's "
        "governor is then left out (docs/ros.md, Your own controller)",
    )
    main_job.add_argument(
        "--peer-timeout",
        type=float,
        metavar="S",
        help="lockstep: wall-clock seconds the machine waits for a node and for each answer "
        "(default 10); a governor silent that long puts it on its fail-safe, an external "
        "controller ends the run",
    )
    main_job.add_argument(
        "--domain-id", type=int, help="ROS domain of the run (default: a random one no other run on this machine holds)"
    )
    main_job.add_argument("--quiet", action="store_true", help="no progress bar")
    schema = commands.add_parser("schema", help="print the JSON Schema of scene files (for editors)")
    schema.add_argument(
        "--format",
        choices=("json", "markdown"),
        default="json",
        help="json: the JSON Schema; markdown: the key tables of docs/scenes.md",
    )
    commands.add_parser("scenes", help="list the bundled scenes")
    compile_command = commands.add_parser(
        "compile",
        help="compile the fast path's steppers and the linkage solver once on this machine (a first fast "
        "run otherwise uses the reference path while they compile in the background; a first linkage "
        "compiles its solver, announced)",
    )
    compile_command.add_argument(
        "--method",
        action="append",
        choices=("RK45", "DOP853", "RK4", "Rosenbrock23"),
        help="a method to compile (repeatable; default: all)",
    )
    server = commands.add_parser(
        "server",
        help="the command server: a resident process with the command line and the physics core loaded "
        "that answers simulate, describe, kinematics, structure, governor, engine, coupling, flywheel, "
        "scenes and schema in a forked child, without their imports (started by the first such "
        "command; stops after 10 min idle, MECH_REGULATOR_SERVER_IDLE seconds; "
        "MECH_REGULATOR_SERVER=off: never one)",
    )
    server.add_argument(
        "action",
        choices=("start", "status", "stop"),
        help="start: start this environment's server (unless running) and wait until it answers; "
        "status: pid, key, idle time and what each server has loaded; stop: stop every server",
    )
    bench = commands.add_parser("bench", help="benchmarks of the solvers", description="benchmarks of the solvers")
    benchmarks = bench.add_subparsers(dest="benchmark", required=True, metavar="BENCHMARK")
    accuracy = benchmarks.add_parser(
        "accuracy",
        help="work-precision benchmark: achieved error against CPU time of every method",
        description="Run every method (scipy's adaptive methods over a tolerance sweep, RK4 over steps, the energy "
        "method over crank-angle steps, the nodes' co-simulation over exchange steps) on reference scenes, "
        "measure the error each achieves against a closed form or a checked reference solution and its "
        "CPU time, and write runs.csv, a work-precision PNG per scene, tolerance_proportionality.png, "
        "README.md and work_precision.rrd. Ctrl-C keeps the runs measured so far in runs.csv.",
    )
    accuracy.add_argument(
        "--quick",
        action="store_true",
        help="few points and tiny durations (a check of the command end to end, not a measurement)",
    )
    accuracy.add_argument(
        "--scenes",
        metavar="NAME[,NAME...]",
        help="reference scenes to run, comma-separated (default: all; a wrong name lists them)",
    )
    accuracy.add_argument(
        "--out",
        type=Path,
        default=Path("docs/accuracy"),
        metavar="FOLDER",
        help="folder for the outputs (default docs/accuracy)",
    )
    accuracy.add_argument(
        "--jobs",
        type=int,
        default=2,
        metavar="N",
        help="worker processes (default 2; CPU time is per process, but more workers than cores disturb it)",
    )
    add_bench_speed_command(benchmarks)
    add_bench_startup_command(benchmarks)
    add_bench_first_run_command(benchmarks)
    add_bench_soak_command(benchmarks)
    add_bench_long_command(benchmarks)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of `mech-regulator` and `python -m mech_regulator`; returns the exit code."""
    args = build_parser().parse_args(argv)
    from mech_regulator.scene import SceneError

    try:
        if args.command == "schema":
            from mech_regulator.scene.reference import schema_json, schema_markdown

            print(schema_json() if args.format == "json" else schema_markdown(), end="")
            return 0
        if args.command == "scenes":
            return _list_scenes()
        if args.command == "server":
            from mech_regulator.cli.server import server_command

            return server_command(args.action)
        if args.command == "compile":
            from mech_regulator.solvers.compiled.warm import compile_steppers

            compile_steppers(args.method or ("RK45", "DOP853", "RK4", "Rosenbrock23"), print)
            if not args.method:
                from mech_regulator.mechanisms.linkage.flat import compile_all

                compile_all(print)
            return 0
        if args.command == "bench":
            return _bench(args)
        if args.command == "flywheel":
            from mech_regulator.cli.flywheel import run_flywheel

            return run_flywheel(args)
        if args.command == "sweep":
            from mech_regulator.cli.sweep import run_sweep_command

            return run_sweep_command(args)
        from mech_regulator.cli.report import check_outputs
        from mech_regulator.scene import load_scene

        if args.command != "run":  # every output checked before the scene is read (it may compile a linkage)
            check_outputs(args, *(getattr(args, name, None) for name in ("out", "record", "scene_out")))
        elif args.out is not None:
            _check_run_files(args.out)
        if args.command == "describe":
            from mech_regulator import cache
            from mech_regulator.cli.report import describe
            from mech_regulator.model import build_model

            with cache.run_uncompiled():  # describing needs no compiled code (cache.py)
                print(describe(build_model(load_scene(args.scene, args.overrides))))
            return 0
        scene = load_scene(args.scene, args.overrides)
        if args.command == "governor":
            return _governor(scene, args)
        if args.command == "run":
            return _main_job(scene, args)
        if args.command == "coupling":
            return _required_coupling(scene, args)
        if args.command in ("kinematics", "structure"):  # they build no machine: the mechanisms' checks here
            from mech_regulator.mechanisms.checks import refuse_unbuildable

            refuse_unbuildable(scene)
        if args.command == "kinematics":
            return _kinematics(scene, args)
        if args.command == "structure":
            from mech_regulator.cli.structure import run_structure

            return run_structure(scene, args)
        if args.command == "engine":
            return _engine(scene, args)
        return _simulate(scene, args)
    except SceneError as error:
        print(f"mech-regulator: {terminal_text(str(error))}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # the reader went away (`... | head`): not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


def _bench(args) -> int:
    """bench: the benchmark asked for."""
    if args.benchmark == "speed":
        from mech_regulator.cli.bench_speed import run_bench_speed

        return run_bench_speed(args)
    if args.benchmark == "startup":
        from mech_regulator.cli.bench_speed import run_bench_startup

        return run_bench_startup(args)
    if args.benchmark == "first-run":
        from mech_regulator.cli.bench_speed import run_bench_first_run

        return run_bench_first_run(args)
    if args.benchmark == "soak":
        from mech_regulator.cli.bench_soak import run_bench_soak

        return run_bench_soak(args)
    if args.benchmark == "long":
        from mech_regulator.cli.bench_long import run_bench_long

        return run_bench_long(args)
    return _bench_accuracy(args)


def _list_scenes() -> int:
    """scenes: each bundled scene's name and the first sentence of its description, read from its file (and the
    files it derives from) without validating it: listing checks and compiles nothing."""
    from mech_regulator.scene import bundled_scenes
    from mech_regulator.scene.loading import read_scene_data

    for name, path in bundled_scenes().items():
        description = " ".join(str(read_scene_data(path).get("description") or "").split())
        print(f"{name:<26} {description.split('. ')[0]}")
    return 0


def _simulate(scene, args) -> int:
    from mech_regulator.analysis import summarise
    from mech_regulator.analysis.self_check import self_checks
    from mech_regulator.cli.report import OutputWriter, format_summary, progress_bar, to_json, write_csv
    from mech_regulator.model import build_model
    from mech_regulator.scene import SceneError
    from mech_regulator.solvers import on_path_for_a_command, simulate
    from mech_regulator.solvers.advice import stiffness_advice

    if args.overspeed_trip and args.exchange_step is None:
        raise SceneError(
            f"--overspeed-trip {args.overspeed_trip:g}: the trip acts at the exchanges of the "
            "co-simulation; expected --exchange-step H with it (the monolithic run has no trip)"
        )
    _check_bag(args.bag)
    model = on_path_for_a_command(build_model(scene), note)
    if args.exchange_step is not None:
        return _cosimulate(model, args)
    advice = stiffness_advice(model)
    if advice is not None:
        print(f"mech-regulator: note: {advice}", file=sys.stderr)
    duration = scene.scenario.duration
    with progress_bar(duration, args.quiet, f"simulating {scene.name or args.scene}") as bar:
        trajectory = simulate(model, progress=lambda t: bar.update(min(t, duration) - bar.n))
        bar.update(min(trajectory.t_end, duration) - bar.n)
    summary = summarise(model, trajectory)
    checks = summary["self_checks"] = self_checks(model, summary, trajectory)
    if checks and summary["status"] == "complete":
        summary["status"] = "inaccurate"
    if not trajectory.interpolants:
        args.out = args.plot = args.record = None  # nothing to write
    outputs = OutputWriter(summary)
    outputs.write("csv", args.out, lambda path: write_csv(path, _sample_columns(model, trajectory)))
    if args.plot is not None:
        from mech_regulator.viz.plots import plot_run

        outputs.write("plot", args.plot, lambda path: plot_run(model, trajectory, summary, path))
    if args.record is not None:
        from mech_regulator.viz.recording import record_run

        outputs.write(
            "recording",
            args.record,
            lambda path: record_run(
                model,
                *_samples(model, trajectory),
                path,
                mode_changes=trajectory.events,
                status=trajectory.status,
                message=trajectory.message,
            ),
        )
    if args.bag is not None and trajectory.interpolants:
        from mech_regulator.viz.bag import write_bag

        outputs.write(
            "bag",
            args.bag,
            lambda path: write_bag(
                path, model, *_samples(model, trajectory), status=trajectory.status, message=trajectory.message
            ),
        )
    print(to_json(summary) if args.json else format_summary(model, summary))
    for check in checks:
        print(
            f"mech-regulator: warning: inaccurate run: {check['check']} {check['value']:.2g} exceeds the "
            f"{check['allowed']:.2g} its tolerance allows; {check['fix']}",
            file=sys.stderr,
        )
    if trajectory.status == "failed":
        print(f"mech-regulator: {terminal_text(trajectory.message)}", file=sys.stderr)
        return outputs.exit_code(EXIT_RUN_FAILED)
    if trajectory.status == "interrupted":
        print(
            f"mech-regulator: {terminal_text(trajectory.message)}; the outputs hold the run up to there",
            file=sys.stderr,
        )
        return outputs.exit_code(EXIT_INTERRUPTED)
    return outputs.exit_code(EXIT_INACCURATE if checks and args.strict else 0)


def _cosimulate(model, args) -> int:
    """simulate --exchange-step: the lockstep co-simulation of the nodes, in this process."""
    from mech_regulator.analysis import summarise_cosimulation
    from mech_regulator.cli.report import OutputWriter, format_cosimulation_summary, progress_bar, to_json, write_csv
    from mech_regulator.scene import SceneError
    from mech_regulator.solvers.cosim import cosimulate

    if not 1e-6 <= args.exchange_step <= 1.0:
        raise SceneError(f"--exchange-step {args.exchange_step:g}: expected 1e-6 to 1 s")
    _check_overspeed_trip(args)
    duration = model.scene.scenario.duration
    with progress_bar(duration, args.quiet, f"co-simulating {model.scene.name or args.scene}") as bar:
        run = cosimulate(
            model,
            args.exchange_step,
            args.overspeed_trip,
            progress=lambda t: bar.update(min(t, duration) - bar.n),
            coupling=args.coupling,
        )
    summary = summarise_cosimulation(model, run, args.exchange_step, args.coupling)
    outputs = OutputWriter(summary)
    outputs.write(
        "csv",
        args.out,
        lambda path: write_csv(path, model.columns(run.times, run.states, run.throttle, run.external_load), digits=17),
    )
    if args.record is not None:
        from mech_regulator.viz.recording import record_run

        outputs.write(
            "recording",
            args.record,
            lambda path: record_run(
                model,
                run.times,
                run.states,
                path,
                mode_changes=[(t, what) for t, what, _ in run.events],
                status=summary["status"],
                message=summary["message"],
            ),
        )
    if args.bag is not None:
        from mech_regulator.viz.bag import write_bag

        outputs.write(
            "bag",
            args.bag,
            lambda path: write_bag(
                path, model, run.times, run.states, run.throttle, run.external_load, run.status, run.message
            ),
        )
    print(to_json(summary) if args.json else format_cosimulation_summary(summary))
    if run.status == "failed":
        print(f"mech-regulator: {terminal_text(run.message)}", file=sys.stderr)
        return outputs.exit_code(EXIT_RUN_FAILED)
    return outputs.exit_code(EXIT_INTERRUPTED if run.status == "interrupted" else 0)


def _governor(scene, args) -> int:
    from mech_regulator.analysis import analyse_governor
    from mech_regulator.cli.report import OutputWriter, format_governor, to_json
    from mech_regulator.model import build_model
    from mech_regulator.scene import SceneError

    if scene.governor is None:
        raise SceneError(f"scene '{scene.name}' has no governor: add a 'governor:' section (see docs/scenes.md)")
    model = build_model(scene)
    analysis = analyse_governor(model)
    outputs = OutputWriter(analysis)
    if args.plot is not None:
        from mech_regulator.viz.plots import plot_governor

        outputs.write("plot", args.plot, lambda path: plot_governor(model, analysis, path))
    print(to_json(analysis) if args.json else format_governor(analysis))
    return outputs.exit_code(0)


def _required_coupling(scene, args) -> int:
    """coupling: solve the inverse problem and write the table, the scene that uses it and the picture."""
    import dataclasses

    import yaml

    from mech_regulator.analysis import required_coupling
    from mech_regulator.cli.report import OutputWriter, format_required_coupling, to_json, write_csv, wrote_lines
    from mech_regulator.model import build_model
    from mech_regulator.scene import SceneError

    for option, value, low, high in (
        ("--run-up", args.run_up, 0.0, math.inf),
        ("--delta", args.delta, 0.0, 2.0),
        ("--frequency", args.frequency, 0.0, math.inf),
        ("--speed", args.speed, 0.0, math.inf),
    ):
        if value is not None and not low < value < high:
            raise SceneError(f"{option} {value:g}: expected a value between {low:g} and {high:g} (exclusive)")
    if args.points < 3:
        raise SceneError(f"--points {args.points}: expected at least 3 table points")
    result = required_coupling(build_model(scene), args.run_up, args.delta, args.frequency, args.speed, args.points)
    answer = {
        "scene": scene.name,
        "law": dataclasses.asdict(result.law),
        "stretch": result.stretch,
        "t_from": result.t_from,
        "realisable": result.realisable,
        "loop_width": result.loop_width,
        "whole_loop_width": result.whole_loop_width,
        "jump": result.jump,
        "driving_delta": result.driving_delta,
        "notes": list(result.notes),
        "initial": result.initial,
        "characteristic": {"twist": result.table_twist.tolist(), "moment": result.table_moment.tolist()},
    }
    outputs = OutputWriter(answer)
    outputs.write(
        "csv",
        args.out,
        lambda path: write_csv(path, {"twist": result.table_twist, "moment": result.table_moment}, digits=17),
    )
    if args.scene_out is not None:
        data = scene.model_dump(exclude_none=True)
        data["name"] = f"{scene.name or 'scene'}_required_coupling"
        data["description"] = (
            f"{scene.name}: the coupling characteristic the inverse problem found for delta = "
            f"{args.delta:g} (mech-regulator coupling), started at t = {result.t_from:.6g} s of "
            "the prescribed law."
        )
        coupling = data["machine"]["coupling"]
        coupling.pop("stiffness", None)
        coupling["characteristic"] = answer["characteristic"]
        data["scenario"]["initial"] = dict(result.initial)
        text = yaml.safe_dump(data, sort_keys=False, default_flow_style=None)
        outputs.write("scene_out", args.scene_out, lambda path: path.write_text(text, encoding="utf-8"))
    if args.plot is not None:
        from mech_regulator.viz.plots import plot_required_coupling

        outputs.write("plot", args.plot, lambda path: plot_required_coupling(result, scene.name, path))
    print(
        to_json(answer)
        if args.json
        else "\n".join([format_required_coupling(result, scene.name), *map(terminal_text, wrote_lines(answer))])
    )
    return outputs.exit_code(0)


def _kinematics(scene, args) -> int:
    """kinematics: the joints' motion over one turn at constant crank speed; summary, CSV and PNG."""
    from mech_regulator.analysis.kinematics import (
        kinematics_summary,
        kinematics_table,
        reactions_summary,
        reactions_table,
        reactions_unavailable,
    )
    from mech_regulator.cli.report import OutputWriter, format_kinematics, to_json, write_csv
    from mech_regulator.mechanisms import cam_pairs_of
    from mech_regulator.scene import SceneError

    mechanism, driven = scene.machine.analysed_mechanism()
    if mechanism is None:
        raise SceneError(
            f"scene '{scene.name}' has no mechanism: kinematics needs machine.mechanism or a coupling's "
            "driven.mechanism (a linkage, docs/linkages.md, or crank_slider, four_bar or walking_beam, "
            "docs/scenes.md)"
        )
    if not (math.isfinite(args.omega) and args.omega > 0.0):
        raise SceneError(f"--omega {args.omega:g}: expected a crank speed > 0 rad/s")
    if not 3 <= args.points <= 100_000:
        raise SceneError(f"--points {args.points}: expected 3 to 100000 crank angles")
    columns = kinematics_table(mechanism, args.omega, args.points)
    summary = {
        "scene": scene.name,
        "mechanism": mechanism.type,
        "driven_part": driven,
        "omega": args.omega,
        "points": args.points,
        "joints": kinematics_summary(columns),
    }
    gravity = tuple(scene.machine.gravity) if scene.machine.gravity is not None else None
    reactions = reactions_table(mechanism, gravity, args.omega, columns["phi"])
    if reactions:
        columns.update(reactions)
        summary["reactions"] = reactions_summary(columns)
    else:
        summary["no_reactions"] = reactions_unavailable(mechanism)
    cams = cam_pairs_of(mechanism, gravity)  # a cam pair's pressure angle, curvature and jump speed
    if cams:
        summary["cams"] = [pair.numbers() for pair in cams]
    outputs = OutputWriter(summary)
    outputs.write("csv", args.out, lambda path: write_csv(path, columns))
    if args.plot is not None:
        from mech_regulator.viz.plots import plot_kinematics

        outputs.write(
            "plot",
            args.plot,
            lambda path: plot_kinematics(mechanism, columns, args.omega, scene.name or mechanism.type, path),
        )
    print(
        to_json(summary)
        if args.json
        else "\n".join([format_kinematics(summary)] + [line for pair in cams for line in pair.report()])
    )
    return outputs.exit_code(0)


def _engine(scene, args) -> int:
    """engine: the analysis of an engine scene at constant speed, printed, and optionally a PNG and a CSV."""
    from mech_regulator.analysis.engine import engine_curve_columns, engine_parts, engine_report
    from mech_regulator.cli.report import OutputWriter, format_engine, to_json, write_csv
    from mech_regulator.model import build_model
    from mech_regulator.scene import SceneError

    engine_parts(scene)  # refuses a scene that is not an engine, before the model is built
    omega = scene.scenario.initial.omega if args.omega is None else args.omega
    if not (math.isfinite(omega) and omega > 0.0):
        source = "--omega" if args.omega is not None else "the scene's scenario.initial.omega"
        raise SceneError(f"{source} = {omega:g} rad/s: expected a crank speed > 0 (give --omega W)")
    model = build_model(scene)
    report = engine_report(model, omega)
    outputs = OutputWriter(report)
    outputs.write("csv", args.out, lambda path: write_csv(path, engine_curve_columns(model, omega)))
    if args.plot is not None:
        from mech_regulator.viz.plots import plot_engine

        outputs.write("plot", args.plot, lambda path: plot_engine(model, omega, path))
    print(to_json(report) if args.json else format_engine(report))
    return outputs.exit_code(0)


def _check_overspeed_trip(args) -> None:
    """Refuse a --overspeed-trip that is not a speed >= 0 rad/s (SceneError)."""
    from mech_regulator.scene import SceneError

    if not (math.isfinite(args.overspeed_trip) and args.overspeed_trip >= 0.0):
        raise SceneError(f"--overspeed-trip {args.overspeed_trip:g}: expected a speed >= 0 rad/s (0: none)")


def _main_job(scene, args) -> int:
    import importlib.util

    from mech_regulator.cli.report import output_folder
    from mech_regulator.scene import SceneError

    _check_overspeed_trip(args)
    if importlib.util.find_spec("rclpy") is None:
        raise SceneError(
            "the main job needs ROS 2's rclpy: source a ROS 2 installation, or "
            "pip install 'mech_regulator[ros]' for the wheels from the package index"
        )
    from mech_regulator.model import build_model
    from mech_regulator.nodes.launch import main_job
    from mech_regulator.nodes.outputs import default_recording

    if args.out is None:  # runs/<scene>-<time>.rrd, its folder made now (a given --out is checked by main)
        args.out = default_recording(scene.name)
        output_folder(args.out.parent, "the default output folder")
        _check_run_files(args.out)
    from mech_regulator.solvers import on_path_for_a_command
    from mech_regulator.solvers.cosim import cosimulation_refusal

    if args.controller == "external" and scene.governor is not None:
        scene = _without_governor(args)
    model = build_model(scene)
    reason = cosimulation_refusal(model)
    if reason is not None:
        raise SceneError(f"scene '{scene.name}' cannot be played by the nodes: {reason}")
    model = on_path_for_a_command(model, note, compile_now=True)  # compiled before the nodes start (warm.py)
    path = model.scene.solver.path  # decided once, for every node
    if path != scene.solver.path:
        args.overrides = [*(args.overrides or []), f"solver.path={path}"]
    if args.exchange_step is None:
        args.exchange_step = model.scene.solver.exchange_step
    if not 1e-6 <= args.exchange_step <= 1.0:
        raise SceneError(f"--exchange-step {args.exchange_step:g}: expected 1e-6 to 1 s")
    if args.duration is not None and not 0.0 < args.duration <= 1e7:
        raise SceneError(f"--duration {args.duration:g}: expected a simulated time in (0, 1e7] s")
    if not 1e-3 <= args.real_time_factor <= 1e3:
        raise SceneError(f"--real-time-factor {args.real_time_factor:g}: expected 0.001 to 1000")
    if args.peer_timeout is not None and not 0.01 <= args.peer_timeout <= 3600.0:
        raise SceneError(f"--peer-timeout {args.peer_timeout:g}: expected 0.01 to 3600 s")
    if args.domain_id is not None and not 0 <= args.domain_id <= 232:
        raise SceneError(f"--domain-id {args.domain_id}: expected 0 to 232")
    _check_bag(args.bag)
    if args.controller == "external" and args.time_mode != "lockstep":
        raise SceneError(
            "--controller external: only with --time-mode lockstep (in realtime any node may publish "
            "throttle to a governed scene's machine: docs/ros.md, Your own controller)"
        )
    return main_job(
        model,
        args.scene,
        args.overrides,
        args.exchange_step,
        args.time_mode,
        args.real_time_factor,
        args.overspeed_trip,
        args.out,
        args.domain_id,
        args.quiet,
        args.duration,
        args.coupling,
        STARTED,
        bag=args.bag,
        controller=args.controller,
        peer_timeout=args.peer_timeout,
    )


def _without_governor(args):
    """The scene of `run --controller external`: the user's controller drives the bare machine, so the scene's
    governor and the initial governor states it sets are left out (added to args.overrides, which the nodes read)."""
    from mech_regulator.nodes.controller import governor_left_out
    from mech_regulator.scene import load_scene

    left_out = governor_left_out(load_scene(args.scene, args.overrides))
    args.overrides = [*args.overrides, *left_out]
    note(
        f"--controller external: the scene's governor is left out ({', '.join(left_out)}); your controller drives "
        "the bare machine"
    )
    return load_scene(args.scene, args.overrides)


def _check_bag(folder: Path | None) -> None:
    """Refuse, before any work, a --bag folder that cannot be written (SceneError)."""
    from mech_regulator.scene import SceneError
    from mech_regulator.viz.bag import bag_refusal

    reason = bag_refusal(folder) if folder is not None else None
    if reason is not None:
        raise SceneError(reason)


def _check_run_files(recording: Path) -> None:
    """Refuse (SceneError) a recording for `run` whose files (nodes.outputs.run_files: it and the parameter file, log,
    summary and CSV next to it) cannot all be written, or one that is itself one of those files."""
    from mech_regulator.cli.report import check_output_paths
    from mech_regulator.nodes.outputs import run_files
    from mech_regulator.scene import SceneError

    files = run_files(recording)
    if recording in files[1:]:
        raise SceneError(
            f"--out '{recording}': expected the recording's file (.rrd): the run writes its own "
            f"{recording.suffix} file next to the recording, under that name"
        )
    check_output_paths(*files)


def _bench_accuracy(args) -> int:
    """bench accuracy: measure, then write runs.csv (also when interrupted), the PNGs, the recording and
    README.md into args.out."""
    import time

    from mech_regulator.bench.accuracy import run_benchmark, select_scenes
    from mech_regulator.bench.report import findings, markdown, write_runs_csv
    from mech_regulator.cli.report import bench_scenes_and_folder, check_output_paths
    from mech_regulator.scene import SceneError

    if args.jobs < 1:
        raise SceneError(f"--jobs {args.jobs}: expected at least 1 worker process")
    scenes = select_scenes(bench_scenes_and_folder(args.scenes, args.out, "startup,compressor"))
    check_output_paths(
        *(args.out / name for name in ("runs.csv", "README.md", "work_precision.rrd", "tolerance_proportionality.png"))
    )
    start = time.monotonic()
    benchmark = run_benchmark(scenes, args.quick, args.jobs, report=lambda line: print(line, flush=True))
    write_runs_csv(benchmark, args.out / "runs.csv")
    if benchmark.interrupted:
        print(f"mech-regulator: interrupted; the runs measured so far are in {args.out / 'runs.csv'}", file=sys.stderr)
        return EXIT_INTERRUPTED
    from mech_regulator.bench.effect_cost import effect_cost_section, effect_cost_table, measure_effect_costs
    from mech_regulator.viz.work_precision import write_pictures

    try:
        print("effect costs:", flush=True)
        costs = measure_effect_costs(1 if args.quick else 3, progress=lambda label: print(f"  {label}", flush=True))
        write_pictures(benchmark, args.out)
        (args.out / "README.md").write_text(
            markdown(benchmark, time.monotonic() - start) + effect_cost_section(costs), encoding="utf-8"
        )
    except KeyboardInterrupt:
        print(
            f"mech-regulator: interrupted while writing the pictures; every run is in {args.out / 'runs.csv'}",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    for result in benchmark.scenes:
        print(f"{result.bench.name}:", *findings(result), sep="\n")
    print("effect costs (DOP853, rtol 1e-8):", effect_cost_table(costs), sep="\n")
    print(
        f"wrote {args.out}: runs.csv, README.md, work_precision_<scene>.png, tolerance_proportionality.png, "
        f"work_precision.rrd ({time.monotonic() - start:.0f} s)"
    )
    return 0


def _sample_columns(model, trajectory):
    """The output columns at the scene's sample rate, SAMPLE_CHUNK samples at a time (a generator: a long run's CSV
    is written without all its rows in memory)."""
    times = trajectory.samples(model.scene.solver.sample_rate)
    for first in range(0, times.size, SAMPLE_CHUNK):
        chunk = times[first : first + SAMPLE_CHUNK]
        yield model.columns(chunk, trajectory(chunk))


def _samples(model, trajectory) -> tuple[np.ndarray, np.ndarray]:
    """Output sample times at the scene's sample rate and the states there."""
    times = trajectory.samples(model.scene.solver.sample_rate)
    return times, trajectory(times)


if __name__ == "__main__":
    sys.exit(main())
