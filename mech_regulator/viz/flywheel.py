"""Pictures of a flywheel design (analysis.flywheel): a matplotlib PNG and a Rerun recording.

Both show the energy swing dE(phi) and J(phi) of the machine without a flywheel, the E(J) (Wittenbauer) curve
with the two tangent rays of slopes k_max, k_min, the whole construction with the rays' E-axis intercepts a, b
and their meeting point O' at J = -J_fw, and the simulated speed omega(phi) over the dynamic period without
the flywheel (or with the scene's) and with each proposed flywheel, against the band omega_m (1 +- [delta] / 2).
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)
import numpy as np  # noqa: E402

from mech_regulator.analysis.flywheel import FlywheelDesign  # noqa: E402
from mech_regulator.viz.plots import room_for_legend  # noqa: E402

# run name -> (legend label, matplotlib colour, Rerun colour)
RUN_STYLE = {
    "none": ("without flywheel", "tab:gray", (150, 150, 150)),
    "scene": ("the scene's flywheel", "tab:purple", (195, 125, 255)),
    "energy_swing": ("energy swing (constant J)", "tab:orange", (255, 165, 50)),
    "wittenbauer": ("Wittenbauer", "tab:green", (110, 215, 110)),
    "refined": ("refined by simulation", "tab:blue", (80, 160, 255)),
}
RAY_MAX, RAY_MIN = "tab:red", "tab:cyan"
TIMELINE = "crank_angle_deg"


def plot_flywheel(design: FlywheelDesign, path: Path) -> None:
    """Six panels: dE(phi) and J(phi); the E(J) curve with the tangent rays; the whole construction with a, b
    and O'; omega(phi) before the flywheel; omega(phi) with each proposal and the band; the numbers."""
    diagram, construction = design.diagram, design.construction
    figure, axes = plt.subplots(2, 3, figsize=(18, 10), constrained_layout=True)
    figure.suptitle(
        f"{design.scene}: flywheel for [delta] = {design.delta:.4g} (1/{1 / design.delta:.4g}) at "
        f"omega_m = {design.omega_m:.5g} rad/s"
    )
    degrees = np.degrees(diagram.phi)

    swing = axes[0, 0]
    swing.plot(degrees, diagram.energy, color="tab:blue", label="dE(phi) = integral (M_d + M_c) dphi")
    swing.axhline(diagram.energy.max(), color="tab:blue", lw=0.6, ls=":")
    swing.axhline(diagram.energy.min(), color="tab:blue", lw=0.6, ls=":")
    swing.set(
        xlabel="crank angle phi [deg]",
        ylabel="energy swing dE [J]",
        title=f"no flywheel: energy swing (dE_max = {diagram.swing:.5g} J), J(phi)",
    )
    inertia = swing.twinx()
    inertia.plot(degrees, diagram.inertia, color="tab:red", lw=1.0, label="J(phi)")
    inertia.set_ylabel("J(phi) without flywheel [kg m^2]", color="tab:red")
    swing.legend(handles=swing.get_lines()[:1] + inertia.get_lines(), loc="lower left", fontsize=8)

    curve = axes[0, 1]
    curve.plot(diagram.inertia, diagram.energy, color="k", lw=1.2, label="E(J) over the dynamic period")
    span = max(float(np.ptp(diagram.inertia)), 0.1 * float(np.mean(diagram.inertia)))  # constant J: a little room
    J = np.linspace(diagram.inertia.min() - 0.3 * span, diagram.inertia.max() + 0.3 * span, 50)
    curve.plot(
        J,
        construction.a + construction.k_max * J,
        color=RAY_MAX,
        lw=1.2,
        label=f"ray k_max = omega_m^2 (1 + delta)/2 = {construction.k_max:.4g}",
    )
    curve.plot(
        J,
        construction.b + construction.k_min * J,
        color=RAY_MIN,
        lw=1.2,
        label=f"ray k_min = omega_m^2 (1 - delta)/2 = {construction.k_min:.4g}",
    )
    for (phi, Jt, Et), colour in ((construction.tangent_max, RAY_MAX), (construction.tangent_min, RAY_MIN)):
        curve.plot(Jt, Et, "o", ms=8, mfc="none", mew=2, color=colour)
        curve.annotate(
            f"phi = {math.degrees(phi):.1f} deg",
            (Jt, Et),
            textcoords="offset points",
            xytext=(8, -4),
            fontsize=8,
            color=colour,
        )
    curve.set(
        xlabel="J without flywheel [kg m^2]", ylabel="dE [J]", title="Wittenbauer curve E(J) and the tangent rays"
    )
    curve.ticklabel_format(useOffset=False)
    room_for_legend(curve)
    curve.legend(loc="upper center", fontsize=8)

    whole = axes[0, 2]
    origin_J, origin_E = construction.origin
    J = np.array([origin_J, diagram.inertia.max() + 0.05 * abs(origin_J)])
    whole.plot(diagram.inertia, diagram.energy, color="k", lw=2.0, label="E(J) curve")
    whole.plot(J, construction.a + construction.k_max * J, color=RAY_MAX, lw=1.0, label="ray k_max")
    whole.plot(J, construction.b + construction.k_min * J, color=RAY_MIN, lw=1.0, label="ray k_min")
    whole.axvline(0.0, color="k", lw=0.8)
    whole.plot([0.0, 0.0], [construction.a, construction.b], "o", color="k", ms=5)
    whole.annotate(
        f"a = {construction.a:.4g} J",
        (0.0, construction.a),
        textcoords="offset points",
        xytext=(-8, 6),
        ha="right",
        fontsize=9,
    )
    whole.annotate(
        f"b = {construction.b:.4g} J",
        (0.0, construction.b),
        textcoords="offset points",
        xytext=(-8, -12),
        ha="right",
        fontsize=9,
    )
    whole.plot(origin_J, origin_E, "s", color="k", ms=6)
    whole.annotate(
        f"O' (J = -J_fw = {origin_J:.4g} kg m^2)",
        (origin_J, origin_E),
        textcoords="offset points",
        xytext=(8, -4),
        fontsize=9,
    )
    whole.set(
        xlabel="J [kg m^2]",
        ylabel="E [J]",
        title=f"construction: J_fw = |ab| / (k_max - k_min) = {design.wittenbauer:.5g}",
    )
    whole.legend(loc="upper left", fontsize=8)
    whole.grid(alpha=0.3)

    before = axes[1, 0]
    for name in ("none", "scene"):
        _plot_speed(before, design, name)
    before.set(
        xlabel="crank angle phi [deg]",
        ylabel="omega [rad/s]",
        title="simulated steady speed without a flywheel and with the scene's"
        if set(design.runs) & {"none", "scene"}
        else "no steady motion without a flywheel (the machine stalls)",
    )
    if set(design.runs) & {"none", "scene"}:
        room_for_legend(before)
        before.legend(loc="upper center", fontsize=8)

    after = axes[1, 1]
    for name in ("energy_swing", "wittenbauer", "refined"):
        _plot_speed(after, design, name)
    centre, which = band_centre(design)
    for sign in (1.0, -1.0):
        after.axhline(
            centre * (1.0 + sign * design.delta / 2.0),
            color="k",
            lw=0.8,
            ls="--",
            label=f"{which} (1 +- [delta]/2)" if sign > 0 else None,
        )
    after.set(
        xlabel="crank angle phi [deg]",
        ylabel="omega [rad/s]",
        title="simulated steady speed with the proposed flywheels",
    )
    room_for_legend(after)
    after.legend(loc="upper center", fontsize=8)

    table = axes[1, 2]
    table.axis("off")
    table.text(0.0, 1.0, _numbers(design), family="monospace", fontsize=8.5, va="top", transform=table.transAxes)
    figure.savefig(path, dpi=100)
    plt.close(figure)


