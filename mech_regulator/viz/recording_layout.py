"""The layout of a run's recording (viz/recording.py): which series a scene records, their names, colours and
widths, the speed band, the `about` document and the blueprint that lays the plots and the pictures out (each plot
names its series and their colours in its title; the final blueprint's y axes span the values recorded and a
margin of Y_MARGIN)."""

from __future__ import annotations

from collections.abc import Iterable

import rerun.blueprint as rrb

from mech_regulator.mechanisms.drawing import mechanism_bounds
from mech_regulator.model import MachineModel
from mech_regulator.viz.recording_pictures import (
    BLUE,
    COLOUR_NAMES,
    GREEN,
    ORANGE,
    PINK,
    RED,
    VIOLET,
    WHITE,
    YELLOW,
    drawn_mechanism,
    mechanism_title,
)

TIMELINE = "sim_time"


MOMENTS_PERIODS = 4  # dynamic periods at the initial speed shown by a cyclic machine's moments view


MOMENTS_WINDOW = 0.5  # [s] of simulated time shown instead when the machine starts from rest


MOMENTS_WINDOW_LIMITS = (0.05, 10.0)  # [s] shortest and longest window of the moments view


MILLIMETRES = 1000.0  # [mm/m]: the sleeve and the dashpot's shift are plotted in mm


MILLIRADIANS = 1000.0  # [mrad/rad]: the coupling's twist is plotted in mrad


Y_MARGIN = 0.08  # the final blueprint's plots span the data and this fraction of it above and below


# entity -> (label in the plot's title, colour, line width [ui points]); the full names: series_names
SERIES_STYLE = {
    "speed/omega": ("ω crank", BLUE, 1.0),
    "speed/driven": ("ω₂ driven part", PINK, 1.0),
    "speed/set_point": ("ω_set", WHITE, 1.5),
    "speed/band_high": ("band", ORANGE, 1.0),
    "speed/band_low": ("band", ORANGE, 1.0),
    "throttle": ("throttle", GREEN, 2.5),
    "governor/sleeve": ("sleeve z", YELLOW, 1.5),
    "governor/integral": ("integral part x", YELLOW, 1.5),
    "governor/feedback_shift": ("shift ζ", PINK, 1.5),
    "coupling/twist": ("coupling twist φ − φ₂", YELLOW, 1.5),
    "moments/drive": ("drive", GREEN, 1.0),
    "moments/resistance": ("resistance", RED, 1.0),
    "moments/external": ("external", VIOLET, 1.5),
    "moments/net": ("net", WHITE, 1.0),
}


SERIES_NAMES = {  # entity -> name of the series (hover, selection) unless series_names gives the scene's own
    "speed/omega": "ω crank speed",
    "speed/driven": "ω₂ driven part's speed",
    "speed/set_point": "ω_set",
    "throttle": "throttle",
    "governor/sleeve": "sleeve z [mm]",
    "governor/integral": "PI's integral part x [-]",
    "governor/feedback_shift": "dashpot's shift ζ [mm]",
    "coupling/twist": "twist φ − φ₂ [mrad]",
    "moments/external": "external load moment",
    "moments/net": "net = J ε + J' ω² / 2",
}


def speed_band_delta(model: MachineModel) -> tuple[float, str]:
    """delta [-] of the speed band omega_set (1 +- delta / 2) and where it comes from: the scene's
    analysis.permitted_delta ('permitted'), else 2 analysis.settling_band ('settling')."""
    analysis = model.scene.analysis
    if analysis.permitted_delta is not None:
        return analysis.permitted_delta, "permitted"
    return 2.0 * analysis.settling_band, "settling"


def band_name(delta: float, source: str) -> str:
    """Name of the band's two series (one name: they are one band): what delta is and where it comes from."""
    if source == "permitted":
        return f"band ω_set (1 ± δ/2), permitted δ = {delta:.4g}"
    return f"settling band ω_set (1 ± {delta / 2:.3g})"


