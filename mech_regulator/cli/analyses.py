"""The commands that analyse a scene rather than run it: `governor` (statics and stability), `coupling` (the
inverse problem's coupling characteristic), `kinematics` (the joints' motion over one turn) and `engine` (an
engine at constant speed); each prints its answer, or JSON, and writes its CSV and pictures."""

from __future__ import annotations

import math

from mech_regulator.cli.report.terminal import terminal_text


def run_governor(scene, args) -> int:
    """governor: the statics and stability of the scene's governor, printed (or JSON), and optionally a PNG."""
    from mech_regulator.analysis import analyse_governor
    from mech_regulator.cli.report.analysis_text import format_governor
    from mech_regulator.cli.report.data import to_json
    from mech_regulator.cli.report.outputs import OutputWriter
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


def run_required_coupling(scene, args) -> int:
    """coupling: solve the inverse problem and write the table, the scene that uses it and the picture."""
    import dataclasses

    import yaml

    from mech_regulator.analysis import required_coupling
    from mech_regulator.cli.report.analysis_text import format_required_coupling
    from mech_regulator.cli.report.data import to_json, write_csv
    from mech_regulator.cli.report.outputs import OutputWriter, wrote_lines
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
        data["name"] = f"{scene.name or 'scene'}run_required_coupling"
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


def run_kinematics(scene, args) -> int:
    """kinematics: the joints' motion over one turn at constant crank speed; summary, CSV and PNG."""
    from mech_regulator.analysis.kinematics import (
        kinematics_summary,
        kinematics_table,
        reactions_summary,
        reactions_table,
        reactions_unavailable,
    )
    from mech_regulator.cli.report.analysis_text import format_kinematics
    from mech_regulator.cli.report.data import to_json, write_csv
    from mech_regulator.cli.report.outputs import OutputWriter
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


def run_engine(scene, args) -> int:
    """engine: the analysis of an engine scene at constant speed, printed, and optionally a PNG and a CSV."""
    from mech_regulator.analysis.engine import engine_curve_columns, engine_parts, engine_report
    from mech_regulator.cli.report.analysis_text import format_engine
    from mech_regulator.cli.report.data import to_json, write_csv
    from mech_regulator.cli.report.outputs import OutputWriter
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
