"""The `simulate` command in this process: the monolithic run (run_simulate) or, with --exchange-step, the
lockstep co-simulation of the nodes; its summary, CSV, picture, recording and bag. The checks of --bag and
--overspeed-trip serve `run` (main_job.py) too."""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from mech_regulator.cli.report.terminal import note, terminal_text
from mech_regulator.errors import EXIT_INACCURATE, EXIT_INTERRUPTED, EXIT_RUN_FAILED

if TYPE_CHECKING:
    import numpy as np

    from mech_regulator.cli.report.outputs import OutputSize


SAMPLE_CHUNK = 200_000  # output samples whose columns simulate computes and writes at once (_sample_columns)


def run_simulate(scene, args) -> int:
    """simulate: the run (monolithic, or co-simulated with --exchange-step), its summary and outputs; the exit code."""
    from mech_regulator.analysis import simulate_streamed, summarise
    from mech_regulator.analysis.self_check import self_checks
    from mech_regulator.cli.report.data import to_json, write_csv
    from mech_regulator.cli.report.machine_text import format_summary
    from mech_regulator.cli.report.outputs import OutputWriter
    from mech_regulator.cli.report.terminal import progress_bar
    from mech_regulator.model import build_model
    from mech_regulator.scene import SceneError
    from mech_regulator.solvers import on_path_for_a_command
    from mech_regulator.solvers.advice import stiffness_advice

    if args.exchange_tolerance is not None and args.exchange_step is None:
        raise SceneError(
            f"--exchange-tolerance {args.exchange_tolerance:g}: the adaptive step is the co-simulation's; expected "
            "--exchange-step H with it (its steps run from H/16 to 4 H)"
        )
    if args.overspeed_trip and args.exchange_step is None:
        raise SceneError(
            f"--overspeed-trip {args.overspeed_trip:g}: the trip acts at the exchanges of the "
            "co-simulation; expected --exchange-step H with it (the monolithic run has no trip)"
        )
    check_bag(args.bag)
    model = build_model(scene)
    if args.exchange_step is None:  # the co-simulation's outputs are checked with its exchange step (_cosimulate)
        rate = scene.solver.sample_rate
        check_sample_space(
            model,
            scene.scenario.duration * rate + 1,
            f"{scene.scenario.duration:g} s at solver.sample_rate {rate:g} Hz",
            "a shorter scenario.duration, a lower solver.sample_rate, or the outputs in a folder with more free space",
            _simulate_outputs(args, digits=12),
        )
    model = on_path_for_a_command(model, note)
    if args.exchange_step is not None:
        return _cosimulate(model, args)
    advice = stiffness_advice(model)
    if advice is not None:
        print(f"mech-regulator: note: {advice}", file=sys.stderr)
    duration = scene.scenario.duration
    # they read the output samples
    sampled = any(output is not None for output in (args.out, args.plot, args.record, args.bag))
    with progress_bar(duration, args.quiet, f"simulating {scene.name or args.scene}") as bar:
        trajectory, streamed = simulate_streamed(model, lambda t: bar.update(min(t, duration) - bar.n), samples=sampled)
        bar.update(min(trajectory.t_end, duration) - bar.n)
    summary = summarise(model, trajectory, streamed)
    checks = summary["self_checks"] = self_checks(model, summary, trajectory, streamed.mode_log if streamed else None)
    if checks and summary["status"] == "complete":
        summary["status"] = "inaccurate"
    if not trajectory.interpolants:
        args.out = args.plot = args.record = None  # nothing to write
    outputs = OutputWriter(summary)
    outputs.write("csv", args.out, lambda path: write_csv(path, _sample_columns(model, trajectory, streamed)))
    if args.plot is not None:
        from mech_regulator.viz.plots import plot_run

        outputs.write(
            "plot",
            args.plot,
            lambda path: plot_run(
                model, trajectory, summary, path, streamed.samples(trajectory) if streamed is not None else None
            ),
        )
    if args.record is not None:
        from mech_regulator.viz.recording import record_run

        outputs.write(
            "recording",
            args.record,
            lambda path: record_run(
                model,
                *_samples(model, trajectory, streamed),
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
                path,
                model,
                *_samples(model, trajectory, streamed),
                status=trajectory.status,
                message=trajectory.message,
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
    from mech_regulator.cli.report.data import to_json, write_csv
    from mech_regulator.cli.report.machine_text import format_cosimulation_summary
    from mech_regulator.cli.report.outputs import OutputWriter
    from mech_regulator.cli.report.terminal import progress_bar
    from mech_regulator.scene import SceneError
    from mech_regulator.solvers.cosim import cosimulate

    if not 1e-6 <= args.exchange_step <= 1.0:
        raise SceneError(f"--exchange-step {args.exchange_step:g}: expected 1e-6 to 1 s")
    check_overspeed_trip(args)
    duration = model.scene.scenario.duration
    check_sample_space(
        model,
        exchange_count(duration, args.exchange_step, args.exchange_tolerance),
        f"{duration:g} s at --exchange-step {args.exchange_step:g} s",
        "a shorter scenario.duration, a longer --exchange-step, or the outputs in a folder with more free space",
        _simulate_outputs(args, digits=17),
    )
    with progress_bar(duration, args.quiet, f"co-simulating {model.scene.name or args.scene}") as bar:
        run = cosimulate(
            model,
            args.exchange_step,
            args.overspeed_trip,
            progress=lambda t: bar.update(min(t, duration) - bar.n),
            coupling=args.coupling,
            exchange_tolerance=args.exchange_tolerance,
        )
    summary = summarise_cosimulation(model, run, args.exchange_step, args.coupling, args.exchange_tolerance)
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


def check_overspeed_trip(args) -> None:
    """Refuse a --overspeed-trip that is not a speed >= 0 rad/s (SceneError)."""
    from mech_regulator.scene import SceneError

    if not (math.isfinite(args.overspeed_trip) and args.overspeed_trip >= 0.0):
        raise SceneError(f"--overspeed-trip {args.overspeed_trip:g}: expected a speed >= 0 rad/s (0: none)")


def exchange_count(duration: float, exchange_step: float, exchange_tolerance: float | None) -> float:
    """The exchanges of a co-simulation over duration [s] at exchange_step [s], at most: with an exchange tolerance,
    at the adaptive step's smallest (cosim.ADAPTIVE_HALVINGS); the first exchange at t = 0 included."""
    from mech_regulator.solvers.cosim import ADAPTIVE_HALVINGS

    smallest = exchange_step / 2**ADAPTIVE_HALVINGS if exchange_tolerance is not None else exchange_step
    return duration / smallest + 1


def check_sample_space(
    model,
    samples: float,
    what: str,
    way_out: str,
    outputs: tuple[tuple[Path, int] | None, tuple[Path, float] | None, Path | None],
    more_columns: int = 0,
    extra: list[OutputSize] | None = None,
) -> None:
    """Refuse, before the run, outputs (the CSV with its digits, the recording with its bytes a sample and column, the
    bag; None: not asked: outputs.output_sizes) of
    `samples` rows of the model's output columns (and `more_columns`) that do not fit on their disks, or announce them
    when large (outputs.check_free_space); `extra`: other outputs' sizes; `what` says the rows' span and rate,
    `way_out` how to write less."""
    from mech_regulator.cli.report.outputs import check_free_space, output_sizes

    if outputs == (None, None, None) and not extra:
        return  # nothing written per row
    columns = output_column_count(model) + more_columns
    sizes = output_sizes(columns, samples, *outputs) + (extra or [])
    check_free_space(sizes, f"{samples:.3g} rows of {columns} columns ({what})", way_out)


def _simulate_outputs(args, digits: int) -> tuple[tuple[Path, int] | None, tuple[Path, float] | None, Path | None]:
    """simulate's outputs as check_sample_space takes them: its CSV written with `digits` significant digits."""
    from mech_regulator.cli.report.outputs import RECORDING_BYTES_PER_COLUMN

    return (
        (args.out, digits) if args.out is not None else None,
        (args.record, RECORDING_BYTES_PER_COLUMN) if args.record is not None else None,
        args.bag,
    )


def output_column_count(model) -> int:
    """The number of output columns of the model (model.columns at its initial state)."""
    import numpy as np

    return len(model.columns(np.zeros(1), model.initial_state()[:, None]))


def check_bag(folder: Path | None) -> None:
    """Refuse, before any work, a --bag folder that cannot be written (SceneError)."""
    from mech_regulator.scene import SceneError
    from mech_regulator.viz.bag import bag_refusal

    reason = bag_refusal(folder) if folder is not None else None
    if reason is not None:
        raise SceneError(reason)


def _sample_columns(model, trajectory, streamed=None):
    """The output columns at the scene's sample rate, SAMPLE_CHUNK samples at a time (a generator: a long run's CSV
    is written without all its columns in memory); of a streamed run (streamed: its RunDigest), at the states it
    sampled."""
    if streamed is not None:
        times, states = streamed.samples(trajectory)
        for first in range(0, times.size, SAMPLE_CHUNK):
            part = slice(first, first + SAMPLE_CHUNK)
            yield model.columns(times[part], states[:, part])
        return
    times = trajectory.samples(model.scene.solver.sample_rate)
    for first in range(0, times.size, SAMPLE_CHUNK):
        chunk = times[first : first + SAMPLE_CHUNK]
        yield model.columns(chunk, trajectory(chunk))


def _samples(model, trajectory, streamed=None) -> tuple[np.ndarray, np.ndarray]:
    """Output sample times at the scene's sample rate and the states there; of a streamed run (streamed: its
    RunDigest), those it sampled."""
    if streamed is not None:
        return streamed.samples(trajectory)
    times = trajectory.samples(model.scene.solver.sample_rate)
    return times, trajectory(times)
