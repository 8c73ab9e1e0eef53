"""Rerun recordings of a run: time series of the crank speed, throttle, governor and moments, an
animation of the mechanism and the governor, and a text log of events, laid out by a blueprint.

A RunRecording is fed sample by sample (the ROS recorder's callbacks, or `record_run` from a monolithic
simulation). Times are whole nanoseconds of SIMULATED time on the duration timeline `sim_time`. Scalar
samples are only appended to lists; `flush()` sends them as columns. The animation is decimated to
`animation_rate` frames per second of simulated time. Rerun's 2-D views have y pointing down, so the
drawings (y up, mechanisms.drawing and governors.drawing) are flipped on the way in.

Speed set point omega_set (`speed/set_point`): for an indirect governor its set speed
(`Governor.set_speed`, constant); for a direct governor the speed of the operating point of the
cycle-averaged machine at the current external load (`analysis.operating_point`), i.e. where a direct
governor settles (it has a static error); a machine without a governor has no set point and no band.
The band `speed/band_high`, `speed/band_low` is omega_set (1 +- delta / 2) with delta the scene's
`analysis.permitted_delta` or, when the scene gives none, twice its `analysis.settling_band` (then the
band is the settling band around omega_set); the speed view's title and the `about` document say which.
"""

from __future__ import annotations

import math
import threading
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from mech_regulator.analysis import operating_point
from mech_regulator.governors.drawing import MOVING_PARTS as GOVERNOR_MOVING_PARTS
from mech_regulator.governors.drawing import ball_radius, governor_bounds, governor_outline
from mech_regulator.mechanisms.drawing import MOVING_PARTS as MECHANISM_MOVING_PARTS
from mech_regulator.mechanisms.drawing import mechanism_bounds, mechanism_kind, mechanism_outline
from mech_regulator.model import MachineModel, crank_moments
from mech_regulator.solvers.trajectory import Progress

APPLICATION_ID = "mech_regulator"
TIMELINE = "sim_time"
NANOSECONDS = 1_000_000_000
SET_POINT_REFRESH_NS = 10_000_000   # a direct governor's set point follows a changing load at most every 10 ms
RECORD_RUN_FLUSH_SAMPLES = 20_000   # record_run sends the buffered columns every this many samples
MOMENTS_WINDOW = 0.5                # [s] of simulated time shown by the moments view of a cyclic machine
MILLIMETRES = 1000.0                # [mm/m]: the sleeve and the dashpot's shift are plotted in mm

WHITE, GREY, DARK_GREY = (235, 235, 235), (150, 150, 150), (95, 95, 95)
BLUE, ORANGE, GREEN = (80, 160, 255), (255, 165, 50), (110, 215, 110)
RED, VIOLET, YELLOW, PINK = (255, 95, 95), (195, 125, 255), (250, 210, 60), (255, 120, 190)

# entity -> (series name in the legend, colour, line width [ui points]); the band's names come from the scene
SERIES_STYLE = {
    "speed/omega": ("ω crank speed", BLUE, 1.0),
    "speed/set_point": ("ω_set", WHITE, 1.5),
    "speed/band_high": ("", ORANGE, 1.0),
    "speed/band_low": ("", ORANGE, 1.0),
    "throttle": ("throttle [-]", GREEN, 2.5),
    "governor/servo": ("servo s [-]", VIOLET, 1.0),
    "governor/sleeve": ("sleeve z [mm]", YELLOW, 1.5),
    "governor/feedback_shift": ("dashpot shift ζ [mm]", PINK, 1.5),
    "moments/drive": ("drive (throttle × M_d)", GREEN, 1.0),
    "moments/resistance": ("resistance (loads, weight)", RED, 1.0),
    "moments/external": ("external load moment", VIOLET, 1.5),
    "moments/net": ("net = J ε + J' ω² / 2", WHITE, 1.0),
}