def band_centre(design: FlywheelDesign) -> tuple[float, str]:
    """The centre of the band omega (1 +- [delta] / 2) [rad/s] and its name: the simulated omega_m of the refined
    run (a machine whose moments read omega sets its own mean speed), else the design omega_m."""
    if "refined" in design.runs:
        return design.runs["refined"].speeds.omega_m, "omega_m of the refined run"
    return design.omega_m, "omega_m"


def _plot_speed(axes, design: FlywheelDesign, name: str) -> None:
    """omega(phi) of one simulated run, labelled with its flywheel and delta."""
    run = design.runs.get(name)
    if run is None:
        return
    label, colour, _ = RUN_STYLE[name]
    axes.plot(
        np.degrees(run.phi),
        run.omega,
        color=colour,
        lw=1.2,
        label=f"{label}: J_fw = {run.flywheel:.5g} kg m^2, delta = {run.speeds.delta:.5g}",
    )


def _method_rows(design: FlywheelDesign) -> list[tuple[str, float, float, float | None]]:
    """(label, J_fw on the crank [kg m^2], J_x on the flywheel's shaft [kg m^2], simulated delta or None) of each
    flywheel the design has: the three methods and the scene's own."""
    rows = []
    for name, flywheel in (
        ("energy_swing", design.energy_swing),
        ("wittenbauer", design.wittenbauer),
        ("refined", design.refined),
        ("scene", design.scene_flywheel),
    ):
        if flywheel is not None:
            run = design.runs.get(name)
            rows.append(
                (RUN_STYLE[name][0], flywheel, design.on_shaft(flywheel), run.speeds.delta if run is not None else None)
            )
    return rows


