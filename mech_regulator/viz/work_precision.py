"""Pictures of the work–precision benchmark: a log–log PNG per scene (CPU time against achieved error,
one line per method, points labelled with their setting), the tolerance-proportionality PNG (achieved
error against requested rtol) and a Rerun recording of the same curves.

In the recording each scene is a 2-D view in decade coordinates, x = -log10(achieved error) and
y = -CPU_STRETCH log10(CPU time [s]): more accurate to the right and (Rerun's 2-D views have y pointing
down) slower higher, as on the PNGs, with decade grid lines, tick labels and a legend.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)
import numpy as np  # noqa: E402
import rerun as rr  # noqa: E402
import rerun.blueprint as rrb  # noqa: E402

from mech_regulator.bench.accuracy import ADAPTIVE, COSIM, METHODS, Benchmark, SceneResult  # noqa: E402
from mech_regulator.viz.recording import APPLICATION_ID  # noqa: E402

# method -> (matplotlib colour, marker): one family of markers per kind of method
STYLE = {
    "RK45": ("tab:blue", "o"),
    "DOP853": ("tab:orange", "o"),
    "Radau": ("tab:green", "o"),
    "BDF": ("tab:red", "o"),
    "LSODA": ("tab:purple", "o"),
    "RK4": ("tab:brown", "s"),
    "energy": ("tab:pink", "D"),
    COSIM: ("tab:gray", "^"),
}
X_LABEL = "achieved error: RMS of omega - omega_ref, relative to max |omega_ref| [-]"
Y_LABEL = "CPU time of the integration [s] (median of repeats)"
GRID_GREY, TEXT_GREY, REFERENCE_RED = (90, 90, 90), (200, 200, 200), (255, 95, 95)
CPU_STRETCH = 2.5  # recording: units per decade of CPU time (errors: 1 per decade), so the curves spread out


def _rgb(colour: str) -> tuple[int, int, int]:
    """A matplotlib colour as 0-255 RGB, so the recording uses the PNGs' colours."""
    red, green, blue = matplotlib.colors.to_rgb(colour)
    return round(255 * red), round(255 * green), round(255 * blue)


def _curve(result: SceneResult, method: str) -> tuple[np.ndarray, np.ndarray, list[str], list[bool]]:
    """A method's completed runs with a known positive error: errors [-], CPU times [s], setting labels
    and whether each lies below the reference's own error."""
    runs = [run for run in result.runs_of(method) if run.error > 0.0]
    return (
        np.array([run.error for run in runs]),
        np.array([run.cpu for run in runs]),
        [run.setting.label for run in runs],
        [result.below_reference(run) for run in runs],
    )


def plot_work_precision(result: SceneResult, path: Path) -> None:
    """Log-log CPU time [s] against achieved headline error [-], one line per method with its points
    labelled by setting (rtol, step, crank-angle step, exchange step); runs below the reference's own
    error hollow, and that error as a dotted line."""
    figure, axes = plt.subplots(figsize=(13, 7.5), constrained_layout=True)
    for method in METHODS:
        errors, cpu, labels, below = _curve(result, method)
        if errors.size == 0:
            continue
        colour, marker = STYLE[method]
        axes.plot(errors, cpu, color=colour, lw=1.3, label=method)
        for x, y, label, hollow in zip(errors, cpu, labels, below):
            axes.plot(x, y, marker=marker, ms=6, color=colour, mfc="white" if hollow else colour)
            axes.annotate(label, (x, y), xytext=(4, 3), textcoords="offset points", fontsize=7, color=colour)
    if result.reference_error > 0.0:
        axes.axvline(
            result.reference_error,
            color="k",
            lw=0.9,
            ls=":",
            label=f"reference's own error ({result.reference_error:.1g})",
        )
    axes.set_xscale("log")
    axes.set_yscale("log")
    axes.invert_xaxis()
    axes.grid(which="major", alpha=0.35)
    axes.grid(which="minor", alpha=0.1)
    axes.set(
        xlabel=X_LABEL + "  (more accurate to the right)",
        ylabel=Y_LABEL,
        title=f"{result.bench.name}: {result.bench.what}\nreference: {result.reference}",
    )
    axes.legend(
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        fontsize=9,
        title_fontsize=8,
        title="method; points labelled with\nrtol (adaptive), step (RK4),\ncrank-angle step (energy),\n"
        "exchange step (co-simulation);\nhollow: below the reference's\nown error",
    )
    figure.savefig(path, dpi=110)
    plt.close(figure)