# drawing part -> (colour, line width or point radius [ui points]; None: the point radius is in metres)
MECHANISM_STYLE = {
    "guide": (GREY, 1.5), "frame": (GREY, 2.0), "crank_path": (DARK_GREY, 1.0), "disc": (GREY, 1.5),
    "crank": (ORANGE, 3.0), "spoke": (ORANGE, 3.0), "rod": (BLUE, 3.0), "coupler": (BLUE, 3.0),
    "rocker": (GREEN, 3.0), "slider": (WHITE, 2.0), "joints": (WHITE, 4.0),
    "tie": (VIOLET, 2.5), "side": (PINK, 2.5), "shuttle": (YELLOW, 4.0),
}
GOVERNOR_STYLE = {
    "spindle": (GREY, 2.5), "stops": (RED, 2.5), "upper_arms": (ORANGE, 2.5), "lower_links": (BLUE, 2.0),
    "sleeve": (YELLOW, 2.0), "balls": ((200, 200, 215), None), "spindle_mark": (ORANGE, 4.0),
}
POINT_PARTS = ("joints", "balls", "spindle_mark")
FLIP_Y = np.array([1.0, -1.0])       # drawings have y up, Rerun's 2-D views y down


class RunRecording:
    """One run written to Rerun: a .rrd file (path) and/or a live viewer (connect: gRPC URL such as
    rerun+http://127.0.0.1:9876/proxy), through a recording stream of its own, with the blueprint of
    `run_blueprint`. Feed it samples in time order per stream (streams may interleave), call `flush()`
    every so often and `close()` at the end. Thread-safe; samples given after close() are dropped."""

    def __init__(self, model: MachineModel, path: Path | None = None, connect: str | None = None,
                 animation_rate: float = 200.0, recording_name: str | None = None):
        if path is None and connect is None:
            raise ValueError("RunRecording needs a file (path) or a viewer to connect to (connect), or both")
        if not animation_rate > 0.0:
            raise ValueError(f"animation_rate = {animation_rate} Hz; expected a positive rate")
        self.model = model
        self._lock = threading.Lock()
        self._closed = False
        self._frame_period_ns = max(1, round(NANOSECONDS / animation_rate))
        self._mechanism_frame = self._governor_frame = -1
        self._phi = model.scene.scenario.initial.phi
        self._external_load = model.external_load(0.0)
        self._delta, self._delta_source = speed_band_delta(model)
        self._set_points: dict[float, float] = {}    # external load [N m] -> direct governor's set point [rad/s]
        self._set_point_load = math.nan
        self._set_point_time = -SET_POINT_REFRESH_NS
        self._set_point = model.governor.set_speed() if model.governor is not None else math.nan
        self._series = {entity: ([], []) for entity in recorded_series(model)}
        self._frames: dict[str, tuple[list[int], list[np.ndarray]]] = {}   # entity -> (times, parts y down)
        self._stream = rr.RecordingStream(APPLICATION_ID)
        self._stream.set_log_time_enabled(False)   # one time line: simulated time, not the wall clock
        sinks = ([rr.FileSink(str(path))] if path is not None else []) + ([rr.GrpcSink(connect)] if connect else [])
        self._stream.set_sinks(*sinks)
        self._stream.send_blueprint(run_blueprint(model), make_active=True, make_default=True)
        self._stream.send_recording_name(recording_name or model.scene.name or "run")
        self._log_static()

    # ---------------------------------------------------------------------------------------------
    # Samples

    def add_machine(self, t_ns: int, phi: float, omega: float) -> None:
        """A sample of the crank: angle phi [rad] and speed omega [rad/s] at t_ns [ns]; also the set point
        and band at that time and, when a frame is due, the mechanism's picture."""
        with self._lock:
            if self._closed:
                return
            self._append("speed/omega", t_ns, omega)
            set_point = self._current_set_point(t_ns)
            if math.isfinite(set_point):
                self._append("speed/set_point", t_ns, set_point)
                self._append("speed/band_high", t_ns, set_point * (1.0 + 0.5 * self._delta))
                self._append("speed/band_low", t_ns, set_point * (1.0 - 0.5 * self._delta))
            self._phi = phi
            frame = t_ns // self._frame_period_ns
            if frame > self._mechanism_frame:
                self._mechanism_frame = frame
                mechanism = self.model.scene.machine.mechanism
                self._add_frame("mechanism", t_ns, mechanism_outline(mechanism, phi),
                                MECHANISM_MOVING_PARTS[mechanism_kind(mechanism)])

    def add_moments(self, t_ns: int, drive: float, resistance: float, external: float, net: float) -> None:
        """Moments on the crank [N m] at t_ns [ns]: the drive as applied (throttle included), the machine's
        resisting moments (loads and link weight, not the external load), the external moment (minus the
        external load) and their sum, the net moment J epsilon + 1/2 J' omega^2."""
        with self._lock:
            if self._closed:
                return
            for entity, value in (("moments/drive", drive), ("moments/resistance", resistance),
                                  ("moments/external", external), ("moments/net", net)):
                self._append(entity, t_ns, value)
            self._external_load = -external

    def add_governor(self, t_ns: int, values: dict[str, float]) -> None:
        """A sample of the governor at t_ns [ns]: sleeve [m], arm_angle [rad], throttle [-], and for an
        indirect governor servo [-] and, isodromic, feedback_shift [m] (other keys are ignored); also the
        governor's picture when a frame is due, its spindle at ratio * (the latest crank angle)."""
        with self._lock:
            if self._closed:
                return
            self._append("throttle", t_ns, values["throttle"])
            self._append("governor/sleeve", t_ns, MILLIMETRES * values["sleeve"])
            if "servo" in values:
                self._append("governor/servo", t_ns, values["servo"])
            if "feedback_shift" in values:
                self._append("governor/feedback_shift", t_ns, MILLIMETRES * values["feedback_shift"])
            frame = t_ns // self._frame_period_ns
            if frame > self._governor_frame:
                self._governor_frame = frame
                sensor = self.model.governor.sensor
                self._add_frame("governor/drawing", t_ns,
                                governor_outline(sensor, values["arm_angle"], sensor.ratio * self._phi),
                                GOVERNOR_MOVING_PARTS)

    def add_event(self, t_ns: int, text: str, level: str = "INFO") -> None:
        """A line of the text log `events` at t_ns [ns] (level: TRACE, DEBUG, INFO, WARN, ERROR, CRITICAL)."""
        with self._lock:
            if self._closed:
                return
            self._stream.set_time(TIMELINE, duration=np.timedelta64(t_ns, "ns"))
            self._stream.log("events", rr.TextLog(text, level=level))

    def flush(self) -> None:
        """Send the buffered samples and animation frames, one column per entity, and empty the buffers."""
        with self._lock:
            self._send_buffers()

    def close(self) -> None:
        """Send everything and finish the sinks (the file gets its footer and is complete); idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._send_buffers()
            self._stream.flush()
            self._stream.disconnect()

    # ---------------------------------------------------------------------------------------------

    def _append(self, entity: str, t_ns: int, value: float) -> None:
        times, values = self._series[entity]
        times.append(t_ns)
        values.append(value)

    def _add_frame(self, root: str, t_ns: int, outline: dict[str, np.ndarray], parts) -> None:
        """Buffer the moving parts of a drawing (metres, y up) as a frame at t_ns, y flipped."""
        for name in parts:
            times, frames = self._frames.setdefault(f"{root}/{name}", ([], []))
            times.append(t_ns)
            frames.append(outline[name] * FLIP_Y)

    def _send_buffers(self) -> None:
        """Send every buffered column: scalars as Scalars, animation frames as partitioned LineStrips2D
        (one or a bundle of strips per frame) or Points2D (a set of points per frame)."""
        for entity, (times, values) in self._series.items():
            if times:
                self._send(entity, times, rr.Scalars.columns(scalars=np.array(values, dtype=float)))
                values.clear()
        for entity, (times, frames) in self._frames.items():
            if not times:
                continue
            if entity.rsplit("/", 1)[1] in POINT_PARTS:
                columns = rr.Points2D.columns(positions=np.concatenate(frames))
                lengths = [len(frame) for frame in frames]
            else:
                columns = rr.LineStrips2D.columns(strips=[strip for frame in frames
                                                          for strip in (frame if frame.ndim == 3 else [frame])])
                lengths = [len(frame) if frame.ndim == 3 else 1 for frame in frames]
            self._send(entity, times, columns.partition(lengths))
            frames.clear()

    def _send(self, entity: str, times: list[int], columns) -> None:
        """send_columns of one entity at times [ns] on the sim_time timeline; empties times."""
        stamps = rr.TimeColumn(TIMELINE, duration=np.array(times, dtype="timedelta64[ns]"))
        self._stream.send_columns(entity, indexes=[stamps], columns=columns)
        times.clear()

    def _current_set_point(self, t_ns: int) -> float:
        """omega_set [rad/s] at t_ns (see the module docstring); a direct governor's is recomputed when the
        external load changed and SET_POINT_REFRESH_NS passed since the last time, and cached by load."""
        governor = self.model.governor
        if governor is None or governor.kind != "direct":
            return self._set_point
        load = self._external_load
        if load != self._set_point_load and t_ns - self._set_point_time >= SET_POINT_REFRESH_NS:
            if load not in self._set_points:
                self._set_points[load] = operating_point(self.model, load).speed
            self._set_point, self._set_point_load, self._set_point_time = self._set_points[load], load, t_ns
        return self._set_point

    def _log_styles(self, root: str, outline: dict[str, np.ndarray], styles: dict, moving) -> None:
        """Log the fixed parts of a drawing (metres, y up) whole and static under root/<part>, y flipped,
        and the moving parts' colours and sizes static (their geometry comes frame by frame)."""
        for name, part in outline.items():
            colour, size = styles[name]
            geometry = part * FLIP_Y if name not in moving else None
            if name in POINT_PARTS:
                radius = ball_radius(self.model.governor.sensor) if size is None else rr.Radius.ui_points(size)
                archetype = rr.Points2D.from_fields(positions=geometry, radii=radius, colors=colour, draw_order=40.0)
            else:
                strips = None if geometry is None else list(geometry) if geometry.ndim == 3 else [geometry]
                archetype = rr.LineStrips2D.from_fields(strips=strips, radii=rr.Radius.ui_points(0.5 * size),
                                                        colors=colour, draw_order=30.0 if name in moving else 10.0)
            self._stream.log(f"{root}/{name}", archetype, static=True)

    def _log_static(self) -> None:
        """The series' styles, the drawings' fixed parts and styles, and the `about` document."""
        band_names = band_series_names(self._delta, self._delta_source)
        for entity in self._series:
            name, colour, width = SERIES_STYLE[entity]
            self._stream.log(entity, rr.SeriesLines(colors=[colour], names=[band_names.get(entity, name)],
                                                    widths=[width]), static=True)
        mechanism = self.model.scene.machine.mechanism
        self._log_styles("mechanism", mechanism_outline(mechanism, self._phi), MECHANISM_STYLE,
                         MECHANISM_MOVING_PARTS[mechanism_kind(mechanism)])
        if self.model.governor is not None:
            sensor = self.model.governor.sensor
            self._log_styles("governor/drawing", governor_outline(sensor, sensor.stop_angles()[0], 0.0),
                             GOVERNOR_STYLE, GOVERNOR_MOVING_PARTS)
        self._stream.log("about", rr.TextDocument(about_text(self.model, self._delta, self._delta_source),
                                                  media_type=rr.MediaType.MARKDOWN), static=True)