def band_title(delta: float, source: str) -> str:
    """What the band is, after its label in the speed view's title."""
    if source == "permitted":
        return f"±δ/2, permitted δ = {delta:.4g}"
    return f"±{delta / 2:.3g}, the settling band"


def resistance_name(model: MachineModel) -> str:
    """Name of the resisting moments on the crank: the machine's loads and whatever else takes moment from it."""
    parts = ["loads"] + (["link weight"] if model.has_weight else []) + (["coupling"] if model.coupling else [])
    parts += (["clutch"] if model.clutch else []) + (["joint friction"] if model.joint_friction else [])
    return "resistance: " + " + ".join(parts)


def governor_signal(governor) -> tuple[str, str, float, str]:
    """The governor's own plotted signal beside the throttle: (entity, its key in the governor's values, factor to
    the plotted unit, unit): GovernorKind.plotted, e.g. a centrifugal governor's sleeve z in mm, a PI governor's
    integral part x [-]."""
    key, _, factor, unit = governor.plotted()
    return f"governor/{key}", key, factor, unit


def series_names(model: MachineModel, outside_throttle: bool = False) -> dict[str, str]:
    """Name of each recorded series (recorded_series): SERIES_NAMES', with the band, the drive, the resistance and an
    indirect governor's throttle named as the scene has them."""
    names = dict(SERIES_NAMES)
    governor = model.governor
    if governor is not None:
        band = band_name(*speed_band_delta(model))
        names.update({"speed/band_high": band, "speed/band_low": band, "moments/drive": "drive = throttle × M_d"})
        names["throttle"] = governor.throttle_label
    elif outside_throttle:
        names["moments/drive"] = "drive = throttle × M_d"
    else:
        names["moments/drive"] = "drive M_d"
    names["moments/resistance"] = resistance_name(model)
    return {entity: names[entity] for entity in recorded_series(model, outside_throttle)}


def recorded_series(model: MachineModel, outside_throttle: bool = False) -> list[str]:
    """The scalar entities a run of this model records: speed (with the driven part's behind a coupling or a
    clutch, with set point and band when governed), throttle and governor states when governed (the dashpot's
    shift for isodromic feedback), the throttle alone of a controller outside the model (outside_throttle, no
    governor), the coupling's twist, and the moments (the external one only when the load
    acts on the crank)."""
    series = ["speed/omega"] + (["speed/driven"] if model.driven is not None else [])
    governor = model.governor
    if governor is not None:
        series += ["speed/set_point", "speed/band_high", "speed/band_low", "throttle", governor_signal(governor)[0]]
        if "feedback_shift" in governor.state_names:
            series.append("governor/feedback_shift")
    elif outside_throttle:
        series.append("throttle")
    if model.coupling is not None:
        series.append("coupling/twist")
    external = ["moments/external"] if model.driven is None else []
    return series + ["moments/drive", "moments/resistance"] + external + ["moments/net"]


def moments_window(model: MachineModel) -> float | None:
    """Seconds of simulated time the moments view shows before the time cursor: MOMENTS_PERIODS dynamic
    periods at the initial speed (MOMENTS_WINDOW from rest), within MOMENTS_WINDOW_LIMITS; None (the whole
    run) for a machine whose moments do not vary within a turn."""
    if model.reduced is None and "phi" not in model.depends_on():
        return None
    omega = abs(model.scene.scenario.initial.omega)
    window = MOMENTS_PERIODS * model.dynamic_period() / omega if omega > 0.0 else MOMENTS_WINDOW
    return min(max(window, MOMENTS_WINDOW_LIMITS[0]), MOMENTS_WINDOW_LIMITS[1])