def plot_tolerance_proportionality(benchmark: Benchmark, path: Path) -> None:
    """One log-log panel per scene: achieved headline error [-] against requested rtol [-] for each adaptive
    method, with the diagonal error = rtol and the reference's own error."""
    count = len(benchmark.scenes)
    columns = min(3, count)
    rows = math.ceil(count / columns)
    figure, grid = plt.subplots(
        rows, columns, figsize=(5.2 * columns, 4.4 * rows), squeeze=False, constrained_layout=True
    )
    for axes, result in zip(grid.flat, benchmark.scenes):
        tolerances = [run.setting.value for method in ADAPTIVE for run in result.runs_of(method)]
        for method in ADAPTIVE:
            runs = [run for run in result.runs_of(method) if run.error > 0.0]
            if runs:
                colour, marker = STYLE[method]
                axes.plot(
                    [run.setting.value for run in runs],
                    [run.error for run in runs],
                    color=colour,
                    marker=marker,
                    ms=4,
                    lw=1.2,
                    label=method,
                )
        if tolerances:
            span = np.array([min(tolerances), max(tolerances)])
            axes.plot(span, span, color="k", lw=0.8, ls="--", label="error = rtol")
        if result.reference_error > 0.0:
            axes.axhline(result.reference_error, color="k", lw=0.8, ls=":", label="reference's own error")
        axes.set_xscale("log")
        axes.set_yscale("log")
        axes.invert_xaxis()
        axes.grid(which="major", alpha=0.35)
        axes.set(
            title=result.bench.name,
            xlabel="requested rtol [-] (tighter to the right)",
            ylabel="achieved error, omega RMS relative [-]",
        )
        axes.legend(fontsize=7, loc="lower left")
    for axes in list(grid.flat)[count:]:
        axes.set_visible(False)
    figure.suptitle("Tolerance proportionality of the adaptive methods")
    figure.savefig(path, dpi=100)
    plt.close(figure)


# ---------------------------------------------------------------------------------------------
# Rerun


def _decades(values: list[float]) -> tuple[int, int]:
    """The whole decades enclosing positive values: (floor log10 of the least, ceil of the largest)."""
    logs = np.log10(values)
    return int(math.floor(logs.min())), int(math.ceil(logs.max()))


def _decade_label(exponent: int, seconds: bool) -> str:
    """Tick text of a decade: 1e-6 for errors; 1 ms, 10 s ... for CPU times."""
    if not seconds:
        return f"1e{exponent}"
    value = 10.0**exponent
    return f"{value * 1e3:g} ms" if value < 1.0 else f"{value:g} s"


def _log_scene(stream: rr.RecordingStream, result: SceneResult) -> tuple[float, float, float, float] | None:
    """Log one scene's curves, grid, tick labels and legend under /<scene>, at x = -log10(error) (more
    accurate to the right) and y = -CPU_STRETCH log10(CPU time [s]) (y down: slower runs higher, as on the
    PNGs); returns the bounds (left, right, top, bottom) of what it drew, or None if it has no run."""
    curves = {method: _curve(result, method) for method in METHODS}
    curves = {method: curve for method, curve in curves.items() if curve[0].size}
    if not curves:
        return None
    errors = [value for curve in curves.values() for value in curve[0]]
    if result.reference_error > 0.0:
        errors.append(result.reference_error)
    error_low, error_high = _decades(errors)
    cpu_low, cpu_high = _decades([value for curve in curves.values() for value in curve[1]])
    left, right, top, bottom = -error_high, -error_low, -CPU_STRETCH * cpu_high, -CPU_STRETCH * cpu_low
    root = result.bench.name
    error_decades, cpu_decades = range(error_low, error_high + 1), range(cpu_low, cpu_high + 1)
    grid = [[[-e, top], [-e, bottom]] for e in error_decades] + [
        [[left, -CPU_STRETCH * c], [right, -CPU_STRETCH * c]] for c in cpu_decades
    ]
    stream.log(
        f"{root}/grid",
        rr.LineStrips2D(grid, colors=GRID_GREY, radii=rr.Radius.ui_points(0.5), draw_order=1.0),
        static=True,
    )
    ticks = [[-e, bottom + 0.4] for e in error_decades] + [[left - 0.45, -CPU_STRETCH * c] for c in cpu_decades]
    labels = [_decade_label(e, False) for e in error_decades] + [_decade_label(c, True) for c in cpu_decades]
    _labels(stream, f"{root}/ticks", ticks, labels, TEXT_GREY)
    _labels(
        stream,
        f"{root}/axis_titles",
        [[(left + right) / 2, bottom + 1.2], [left, top - 0.7]],
        ["achieved error: omega RMS, relative (more accurate to the right)", "CPU time per run"],
        TEXT_GREY,
    )
    if result.reference_error > 0.0:
        x = -math.log10(result.reference_error)
        stream.log(
            f"{root}/reference_error",
            rr.LineStrips2D(
                [[[x, top], [x, bottom]]], colors=REFERENCE_RED, radii=rr.Radius.ui_points(1.0), draw_order=5.0
            ),
            static=True,
        )
        _labels(
            stream,
            f"{root}/reference_error/label",
            [[x, top - 0.7]],
            [f"reference's own error {result.reference_error:.1g}"],
            REFERENCE_RED,
        )
    for method, (method_errors, method_cpu, point_labels, below) in curves.items():
        points = np.column_stack([-np.log10(method_errors), -CPU_STRETCH * np.log10(method_cpu)])
        colour = _rgb(STYLE[method][0])
        stream.log(
            f"{root}/methods/{method}",
            rr.LineStrips2D(
                [points],
                colors=colour,
                labels=[method],
                show_labels=False,
                radii=rr.Radius.ui_points(1.5),
                draw_order=10.0,
            ),
            static=True,
        )
        stream.log(
            f"{root}/methods/{method}/points",
            rr.Points2D(
                points,
                labels=point_labels,
                colors=[(255, 255, 255) if hollow else colour for hollow in below],
                radii=rr.Radius.ui_points(3.0),
                show_labels=True,
                draw_order=20.0,
            ),
            static=True,
        )
    legend = [[right + 0.6, top + 0.9 * i] for i in range(len(curves))]
    stream.log(
        f"{root}/legend",
        rr.Points2D(
            legend,
            labels=list(curves),
            colors=[_rgb(STYLE[m][0]) for m in curves],
            radii=rr.Radius.ui_points(4.0),
            show_labels=True,
        ),
        static=True,
    )
    return left - 1.2, right + 2.2, top - 1.4, bottom + 1.8


