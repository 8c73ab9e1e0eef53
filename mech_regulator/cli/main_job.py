"""The `run` command: the main job, the scene played by the ROS nodes in lockstep or real time (nodes/launch.py),
its options checked before any node starts."""

from __future__ import annotations

import os
from pathlib import Path

from mech_regulator.cli.report.terminal import note
from mech_regulator.cli.simulate import check_bag, check_overspeed_trip, check_sample_space, exchange_count
from mech_regulator.cli.start import STARTED


def run_main_job(scene, args) -> int:
    """run: the options checked, the model built and put on its path, then the nodes started (nodes.launch.main_job);
    the exit code."""
    import importlib.util

    from mech_regulator.cli.report.outputs import output_folder
    from mech_regulator.scene import SceneError

    check_overspeed_trip(args)
    if importlib.util.find_spec("rclpy") is None:
        raise SceneError(
            "the main job needs ROS 2's rclpy: source a ROS 2 installation, or "
            "pip install 'mech_regulator[ros]' for the wheels from the package index"
        )
    from mech_regulator.model import build_model
    from mech_regulator.nodes.launch import claim_run, main_job
    from mech_regulator.nodes.outputs import default_recording

    if args.domain_id is not None and not 0 <= args.domain_id <= 232:
        raise SceneError(f"--domain-id {args.domain_id}: expected 0 to 232")
    args.domain_id = claim_run(args.domain_id)  # another run on the domain refused before anything compiles

    if args.out is None:  # runs/<scene>-<time>.rrd, its folder made now (a given --out is checked by main)
        args.out = default_recording(scene.name)
        output_folder(args.out.parent, "the default output folder")
        check_run_files(args.out)
    from mech_regulator.solvers import on_path_for_a_command
    from mech_regulator.solvers.cosim import cosimulation_refusal

    if args.controller == "external" and scene.governor is not None:
        scene = _without_governor(args)
    model = build_model(scene)
    reason = cosimulation_refusal(model)
    if reason is not None:
        raise SceneError(f"scene '{scene.name}' cannot be played by the nodes: {reason}")
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
    check_bag(args.bag)
    if args.controller == "external" and args.time_mode != "lockstep":
        raise SceneError(
            "--controller external: only with --time-mode lockstep (in realtime any node may publish "
            "throttle to a governed scene's machine: docs/ros.md, Your own controller)"
        )
    _check_run_space(model, args)
    model = on_path_for_a_command(model, note, compile_now=True)  # compiled before the nodes start (warm.py)
    path = model.scene.solver.path  # decided once, for every node
    if path != scene.solver.path:
        args.overrides = [*(args.overrides or []), f"solver.path={path}"]
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
        exchange_tolerance=args.exchange_tolerance,
        controller=args.controller,
        peer_timeout=args.peer_timeout,
    )


def _check_run_space(model, args) -> None:
    """Refuse, before the nodes start, a run whose recording, CSV (the columns of simulate --out with the applied
    throttle and load, 17 digits), bag and recorder's spool would not fit on their disks, or announce them when large
    (simulate.check_sample_space): one row an exchange."""
    from mech_regulator.cli.report.outputs import RUN_RECORDING_BYTES_PER_COLUMN, SPOOL_BYTES_PER_EXCHANGE, OutputSize

    duration = args.duration or model.scene.scenario.duration
    spool_folder = Path(os.path.realpath(args.out)).parent
    exchanges = exchange_count(duration, args.exchange_step, args.exchange_tolerance)
    check_sample_space(
        model,
        exchanges,
        f"{duration:g} s at --exchange-step {args.exchange_step:g} s"
        + (", at the adaptive step's smallest" if args.exchange_tolerance is not None else ""),
        "a shorter --duration, a longer --exchange-step, or --out (and --bag) in a folder with more free space",
        ((args.out.with_suffix(".csv"), 17), (args.out, RUN_RECORDING_BYTES_PER_COLUMN), args.bag),
        more_columns=2,
        extra=[OutputSize("the recorder's spool", spool_folder, exchanges * SPOOL_BYTES_PER_EXCHANGE)],
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


def check_run_files(recording: Path) -> None:
    """Refuse (SceneError) a recording for `run` whose files (nodes.outputs.run_files: it and the parameter file, log,
    summary and CSV next to it) cannot all be written, or one that is itself one of those files."""
    from mech_regulator.cli.report.outputs import check_output_paths
    from mech_regulator.nodes.outputs import run_files
    from mech_regulator.scene import SceneError

    files = run_files(recording)
    if recording in files[1:]:
        raise SceneError(
            f"--out '{recording}': expected the recording's file (.rrd): the run writes its own "
            f"{recording.suffix} file next to the recording, under that name"
        )
    check_output_paths(*files)