def _numbers(design: FlywheelDesign) -> str:
    """The three methods side by side as monospace text."""
    lines = [
        f"{'':<26}{'J_fw [kg m^2]':>14}{'J_x [kg m^2]':>14}{'delta sim':>11}",
        f"{'':<26}{'(crank)':>14}{f'(ratio {design.ratio:g})':>14}",
    ]
    for label, flywheel, on_shaft, delta in _method_rows(design):
        lines.append(
            f"{label:<26}{flywheel:>14.6g}{on_shaft:>14.6g}"
            + (f"{delta:>11.5g}" if delta is not None else f"{'-':>11}")
        )
    construction = design.construction
    lines += [
        "",
        f"[delta] = {design.delta:.5g}, omega_m = {design.omega_m:.5g} rad/s",
        f"dE_max = {design.diagram.swing:.5g} J, mean J = {design.diagram.mean_inertia:.5g} kg m^2",
        f"k_max = {construction.k_max:.5g}, k_min = {construction.k_min:.5g} J/(kg m^2)",
        f"a = {construction.a:.5g} J, b = {construction.b:.5g} J",
    ]
    lines += [""] + [_wrap(note) for note in design.notes]
    return "\n".join(lines)


def _wrap(text: str, width: int = 64) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(f"note: {text}", width))