def about_text(model: MachineModel, delta: float, source: str, outside_throttle: bool = False) -> str:
    """Markdown describing the scene and what the series mean (units, set point, band, moments, drawings)."""
    scene = model.scene
    governor = model.governor
    paragraphs = [f"# {scene.name or 'run'}"] + ([scene.description] if scene.description else [])
    paragraphs.append(
        "Time line `sim_time`: simulated time. Crank speed ω in rad/s; moments on the crank in N m: "
        "drive as applied (throttle included), resistance = the machine's loads and link weights (and "
        "what a coupling or a clutch takes), external = minus the external load (when it acts on the "
        "crank), net = their sum = J ε + J' ω² / 2."
    )
    if model.driven is not None:
        where = "coupling" if model.coupling is not None else "clutch"
        paragraphs.append(
            f"Behind the {where}: the driven part's speed ω₂ in rad/s; it carries the external load."
            + (" The coupling's twist φ − φ₂ in mrad." if model.coupling is not None else "")
        )
    if governor is None:
        paragraphs.append(
            "No governor: the throttle (0..1) comes from a controller outside the model; no set speed "
            "and no band are drawn."
            if outside_throttle
            else "No governor: no throttle, no set speed and no band are drawn."
        )
    else:
        paragraphs.append(governor.set_speed_text())
        if source == "permitted":
            paragraphs.append(
                f"Band ω_set (1 ± δ/2) with the permitted coefficient of speed fluctuation "
                f"δ = {delta:.4g} (analysis.permitted_delta)."
            )
        else:
            paragraphs.append(
                f"Band ω_set (1 ± {delta / 2:.3g}): the settling band (analysis.settling_band); the "
                "scene gives no analysis.permitted_delta."
            )
        paragraphs.append(
            "Sleeve rise z (and the dashpot's shift ζ of isodromic feedback) in mm. The governor is "
            "drawn to scale, its balls as steel spheres of the ball mass, projected on a plane "
            "through the turning spindle."
        )
    drawing, driven = drawn_mechanism(model)
    if drawing is None:
        paragraphs.append("The machine has no mechanism: a schematic disc with a spoke shows the crank angle.")
    else:
        where = ", on the driven shaft at φ₂ = φ − twist." if driven else "."
        paragraphs.append(f"The mechanism is drawn to scale in metres{where}")
    paragraphs.append(
        "Events: the start, each change of the external load (a ramp as one line with its start and "
        "end), the mode changes of the governor or the clutch, and the end."
    )
    return "\n\n".join(paragraphs)


def _caption(entities: Iterable[str]) -> str:
    """The series of a plot with their colours, e.g. 'ω crank (blue) · ω_set (white)' (a label once)."""
    shown: dict[str, str] = {}
    for entity in entities:
        label, colour, _ = SERIES_STYLE[entity]
        shown.setdefault(label, COLOUR_NAMES[colour])
    return " · ".join(f"{label} ({colour})" for label, colour in shown.items())


def _plot(
    title: str, entities: list[str], extents: dict[str, tuple[float, float]], window: rrb.VisibleTimeRange | None = None
) -> rrb.TimeSeriesView:
    """A time series view of these entities with its legend hidden (the title names the series) and, when any
    of them has an extent (lowest, highest value), its y axis over their extents widened by Y_MARGIN (a
    constant by 5 % of its size, at least 0.05) on each side; else the viewer fits the y axis to the data."""
    known = [extents[entity] for entity in entities if entity in extents]
    axis = None
    if known:
        low, high = min(extent[0] for extent in known), max(extent[1] for extent in known)
        margin = Y_MARGIN * (high - low) if high > low else 0.05 * max(abs(high), 1.0)
        axis = rrb.ScalarAxis(range=(low - margin, high + margin))
    return rrb.TimeSeriesView(
        name=title,
        contents=[f"/{entity}" for entity in entities],
        time_ranges=window,
        axis_y=axis,
        plot_legend=rrb.PlotLegend(visible=False),
    )


def _single_plot(entity: str, unit: str, extents: dict[str, tuple[float, float]]) -> rrb.TimeSeriesView:
    """The time series view of one entity, titled with its label and unit."""
    return _plot(f"{SERIES_STYLE[entity][0]} [{unit}]", [entity], extents)


