"""`mech-regulator flywheel`: size a flywheel for a permitted coefficient of speed fluctuation [delta].

A thin layer over analysis.flywheel: it reads [delta] (--delta, --class or the scene's
analysis.permitted_delta), runs the design with a progress bar over the simulated dynamic periods, and prints
the three answers side by side (text or JSON), with a PNG and a Rerun recording on request.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path

from mech_regulator.cli.report.data import to_json
from mech_regulator.cli.report.outputs import OutputWriter, check_outputs, wrote_lines
from mech_regulator.cli.report.terminal import note, progress_bar, terminal_text


def add_flywheel_command(scene_command: Callable[..., argparse.ArgumentParser]) -> None:
    """The `flywheel` subcommand and its options; scene_command (cli.parser) makes a subcommand with the SCENE and
    --set arguments of every scene command (SCENE optional here: --classes needs none)."""
    text = (
        "size a flywheel for a permitted coefficient of speed fluctuation [delta]: the energy-swing formula, "
        "the Wittenbauer construction (exact numerical form) and the flywheel refined by simulation, each "
        "checked by simulating the steady motion"
    )
    parser = scene_command("flywheel", text, scene_required=False)
    parser.add_argument(
        "--delta",
        metavar="DELTA",
        help="permitted (omega_max - omega_min) / omega_m, as a fraction (1/80) or a number (0.0125); "
        "default: the scene's analysis.permitted_delta",
    )
    parser.add_argument(
        "--class",
        dest="machine_class",
        metavar="CLASS",
        help="take the strictest [delta] of a machine class (see --classes)",
    )
    parser.add_argument("--classes", action="store_true", help="list the machine classes and their [delta] and exit")
    parser.add_argument(
        "--omega-m",
        type=float,
        metavar="OMEGA",
        help="design mean speed [rad/s] for moments independent of omega (default: the mean speed of "
        "the scene's steady motion through its initial state; a machine whose moments read "
        "omega sets its own)",
    )
    parser.add_argument(
        "--ratio",
        type=float,
        metavar="N",
        help="put the flywheel on a shaft turning at N times the crank speed: J_x = J_fw / N^2 "
        "(default: the ratio of the scene's flywheel, else 1)",
    )
    parser.add_argument(
        "--plot",
        type=Path,
        help="write a PNG: dE(phi), the E(J) curve with the tangent rays, "
        "the construction, omega(phi) before and after",
    )
    parser.add_argument("--record", type=Path, metavar="DESIGN.rrd", help="write a Rerun recording of the same")
    parser.add_argument("--json", action="store_true", help="print the design as JSON")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run_flywheel(args: argparse.Namespace) -> int:
    """Run the command; a user's mistake raises SceneError (exit 2 in cli.main)."""
    from mech_regulator.analysis.flywheel import design_flywheel
    from mech_regulator.scene import SceneError, load_scene

    if args.classes:
        print(format_classes())
        return 0
    if args.scene is None:
        raise SceneError(
            "flywheel: give a SCENE (a file or a bundled scene's name), or --classes to list the machine classes"
        )
    check_outputs(args, args.record)
    from mech_regulator.model import build_model
    from mech_regulator.solvers import on_path_for_a_command

    scene = on_path_for_a_command(build_model(load_scene(args.scene, args.overrides)), note).scene
    delta, delta_source = requested_delta(args.delta, args.machine_class, scene.analysis.permitted_delta)
    with progress_bar(
        None, args.quiet, f"flywheel for {scene.name or args.scene}", quantity=None, unit="dynamic periods simulated"
    ) as bar:

        def progress(stage: str) -> None:
            bar.set_description_str(stage, refresh=False)
            bar.update(1)

        design = design_flywheel(scene, delta, args.omega_m, args.ratio, progress)
    data = design_data(design, delta_source)
    outputs = OutputWriter(data)
    if args.plot is not None or args.record is not None:
        from mech_regulator.viz.flywheel import plot_flywheel, record_flywheel

        outputs.write("plot", args.plot, lambda path: plot_flywheel(design, path))
        outputs.write("recording", args.record, lambda path: record_flywheel(design, path))
    print(to_json(data) if args.json else format_flywheel(data))
    return outputs.exit_code(0)