def record_flywheel(design: FlywheelDesign, path: Path) -> None:
    """A Rerun recording of the design: omega(phi) of every simulated run with the band, dE(phi) and J(phi) on
    the timeline `crank_angle_deg` (one step per degree), the E(J) curve with its tangent rays and the whole
    construction as 2-D drawings (scaled to a unit frame like the textbook's mu_J, mu_E: the views' names give
    the scales), and a document with the numbers."""
    import rerun as rr

    from mech_regulator.viz.recording import finish_stream

    stream = rr.RecordingStream("mech_regulator")
    stream.set_log_time_enabled(False)
    stream.set_sinks(rr.FileSink(str(path)))
    stream.send_blueprint(_blueprint(design), make_active=True, make_default=True)
    stream.send_recording_name(f"{design.scene} flywheel")
    diagram = design.diagram
    angles = np.arange(0, int(round(math.degrees(diagram.phi[-1]))) + 1)
    stamps = rr.TimeColumn(TIMELINE, sequence=angles)
    series = {
        "energy/dE": ("dE(φ) [J]", (80, 160, 255), np.interp(angles, np.degrees(diagram.phi), diagram.energy)),
        "inertia/J": (
            "J(φ) without flywheel [kg m²]",
            (255, 95, 95),
            np.interp(angles, np.degrees(diagram.phi), diagram.inertia),
        ),
    }
    for name, run in design.runs.items():
        label, _, colour = RUN_STYLE[name]
        series[f"speed/{name}"] = (
            f"{label}: δ = {run.speeds.delta:.4g}",
            colour,
            np.interp(angles, np.degrees(run.phi), run.omega),
        )
    centre, which = band_centre(design)
    for sign, key in ((1.0, "high"), (-1.0, "low")):
        series[f"speed/band_{key}"] = (
            f"{which.replace('omega_m', 'ω_m')} (1 {'+' if sign > 0 else '−'} [δ]/2)",
            (235, 235, 235),
            np.full(angles.size, centre * (1.0 + sign * design.delta / 2.0)),
        )
    for entity, (name, colour, values) in series.items():
        stream.log(entity, rr.SeriesLines(names=[name], colors=[colour], widths=[1.5]), static=True)
        stream.send_columns(entity, indexes=[stamps], columns=rr.Scalars.columns(scalars=values))
    for root, drawing in (("curve", _curve_drawing(design)), ("construction", _construction_drawing(design))):
        for name, (kind, geometry, colour, labels) in drawing.items():
            geometry = geometry * np.array([1.0, -1.0])  # Rerun's 2-D views have y down
            if kind == "points":
                stream.log(
                    f"{root}/{name}",
                    rr.Points2D(geometry, colors=colour, labels=labels, radii=rr.Radius.ui_points(5.0)),
                    static=True,
                )
            else:
                stream.log(
                    f"{root}/{name}",
                    rr.LineStrips2D([geometry], colors=colour, labels=labels, radii=rr.Radius.ui_points(1.0)),
                    static=True,
                )
    stream.log("about", rr.TextDocument(_about(design), media_type=rr.MediaType.MARKDOWN), static=True)
    finish_stream(stream)


def _scales(J: np.ndarray, E: np.ndarray, aspect: float = 1.6) -> tuple[float, float, float, float]:
    """Drawing scales (J0, mu_J, E0, mu_E): x = (J - J0) / mu_J spans aspect units, y = (E - E0) / mu_E one."""
    J_span = max(float(np.ptp(J)), 1e-12)
    E_span = max(float(np.ptp(E)), 1e-12)
    return float(np.min(J)), J_span / aspect, float(np.min(E)), E_span


def _scaler(J0: float, mu_J: float, E0: float, mu_E: float):
    """(J, E) -> drawing coordinates, rows of ((J - J0) / mu_J, (E - E0) / mu_E)."""

    def scaled(J, E):
        return np.column_stack([(np.asarray(J) - J0) / mu_J, (np.asarray(E) - E0) / mu_E])

    return scaled


def _curve_drawing(design: FlywheelDesign) -> dict:
    """The E(J) curve with the tangent segments and points, in drawing units."""
    diagram, construction = design.diagram, design.construction
    J0, mu_J, E0, mu_E = _scales(diagram.inertia, diagram.energy)
    if np.ptp(diagram.inertia) < 1e-9 * max(abs(J0), 1.0):  # constant J: a vertical segment, draw it narrow
        mu_J = 1.0
    scaled = _scaler(J0, mu_J, E0, mu_E)
    J = np.array([J0 - 0.2 * 1.6 * mu_J, J0 + 1.2 * 1.6 * mu_J])
    return {
        "E_of_J": ("line", scaled(diagram.inertia, diagram.energy), (235, 235, 235), None),
        "ray_k_max": ("line", scaled(J, construction.a + construction.k_max * J), (255, 95, 95), ["k_max"]),
        "ray_k_min": ("line", scaled(J, construction.b + construction.k_min * J), (80, 200, 255), ["k_min"]),
        "tangent_points": (
            "points",
            scaled(
                [construction.tangent_max[1], construction.tangent_min[1]],
                [construction.tangent_max[2], construction.tangent_min[2]],
            ),
            (250, 210, 60),
            [
                f"φ = {math.degrees(construction.tangent_max[0]):.1f}°",
                f"φ = {math.degrees(construction.tangent_min[0]):.1f}°",
            ],
        ),
    }


