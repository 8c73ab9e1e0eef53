"""The `mech-regulator` command: simulate, describe and list scenes, analyse governors and engines, print the
scene schema.

This module runs the command the parser (cli/parser.py) read; each family of commands has its module: simulate.py
(`simulate`, monolithic or co-simulated), main_job.py (`run`, the ROS nodes), analyses.py (`governor`, `coupling`,
`kinematics`, `engine`), bench_accuracy.py and the bench_*.py modules (`bench`), flywheel.py, sweep.py,
structure.py. A user's mistake in a scene or an option ends in a message and exit code 2, never a traceback; a run
that fails or is interrupted still writes what it computed.
"""

from __future__ import annotations

import os
import sys

from mech_regulator.cli.analyses import run_engine, run_governor, run_kinematics, run_required_coupling
from mech_regulator.cli.bench_accuracy import run_bench_accuracy
from mech_regulator.cli.main_job import check_run_files, run_main_job
from mech_regulator.cli.parser import build_parser
from mech_regulator.cli.report.terminal import terminal_text
from mech_regulator.cli.simulate import run_simulate

EXIT_BAD_INPUT = 2


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
            from mech_regulator.cli.server_client import server_command

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
        from mech_regulator.cli.report.outputs import check_outputs
        from mech_regulator.scene import load_scene

        if args.command != "run":  # every output checked before the scene is read (it may compile a linkage)
            check_outputs(args, *(getattr(args, name, None) for name in ("out", "record", "scene_out")))
        elif args.out is not None:
            check_run_files(args.out)
        if args.command == "describe":
            from mech_regulator import cache
            from mech_regulator.cli.report.machine_text import describe
            from mech_regulator.model import build_model

            with cache.run_uncompiled():  # describing needs no compiled code (cache.py)
                print(describe(build_model(load_scene(args.scene, args.overrides))))
            return 0
        scene = load_scene(args.scene, args.overrides)
        if args.command == "governor":
            return run_governor(scene, args)
        if args.command == "run":
            return run_main_job(scene, args)
        if args.command == "coupling":
            return run_required_coupling(scene, args)
        if args.command in ("kinematics", "structure"):  # they build no machine: the mechanisms' checks here
            from mech_regulator.mechanisms.checks import refuse_unbuildable

            refuse_unbuildable(scene)
        if args.command == "kinematics":
            return run_kinematics(scene, args)
        if args.command == "structure":
            from mech_regulator.cli.structure import run_structure

            return run_structure(scene, args)
        if args.command == "engine":
            return run_engine(scene, args)
        return run_simulate(scene, args)
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
    return run_bench_accuracy(args)


def _list_scenes() -> int:
    """scenes: each bundled scene's name and the first sentence of its description, read from its file (and the
    files it derives from) without validating it: listing checks and compiles nothing."""
    from mech_regulator.scene import bundled_scenes
    from mech_regulator.scene.loading import read_scene_data

    for name, path in bundled_scenes().items():
        description = " ".join(str(read_scene_data(path).get("description") or "").split())
        print(f"{name:<26} {description.split('. ')[0]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