def speed_band_delta(model: MachineModel) -> tuple[float, str]:
    """delta [-] of the speed band omega_set (1 +- delta / 2) and where it comes from: the scene's
    analysis.permitted_delta ('permitted'), else 2 analysis.settling_band ('settling')."""
    analysis = model.scene.analysis
    if analysis.permitted_delta is not None:
        return analysis.permitted_delta, "permitted"
    return 2.0 * analysis.settling_band, "settling"


def band_series_names(delta: float, source: str) -> dict[str, str]:
    """Legend names of the band's two series (the speed view's title says where delta comes from)."""
    half = "δ/2" if source == "permitted" else f"{delta / 2:.3g}"
    return {"speed/band_high": f"ω_set (1 + {half})", "speed/band_low": f"ω_set (1 − {half})"}


def band_title(delta: float, source: str) -> str:
    """What the speed band is, for the speed view's title."""
    if source == "permitted":
        return f"band: permitted δ = {delta:.4g}"
    return f"band: settling band ± {delta / 2:.3g}"


def recorded_series(model: MachineModel) -> list[str]:
    """The scalar entities a run of this model records: speed (with set point and band when governed),
    throttle and governor states when governed (servo for indirect action, the dashpot's shift for
    isodromic feedback), and the four moments."""
    series = ["speed/omega"]
    governor = model.governor
    if governor is not None:
        series += ["speed/set_point", "speed/band_high", "speed/band_low", "throttle", "governor/sleeve"]
        if governor.kind == "indirect":
            series.append("governor/servo")
        if "feedback_shift" in governor.state_names:
            series.append("governor/feedback_shift")
    return series + ["moments/drive", "moments/resistance", "moments/external", "moments/net"]