def _construction_drawing(design: FlywheelDesign) -> dict:
    """The whole construction from O' to the curve, with the E axis and the intercepts a, b, in drawing units
    (short labels: a and b lie close together; their values are in the numbers document)."""
    diagram, construction = design.diagram, design.construction
    origin_J, origin_E = construction.origin
    J = np.array([origin_J, diagram.inertia.max()])
    E_all = np.concatenate([diagram.energy, [origin_E, construction.a, construction.b]])
    scaled = _scaler(*_scales(np.concatenate([diagram.inertia, [origin_J]]), E_all))
    return {
        "E_axis": ("line", scaled([0.0, 0.0], [E_all.min(), E_all.max()]), (150, 150, 150), ["E axis (J = 0)"]),
        "E_of_J": ("line", scaled(diagram.inertia, diagram.energy), (235, 235, 235), None),
        "ray_k_max": ("line", scaled(J, construction.a + construction.k_max * J), (255, 95, 95), None),
        "ray_k_min": ("line", scaled(J, construction.b + construction.k_min * J), (80, 200, 255), None),
        "points": (
            "points",
            scaled([0.0, 0.0, origin_J], [construction.a, construction.b, origin_E]),
            (250, 210, 60),
            ["a", "b", "O' (J = −J_fw)"],
        ),
    }


def _about(design: FlywheelDesign) -> str:
    """Markdown: what the views show and the numbers."""
    rows = [
        f"| method | J_fw [kg m²] | J_x at ratio {design.ratio:g} [kg m²] | simulated δ |",
        "| --- | ---: | ---: | ---: |",
    ]
    for label, flywheel, on_shaft, delta in _method_rows(design):
        rows.append(
            f"| {label} | {flywheel:.6g} | {on_shaft:.6g} | "
            + (f"{delta:.6g} |" if delta is not None else "not simulated |")
        )
    construction = design.construction
    return "\n\n".join(
        [
            f"# {design.scene}: flywheel for [δ] = {design.delta:.4g}",
            f"ω_m = {design.omega_m:.6g} rad/s. Time line `{TIMELINE}`: the crank angle over one dynamic period, one "
            "step per degree. Speeds: the simulated periodic steady motion with each flywheel; the band is "
            "ω_m (1 ± [δ]/2).",
            "\n".join(rows),
            f"Wittenbauer: k_max = {construction.k_max:.6g}, k_min = {construction.k_min:.6g} J/(kg m²); E-axis "
            f"intercepts a = {construction.a:.6g} J, b = {construction.b:.6g} J; J_fw = (a − b) / (k_max − k_min). "
            "The drawings are scaled to a unit frame (like the textbook's drawing scales μ_J, μ_E), so slopes there "
            "are not the k's; the numbers are.",
        ]
        + [f"Note: {note}" for note in design.notes]
    )


def _blueprint(design: FlywheelDesign):
    """Speeds on the left over dE and J; the two drawings and the numbers on the right."""
    import rerun.blueprint as rrb

    speeds = rrb.TimeSeriesView(
        name="ω(φ) over the dynamic period [rad/s]", origin="speed", plot_legend=rrb.PlotLegend(corner="LeftTop")
    )
    energy = rrb.TimeSeriesView(name="energy swing dE(φ) [J]", origin="energy")
    inertia = rrb.TimeSeriesView(name="J(φ) without flywheel [kg m²]", origin="inertia")
    curve = rrb.Spatial2DView(name="Wittenbauer curve E(J) and tangent rays (scaled)", origin="curve")
    construction = rrb.Spatial2DView(name="construction: O', rays, intercepts a, b (scaled)", origin="construction")
    about = rrb.TextDocumentView(name="numbers", origin="about")
    layout = rrb.Horizontal(
        rrb.Vertical(speeds, energy, inertia, row_shares=[2.0, 1.0, 1.0]),
        rrb.Vertical(curve, construction, about, row_shares=[1.2, 1.5, 1.0]),
    )
    return rrb.Blueprint(
        layout,
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline=TIMELINE),
    )