def _labels(stream: rr.RecordingStream, entity: str, positions: list, labels: list[str], colour) -> None:
    """Text at positions (decade coordinates), drawn as the labels of invisible points."""
    stream.log(
        entity,
        rr.Points2D(positions, labels=labels, colors=colour, radii=rr.Radius.ui_points(0.0), show_labels=True),
        static=True,
    )


def record_work_precision(benchmark: Benchmark, path: Path) -> None:
    """Write the work-precision curves of every scene to the Rerun file `path`: one 2-D view per scene
    (see the module docstring) and an `about` document saying how to read them."""
    stream = rr.RecordingStream(APPLICATION_ID)
    stream.set_log_time_enabled(False)
    stream.set_sinks(rr.FileSink(str(path)))
    views: list[rrb.View] = []
    for result in benchmark.scenes:
        bounds = _log_scene(stream, result)
        if bounds is None:
            continue
        left, right, top, bottom = bounds
        views.append(
            rrb.Spatial2DView(
                name=f"{result.bench.name}: CPU time against achieved error",
                origin=result.bench.name,
                visual_bounds=rrb.VisualBounds2D(x_range=[left, right], y_range=[top, bottom]),
            )
        )
    stream.log(
        "about",
        rr.TextDocument(
            "# Work–precision benchmark\n\nOne view per scene, in decades: x = achieved error (RMS of omega - "
            "omega_ref relative to max |omega_ref|), more accurate to the right; y = CPU time per run, slower "
            "higher. One line per "
            "method, its points labelled with their setting (rtol, RK4 step, energy-method crank-angle step, "
            "co-simulation exchange step); white points lie below the reference's own error (red line). "
            "Tables and findings: docs/accuracy/README.md.",
            media_type=rr.MediaType.MARKDOWN,
        ),
        static=True,
    )
    views.append(rrb.TextDocumentView(name="about", origin="about"))
    stream.send_blueprint(
        rrb.Blueprint(
            rrb.Grid(*views),
            rrb.BlueprintPanel(state="collapsed"),
            rrb.SelectionPanel(state="collapsed"),
            rrb.TimePanel(state="collapsed"),
        ),
        make_active=True,
        make_default=True,
    )
    stream.send_recording_name("work–precision benchmark")
    stream.flush()
    stream.disconnect()


def write_pictures(benchmark: Benchmark, folder: Path) -> None:
    """Write work_precision_<scene>.png for every scene, tolerance_proportionality.png and
    work_precision.rrd into folder."""
    for result in benchmark.scenes:
        plot_work_precision(result, folder / f"work_precision_{result.bench.name}.png")
    plot_tolerance_proportionality(benchmark, folder / "tolerance_proportionality.png")
    record_work_precision(benchmark, folder / "work_precision.rrd")