def about_text(model: MachineModel, delta: float, source: str) -> str:
    """Markdown describing the scene and what the series mean (units, set point, band, moments, drawings)."""
    scene = model.scene
    governor = model.governor
    paragraphs = [f"# {scene.name or 'run'}"] + ([scene.description] if scene.description else [])
    paragraphs.append("Time line `sim_time`: simulated time. Crank speed ω in rad/s; moments on the crank in N m: "
                      "drive as applied (throttle included), resistance = the machine's loads and link weights, "
                      "external = minus the external load, net = their sum = J ε + J' ω² / 2.")
    if governor is None:
        paragraphs.append("No governor: no set speed and no band are drawn.")
    else:
        if governor.kind == "indirect":
            paragraphs.append(f"Set speed ω_set = {governor.set_speed():.6g} rad/s: the indirect governor's set speed "
                              "(sleeve at the pilot valve's neutral). Throttle and servo s in 0..1 (the servo "
                              "position is the throttle).")
        else:
            paragraphs.append("Set speed ω_set: where the direct governor settles under the present external load "
                              "(operating point of the cycle-averaged machine; it moves with the load: the static "
                              "error). Throttle in 0..1.")
        if source == "permitted":
            paragraphs.append(f"Band ω_set (1 ± δ/2) with the permitted coefficient of speed fluctuation "
                              f"δ = {delta:.4g} (analysis.permitted_delta).")
        else:
            paragraphs.append(f"Band ω_set (1 ± {delta / 2:.3g}): the settling band (analysis.settling_band); the "
                              "scene gives no analysis.permitted_delta.")
        paragraphs.append("Sleeve rise z (and the dashpot's shift ζ of isodromic feedback) in mm. The governor is "
                          "drawn to scale, its balls as steel spheres of the ball mass, projected on a plane "
                          "through the turning spindle.")
    paragraphs.append("The mechanism is drawn to scale in metres." if scene.machine.mechanism is not None
                      else "The machine has no mechanism: a schematic disc with a spoke shows the crank angle.")
    return "\n\n".join(paragraphs)


