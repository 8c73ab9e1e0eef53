"""The `mech-regulator` command: simulate, describe and list scenes, print the scene schema.

A user's mistake in a scene or an option ends in a message and exit code 2, never a traceback; a run
that fails or is interrupted still writes what it computed.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

import numpy as np

from mech_regulator import __version__
from mech_regulator.scene import SceneError, bundled_scenes, load_scene
from mech_regulator.scene.reference import schema_json, schema_markdown

EXIT_BAD_INPUT = 2
EXIT_RUN_FAILED = 1
EXIT_INTERRUPTED = 130


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="mech-regulator", description="Real motion of machines and the regulation "
                                     "of their speed: simulate a machine described in a scene file.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def scene_command(name: str, help_text: str) -> argparse.ArgumentParser:
        sub = commands.add_parser(name, help=help_text, description=help_text)
        sub.add_argument("scene", metavar="SCENE", help="scene file, or the name of a bundled scene (see 'scenes')")
        sub.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                         help="change a scene value, e.g. --set machine.flywheel.inertia=0.5 "
                              "(list items by index: machine.loads.0.coefficient=0.02); repeatable")
        return sub

    simulate = scene_command("simulate", "simulate a scene and print its summary")
    simulate.add_argument("--out", type=Path, help="write the sampled run as CSV (t, phi, omega, epsilon, J, moments, ...)")
    simulate.add_argument("--plot", type=Path, help="write a PNG picture of the run")
    simulate.add_argument("--json", action="store_true", help="print the summary as JSON")
    simulate.add_argument("--quiet", action="store_true", help="no progress bar")
    scene_command("describe", "print the effects, state vector and solver a scene uses, without running it")
    governor = scene_command("governor", "statics and stability of a governed scene: static characteristic, "
                                         "statism, insensitivity, operating points, droop, eigenvalues, "
                                         "Vyshnegradsky A and B, Floquet multipliers")
    governor.add_argument("--plot", type=Path, help="write a PNG picture of the statics and stability")
    governor.add_argument("--json", action="store_true", help="print the analysis as JSON")
    schema = commands.add_parser("schema", help="print the JSON Schema of scene files (for editors)")
    schema.add_argument("--format", choices=("json", "markdown"), default="json",
                        help="json: the JSON Schema; markdown: the key tables of docs/scenes.md")
    commands.add_parser("scenes", help="list the bundled scenes")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of `mech-regulator` and `python -m mech_regulator`; returns the exit code."""
    args = build_parser().parse_args(argv)
    try:
        if args.command == "schema":
            print(schema_json() if args.format == "json" else schema_markdown(), end="")
            return 0
        if args.command == "scenes":
            return _list_scenes()
        scene = load_scene(args.scene, args.overrides)
        if args.command == "describe":
            from mech_regulator.model import build_model
            from mech_regulator.cli.report import describe

            print(describe(build_model(scene)))
            return 0
        if args.command == "governor":
            return _governor(scene, args)
        return _simulate(scene, args)
    except SceneError as error:
        print(f"mech-regulator: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # the reader went away (`... | head`): not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


def _list_scenes() -> int:
    for name, path in bundled_scenes().items():
        description = " ".join((load_scene(str(path)).description or "").split())
        print(f"{name:<26} {description.split('. ')[0]}")
    return 0


def _simulate(scene, args) -> int:
    from tqdm import tqdm

    from mech_regulator.analysis import summarise
    from mech_regulator.cli.report import format_summary
    from mech_regulator.model import build_model
    from mech_regulator.solvers import simulate

    _check_outputs(args, args.out)
    model = build_model(scene)
    duration = scene.scenario.duration
    with tqdm(total=duration, unit="s sim", disable=True if args.quiet else None, file=sys.stderr,
              bar_format="{l_bar}{bar}| {n:.3g}/{total:.3g} s simulated [{elapsed}<{remaining}]") as bar:
        trajectory = simulate(model, progress=lambda t: bar.update(min(t, duration) - bar.n))
        bar.update(min(trajectory.t_end, duration) - bar.n)
    summary = summarise(model, trajectory)
    if not trajectory.interpolants:
        args.out = args.plot = None  # nothing to write
    if args.out is not None:
        columns = model.columns(*_samples(model, trajectory))
        np.savetxt(args.out, np.column_stack(list(columns.values())), delimiter=",", header=",".join(columns),
                   comments="", fmt="%.12g")
        summary["csv"] = str(args.out)
    if args.plot is not None:
        from mech_regulator.viz.plots import plot_run

        plot_run(model, trajectory, summary, args.plot)
        summary["plot"] = str(args.plot)
    print(_to_json(summary) if args.json else format_summary(model, summary))
    if trajectory.status == "failed":
        print(f"mech-regulator: {trajectory.message}", file=sys.stderr)
        return EXIT_RUN_FAILED
    if trajectory.status == "interrupted":
        print(f"mech-regulator: {trajectory.message}; the outputs hold the run up to there", file=sys.stderr)
        return EXIT_INTERRUPTED
    return 0


def _check_outputs(args, *others: Path | None) -> None:
    """Give the plot a .png suffix and refuse, before any work, output paths that cannot be written."""
    if args.plot is not None and not args.plot.suffix:
        args.plot = args.plot.with_suffix(".png")
    for path in (*others, args.plot):
        if path is not None and (path.is_dir() or not path.parent.is_dir()):
            problem = "it is a folder" if path.is_dir() else f"the folder '{path.parent}' does not exist"
            raise SceneError(f"cannot write '{path}': {problem}")


def _governor(scene, args) -> int:
    from mech_regulator.analysis import analyse_governor
    from mech_regulator.cli.report import format_governor
    from mech_regulator.model import build_model

    if scene.governor is None:
        raise SceneError(f"scene '{scene.name}' has no governor: add a 'governor:' section (see docs/scenes.md)")
    _check_outputs(args)
    model = build_model(scene)
    analysis = analyse_governor(model)
    if args.plot is not None:
        from mech_regulator.viz.plots import plot_governor

        plot_governor(model, analysis, args.plot)
        analysis["plot"] = str(args.plot)
    print(_to_json(analysis) if args.json else format_governor(analysis))
    return 0


def _samples(model, trajectory) -> tuple[np.ndarray, np.ndarray]:
    """Output sample times at the scene's sample rate and the states there."""
    times = trajectory.samples(model.scene.solver.sample_rate)
    return times, trajectory(times)


def _to_json(data) -> str:
    """Strict JSON (no NaN or Infinity, which jq and JavaScript reject): non-finite numbers become null."""
    def finite(value):
        if isinstance(value, dict):
            return {key: finite(item) for key, item in value.items()}
        if isinstance(value, (list, tuple)):
            return [finite(item) for item in value]
        if isinstance(value, (np.floating, np.integer)):
            value = value.item()
        if isinstance(value, float) and not math.isfinite(value):
            return None
        return value

    return json.dumps(finite(data), indent=2, allow_nan=False)


if __name__ == "__main__":
    sys.exit(main())