def run_blueprint(
    model: MachineModel, extents: dict[str, tuple[float, float]] | None = None, outside_throttle: bool = False
) -> rrb.Blueprint:
    """The layout: time series on the left (speeds, throttle, sleeve, the coupling's twist, moments), each titled
    with its series and their colours; on the right the mechanism over the governor beside the events log (with
    the `about` document in a tab). Each 2-D view is framed by the drawing's bounds (y flipped). A machine
    whose moments vary within a turn shows them over a window before the time cursor (moments_window); the
    viewer fits the window's time axis to the data in it, so from t = 0 until the run passes the window it
    shows [0, cursor]. extents: entity -> (lowest, highest value) recorded, to frame the plots' y axes (see _plot;
    none while the run goes on: the viewer fits them to the data); outside_throttle: a throttle plot for a controller
    outside the model (no governor)."""
    extents = extents or {}
    series = recorded_series(model, outside_throttle)
    speed = [entity for entity in series if entity.startswith("speed/")]
    band = f" {band_title(*speed_band_delta(model))}" if model.governor is not None else ""
    plots: list[rrb.Container | rrb.View] = [_plot(f"speed [rad/s]: {_caption(speed)}{band}", speed, extents)]
    shares = [2.0]
    if model.governor is not None:
        # side by side, each tall enough for the viewer to label its y axis
        entity, _, _, unit = governor_signal(model.governor)
        governor_plots = [_single_plot("throttle", "-", extents), _single_plot(entity, unit, extents)]
        if "governor/feedback_shift" in series:
            governor_plots.append(_single_plot("governor/feedback_shift", "mm", extents))
        plots.append(rrb.Horizontal(*governor_plots))
        shares.append(1.6)
    elif "throttle" in series:
        plots.append(_single_plot("throttle", "-", extents))
        shares.append(1.2)
    if model.coupling is not None:
        plots.append(_single_plot("coupling/twist", "mrad", extents))
        shares.append(1.0)
    moments = [entity for entity in series if entity.startswith("moments/")]
    window = moments_window(model)
    time_range = (
        None
        if window is None
        else rrb.VisibleTimeRange(
            TIMELINE,
            start=rrb.TimeRangeBoundary.cursor_relative(seconds=-window),
            end=rrb.TimeRangeBoundary.cursor_relative(seconds=0.0),
        )
    )
    span = "" if window is None else f", last {window:.2g} s"
    plots.append(_plot(f"moments [N m]{span}: {_caption(moments)}", moments, extents, time_range))
    shares.append(1.6)
    logs = rrb.Tabs(
        rrb.TextLogView(
            name="events", origin="events", columns=rrb.TextLogColumns(text_log_columns=["LogLevel", "Body"])
        ),
        rrb.TextDocumentView(name="about", origin="about"),
    )
    mechanism = rrb.Spatial2DView(
        name=mechanism_title(model),
        origin="mechanism",
        visual_bounds=_bounds_y_down(mechanism_bounds(drawn_mechanism(model)[0])),
    )
    sensor = model.governor.sensor if model.governor is not None else None
    if sensor is not None:  # a centrifugal governor's drawing
        governor = rrb.Spatial2DView(
            name="governor", origin="governor/drawing", visual_bounds=_bounds_y_down(sensor.bounds())
        )
        right = rrb.Vertical(mechanism, rrb.Horizontal(governor, logs, column_shares=[1.0, 1.3]), row_shares=[1.0, 1.8])
    else:
        right = rrb.Vertical(mechanism, logs, row_shares=[1.6, 1.0])
    layout = rrb.Horizontal(rrb.Vertical(*plots, row_shares=shares), right)
    return rrb.Blueprint(
        layout,
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline=TIMELINE),
    )


def _bounds_y_down(bounds: tuple[float, float, float, float]) -> rrb.VisualBounds2D:
    """VisualBounds2D of drawing bounds (xmin, xmax, ymin, ymax) [m, y up] in Rerun's y-down plane."""
    xmin, xmax, ymin, ymax = bounds
    return rrb.VisualBounds2D(x_range=[xmin, xmax], y_range=[-ymax, -ymin])