def run_blueprint(model: MachineModel) -> rrb.Blueprint:
    """The layout: time series on the left (speed, throttle, sleeve, moments); on the right the mechanism
    (wide) over the governor (tall) beside the events log (with the `about` document in a tab). Each 2-D view
    is framed by the drawing's bounds (y flipped). A machine whose moments vary within a turn shows them
    over a window of MOMENTS_WINDOW before the time cursor, so the cycle stays readable while it plays."""
    governed = model.governor is not None
    plots = [rrb.TimeSeriesView(name=_speed_title(model), origin="speed",
                                plot_legend=rrb.PlotLegend(corner="RightBottom"))]
    if governed:
        plots += [rrb.TimeSeriesView(name="throttle [-]", contents=["/throttle", "/governor/servo"],
                                     plot_legend=rrb.PlotLegend(corner="RightBottom")),
                  rrb.TimeSeriesView(name="governor sleeve [mm]",
                                     contents=["/governor/sleeve", "/governor/feedback_shift"],
                                     plot_legend=rrb.PlotLegend(corner="RightBottom"))]
    cyclic = model.reduced is not None or "phi" in model.depends_on()
    window = rrb.VisibleTimeRange(TIMELINE, start=rrb.TimeRangeBoundary.cursor_relative(seconds=-MOMENTS_WINDOW),
                                  end=rrb.TimeRangeBoundary.cursor_relative(seconds=0.0)) if cyclic else None
    title = f"moments on the crank [N m], last {MOMENTS_WINDOW:g} s" if cyclic else "moments on the crank [N m]"
    plots.append(rrb.TimeSeriesView(name=title, origin="moments", time_ranges=window,
                                    plot_legend=rrb.PlotLegend(corner="RightTop")))
    logs = rrb.Tabs(rrb.TextLogView(name="events", origin="events",
                                    columns=rrb.TextLogColumns(text_log_columns=["LogLevel", "Body"])),
                    rrb.TextDocumentView(name="about", origin="about"))
    mechanism = rrb.Spatial2DView(name="mechanism", origin="mechanism",
                                  visual_bounds=_bounds_y_down(mechanism_bounds(model.scene.machine.mechanism)))
    below = logs
    if governed:
        governor = rrb.Spatial2DView(name="governor", origin="governor/drawing",
                                     visual_bounds=_bounds_y_down(governor_bounds(model.governor.sensor)))
        below = rrb.Horizontal(governor, logs, column_shares=[1.0, 1.3])
    layout = rrb.Horizontal(rrb.Vertical(*plots, row_shares=[2.0] + [1.0] * (len(plots) - 2) + [1.4]),
                            rrb.Vertical(mechanism, below, row_shares=[1.0, 1.8]))
    return rrb.Blueprint(layout, rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"),
                         rrb.TimePanel(state="collapsed", timeline=TIMELINE))