def parse_delta(text: str) -> float:
    """[delta] from '1/80' or '0.0125' (fractions.Fraction reads both); SceneError unless 0 < delta < 1."""
    from mech_regulator.scene import SceneError

    try:
        value = Fraction(text.strip())
    except (ValueError, ZeroDivisionError):
        value = None
    if value is None or not 0 < value < 1:
        raise SceneError(
            f"--delta '{text}': expected a coefficient of speed fluctuation between 0 and 1, as a "
            "fraction (1/80) or a number (0.0125)"
        )
    return float(value)


def requested_delta(delta: str | None, machine_class: str | None, permitted: float | None) -> tuple[float, str]:
    """[delta] and where it comes from: --delta, else --class (its strictest value), else the scene's
    analysis.permitted_delta."""
    from mech_regulator.analysis.flywheel import MACHINE_CLASSES
    from mech_regulator.scene import SceneError

    if delta is not None and machine_class is not None:
        raise SceneError(f"--delta {delta} and --class {machine_class}: give one of them, not both")
    if delta is not None:
        return parse_delta(delta), "--delta"
    if machine_class is not None:
        if machine_class not in MACHINE_CLASSES:
            raise SceneError(
                f"--class '{machine_class}': no such machine class; expected one of "
                f"{', '.join(MACHINE_CLASSES)} (--classes lists their [delta])"
            )
        chosen = MACHINE_CLASSES[machine_class]
        return chosen.strictest, (
            f"the strictest of {chosen.description} (--class {chosen.name}: "
            f"{_fraction(chosen.loosest)} to {_fraction(chosen.strictest)})"
        )
    if permitted is None:
        raise SceneError(
            "no [delta]: give --delta (e.g. 1/80), --class (see --classes) or the scene's analysis.permitted_delta"
        )
    if not permitted < 1.0:
        raise SceneError(f"analysis.permitted_delta = {permitted:g}: expected below 1 for a flywheel design")
    return permitted, "the scene's analysis.permitted_delta"


def format_classes() -> str:
    """The table of machine classes and their permitted [delta]."""
    from mech_regulator.analysis.flywheel import MACHINE_CLASSES

    lines = [
        "permitted coefficient of speed fluctuation [delta] by machine class (docs/theory.md §3.1: the "
        "common textbook ranges; source 000's list is garbled); --class NAME takes the strictest value:"
    ]
    for machine in MACHINE_CLASSES.values():
        lines.append(
            f"  {machine.name:<14} {machine.description:<30} {_fraction(machine.loosest)} to "
            f"{_fraction(machine.strictest)}"
        )
    return "\n".join(lines)


def design_data(design, delta_source: str) -> dict:
    """The design as plain data (JSON-ready): the request, the machine's energy diagram in numbers, the three
    flywheels (reduced to the crank and on the ratio-N shaft) with the delta each gives in simulation, and the
    Wittenbauer construction."""
    construction = design.construction
    diagram = design.diagram

    def proposal(name: str, flywheel: float | None) -> dict | None:
        if flywheel is None:
            return None
        run = design.runs.get(name)
        speeds = run.speeds if run is not None else None
        return {
            "flywheel": flywheel,
            "on_shaft": design.on_shaft(flywheel) if flywheel >= 0.0 else None,
            "simulated": None
            if speeds is None
            else {
                "delta": speeds.delta,
                "omega_m": speeds.omega_m,
                "omega_max": speeds.omega_max,
                "omega_min": speeds.omega_min,
                "omega_at_phi_0": run.omega_start,
                "relative_error": speeds.delta / design.delta - 1.0,
            },
        }

    return {
        "scene": design.scene,
        "delta": design.delta,
        "delta_source": delta_source,
        "omega_m": design.omega_m,
        "omega_m_source": design.omega_m_source,
        "speed_dependent": design.speed_dependent,
        "ratio": design.ratio,
        "dynamic_period_rad": float(diagram.phi[-1]),
        "inertia_min": float(diagram.inertia.min()),
        "inertia_max": float(diagram.inertia.max()),
        "inertia_mean": diagram.mean_inertia,
        "energy_swing_max": diagram.swing,
        "methods": {
            "energy_swing": proposal("energy_swing", design.energy_swing),
            "wittenbauer": proposal("wittenbauer", design.wittenbauer),
            "refined": proposal("refined", design.refined),
        },
        "without_flywheel": proposal("none", 0.0),
        "scene_flywheel": proposal("scene", design.scene_flywheel),
        "construction": {
            "k_max": construction.k_max,
            "k_min": construction.k_min,
            "a": construction.a,
            "b": construction.b,
            "origin": list(construction.origin),
            "tangent_max": dict(zip(("phi", "J", "dE"), construction.tangent_max)),
            "tangent_min": dict(zip(("phi", "J", "dE"), construction.tangent_min)),
        },
        "notes": design.notes,
    }


