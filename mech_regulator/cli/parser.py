"""The `mech-regulator` command's argument parser: each command and its options (the families with a module of
their own add theirs: add_*_command).

The parser is built from light modules only (the standard library and the cli's own parser builders), so that
`--help` and a mistyped option answer at once; each command imports what it needs (numpy, scipy, numba,
pydantic, matplotlib, rerun) inside its function. test/test_cli_startup.py checks it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from mech_regulator import __version__
from mech_regulator.cli.bench_long import add_bench_long_command
from mech_regulator.cli.bench_soak import add_bench_soak_command
from mech_regulator.cli.bench_speed import (
    add_bench_first_run_command,
    add_bench_speed_command,
    add_bench_startup_command,
)
from mech_regulator.cli.flywheel import add_flywheel_command
from mech_regulator.cli.structure import add_structure_command
from mech_regulator.cli.sweep import add_sweep_command
from mech_regulator.nodes.controller import CONTROLLERS

COUPLING_HELP = (
    "how machine and governor see each other over an exchange step: hold (each holds the other's last "
    "value, first order in H), waveform (the governor follows the machine's speed over the step, the "
    "machine the throttle extrapolated from the governor's last answers) or corrected (waveform's "
    "prediction, then the step done again with the governor's own throttle over it, the governor "
    "following the machine's speed sampled every 1.25 ms, a ramp of the load followed; the default; "
    "docs/ros.md)"
)
TOLERANCE_HELP = (
    "an adaptive exchange step instead of the fixed H: each step set by the corrected coupling's predictor miss "
    "(relative to the largest speed) against this tolerance, from H/16 to 4 H, every load change an exchange time; "
    "it spends fewer exchanges than the fixed step on machines without a firing ripple, more on the bundled engines "
    "(docs/speed.md, 'The adaptive step tried again')"
)


def build_parser() -> argparse.ArgumentParser:
    """The parser of the `mech-regulator` command line: every command and its options."""
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
        "--exchange-tolerance", type=float, metavar="TOL", help="with --exchange-step: " + TOLERANCE_HELP
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
    main_job.add_argument("--exchange-tolerance", type=float, metavar="TOL", help=TOLERANCE_HELP)
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