def _speed_title(model: MachineModel) -> str:
    if model.governor is None:
        return "crank speed ω [rad/s]"
    return f"crank speed ω [rad/s]; {band_title(*speed_band_delta(model))}"


def _bounds_y_down(bounds: tuple[float, float, float, float]) -> rrb.VisualBounds2D:
    """VisualBounds2D of drawing bounds (xmin, xmax, ymin, ymax) [m, y up] in Rerun's y-down plane."""
    xmin, xmax, ymin, ymax = bounds
    return rrb.VisualBounds2D(x_range=[xmin, xmax], y_range=[-ymax, -ymin])


def load_change_events(model: MachineModel) -> list[tuple[float, str]]:
    """(time [s], text) of the scenario's external load: its value at t = 0 and each step or ramp (none for a
    scene without an external load)."""
    scenario = model.scene.scenario
    if not model.load_pieces:
        return []
    events = [(0.0, f"external load {scenario.external_load:g} N m")]
    for event in scenario.load_events:
        if event.ramp > 0.0:
            events.append((event.time, f"external load ramps to {event.torque:g} N m over {event.ramp:g} s"))
        else:
            events.append((event.time, f"external load steps to {event.torque:g} N m"))
    return events


def record_run(model: MachineModel, times: np.ndarray, states: np.ndarray, path: Path,
               progress: Progress | None = None) -> None:
    """Record a monolithic simulation sampled at `times` [s] with its states (n_states x n, as
    `trajectory(times)` gives) into the .rrd file `path`, with the scenario's load changes as events.

    Moments from `model.columns`: drive = M_drive; external = M_external (0 without an external load);
    resistance = M_load - M_external + M_weight (the machine's own resisting moments); net = J epsilon +
    1/2 dJ/dphi omega^2. progress(t) is called with the simulated time [s] recorded so far.
    """
    columns = model.columns(times, states)
    count = times.size
    moments = crank_moments(columns)
    governor_keys = [key for key in ("sleeve", "sleeve_velocity", "arm_angle", "throttle", "servo", "feedback_shift")
                     if key in columns]
    stamps = np.round(np.asarray(times) * NANOSECONDS).astype(np.int64)
    recording = RunRecording(model, path=path)
    for time, text in load_change_events(model):
        recording.add_event(int(round(time * NANOSECONDS)), text)
    for i in range(count):
        t_ns = int(stamps[i])
        recording.add_machine(t_ns, float(columns["phi"][i]), float(columns["omega"][i]))
        recording.add_moments(t_ns, *(float(moments[name][i]) for name in ("drive", "resistance", "external", "net")))
        if governor_keys:
            recording.add_governor(t_ns, {key: float(columns[key][i]) for key in governor_keys})
        if (i + 1) % RECORD_RUN_FLUSH_SAMPLES == 0:
            recording.flush()
            if progress is not None:
                progress(float(times[i]))
    recording.close()
    if progress is not None and count:
        progress(float(times[-1]))