def format_flywheel(data: dict) -> str:
    """The human-readable design: request, machine, the methods side by side, the construction, notes."""
    delta = data["delta"]
    lines = [
        f"scene {data['scene']}: flywheel for [delta] = {delta:.6g} (1/{1 / delta:.4g}; {data['delta_source']})",
        f"design mean speed omega_m = {data['omega_m']:.6g} rad/s ({data['omega_m'] * 30 / math.pi:.5g} rpm): "
        f"{data['omega_m_source']}",
        f"machine without flywheel: J(phi) = {data['inertia_min']:.6g} to {data['inertia_max']:.6g} kg m^2 "
        f"(mean {data['inertia_mean']:.6g}); energy swing dE_max = {data['energy_swing_max']:.6g} J over the "
        f"dynamic period of {math.degrees(data['dynamic_period_rad']):g} deg"
        + (" (moments that read omega taken at omega_m)" if data["speed_dependent"] else ""),
    ]
    shaft = f"J_x at ratio {data['ratio']:g}"
    lines.append(
        f"  {'':<40} {'J_fw [kg m^2]':>14} {shaft + ' [kg m^2]':>24} {'simulated delta':>16} "
        f"{'vs [delta]':>11} {'omega_m sim':>12}"
    )
    rows = [
        ("energy swing (constant J = mean J)", data["methods"]["energy_swing"]),
        ("Wittenbauer (exact numerical form)", data["methods"]["wittenbauer"]),
        ("refined by simulation (brentq)", data["methods"]["refined"]),
        ("without flywheel", data["without_flywheel"]),
        ("the scene's flywheel", data["scene_flywheel"]),
    ]
    for label, row in rows:
        if row is None:
            continue
        on_shaft = f"{row['on_shaft']:.7g}" if row["on_shaft"] is not None else "-"
        simulated = row["simulated"]
        tail = (
            f"{simulated['delta']:16.7g} {simulated['relative_error']:+11.2e} {simulated['omega_m']:12.7g}"
            if simulated
            else f"{'not simulated':>16}"
        )
        lines.append(f"  {label:<40} {row['flywheel']:14.7g} {on_shaft:>24} {tail}")
    methods = data["methods"]
    witt, swing = methods["wittenbauer"]["flywheel"], methods["energy_swing"]["flywheel"]  # always proposed
    refined = methods["refined"]["flywheel"] if methods["refined"] else None
    lines.append(
        f"differences: energy swing vs Wittenbauer {swing / witt - 1.0:+.3%} (the constant-J approximation: "
        "J(phi) taken as its mean)"
    )
    if refined:
        lines.append(
            f"             Wittenbauer vs refined {witt / refined - 1.0:+.3%} (omega_max,min^2 ~ omega_m^2 "
            "(1 +- delta) is O(delta^2)"
            + ("; the moments taken at omega_m while the speed fluctuates)" if data["speed_dependent"] else ")")
        )
    construction = data["construction"]
    upper, lower = construction["tangent_max"], construction["tangent_min"]
    lines.append(
        f"Wittenbauer construction: k_max,min = omega_m^2 (1 +- delta) / 2 = {construction['k_max']:.6g}, "
        f"{construction['k_min']:.6g} J/(kg m^2); tangent points at phi = {math.degrees(upper['phi']):.2f} deg "
        f"(J = {upper['J']:.5g} kg m^2, dE = {upper['dE']:.5g} J) and {math.degrees(lower['phi']):.2f} deg "
        f"(J = {lower['J']:.5g}, dE = {lower['dE']:.5g}); E-axis intercepts a = {construction['a']:.6g} J, "
        f"b = {construction['b']:.6g} J; J_fw = (a - b) / (k_max - k_min) = {witt:.7g} kg m^2"
    )
    lines += [f"note: {note}" for note in data["notes"]]
    return terminal_text("\n".join(lines + wrote_lines(data)))


def _fraction(value: float) -> str:
    """A [delta] as 1/N."""
    return f"1/{1 / value:.4g}"
