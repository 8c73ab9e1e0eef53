"""Rerun recordings of a run: time series of the speeds, throttle, governor, coupling and moments, an
animation of the mechanism and the governor, and a text log of events, laid out by a blueprint. This module is the
live recorder (RunRecording, the load's changes and the text log, record_run); recording_layout.py holds the series
and the blueprint, recording_pictures.py the drawings.

A RunRecording is fed samples a batch at a time (add_machines, add_governors, ...: the ROS recorder's batches, or
`record_run`'s pieces of a monolithic or co-simulated run), or one by one. Times are whole nanoseconds of SIMULATED
time on the duration timeline `sim_time`. Scalar samples are only appended to lists; `flush()` sends them as
columns. The animation is decimated to `animation_rate` frames per second of simulated time. Rerun's 2-D views have
y pointing down, so the drawings (y up, mechanisms.drawing and governors.drawing) are flipped on the way in.

Only what the scene has is recorded and shown: a throttle, a governor and a set point only with a governor,
the driven part's speed omega_driven with a coupling or a clutch, the coupling's twist with a coupling, the
external load moment on the crank only when the load acts on the crank (behind a coupling or a clutch it acts
on the driven part). The mechanism drawn is the machine's, else the driven part's at phi_driven = phi - twist
(a two-mass machine with a mechanism behind its coupling), else a schematic disc. Each plot names its series
and their colours in its title; the legends are hidden, so they never cover the curves. While the run goes
on the viewer fits the plots' y axes to the data; `close()` sends the blueprint again with each y axis over
the values recorded and a margin of Y_MARGIN (the throttle's over 0..1 at least, the sleeve's over its
stroke), so that no curve runs along a frame and the axes stay put while the run is played back.

Speed set point omega_set (`speed/set_point`): for an indirect governor its set speed
(`Governor.set_speed`, constant); for a direct governor the speed of the operating point of the
cycle-averaged machine at the current external load (`analysis.operating_point`), i.e. where a direct
governor settles (it has a static error); a machine without a governor has no set point and no band.
The band `speed/band_high`, `speed/band_low` is omega_set (1 +- delta / 2) with delta the scene's
`analysis.permitted_delta` or, when the scene gives none, twice its `analysis.settling_band` (then the
band is the settling band around omega_set); the band's name and the `about` document say which.

The text log `events` says what happened: the start (scene, governor, initial speed and load), every change
of the external load as the samples show it (`add_external_load`: a change that goes on at consecutive
samples in one direction is ONE ramp event, logged at its start with its end; a change at a single sample
is a step), the mode changes (`add_mode_change`: the governor's stops and sticking, a clutch's slip) and
the end (`close(status, message)`).
"""

from __future__ import annotations

import contextlib
import errno
import math
import threading
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rerun as rr

from mech_regulator.analysis import operating_point
from mech_regulator.governors.drawing import MOVING_PARTS as GOVERNOR_MOVING_PARTS
from mech_regulator.mechanisms.drawing import MOVING_PARTS as MECHANISM_MOVING_PARTS
from mech_regulator.mechanisms.drawing import mechanism_kind, mechanism_outline
from mech_regulator.model import MachineModel, crank_moments
from mech_regulator.solvers.trajectory import Progress
from mech_regulator.viz.recording_layout import (
    MILLIMETRES,
    MILLIRADIANS,
    SERIES_STYLE,
    TIMELINE,
    about_text,
    governor_signal,
    recorded_series,
    run_blueprint,
    series_names,
    speed_band_delta,
)
from mech_regulator.viz.recording_pictures import (
    FLIP_Y,
    GOVERNOR_STYLE,
    MECHANISM_STYLE,
    drawn_mechanism,
    frame_columns,
    log_drawing,
)

APPLICATION_ID = "mech_regulator"
NANOSECONDS = 1_000_000_000
SET_POINT_REFRESH_NS = 10_000_000  # a direct governor's set point follows a changing load at most every 10 ms
RECORD_RUN_FLUSH_SAMPLES = 20_000  # record_run sends the buffered columns every this many samples


END_LEVELS: dict[str | None, str] = {"complete": "INFO", "tripped": "WARN", "interrupted": "WARN", "failed": "ERROR"}


class RunRecording:
    """One run written to Rerun: a .rrd file (path) and/or a live viewer (connect: gRPC URL such as
    rerun+http://127.0.0.1:9876/proxy), through a recording stream of its own, with the blueprint of
    `run_blueprint`. Feed it samples in time order per stream (streams may interleave), call `flush()`
    every so often and `close()` at the end. Thread-safe; samples given after close() are dropped.
    A sample time earlier than the one before on the machine's or the load's stream starts a new trial
    (the machine was reset): the load's changes are then followed from that sample on."""

    def __init__(
        self,
        model: MachineModel,
        path: Path | None = None,
        connect: str | None = None,
        animation_rate: float = 200.0,
        recording_name: str | None = None,
        outside_throttle: bool = False,
    ):
        if path is None and connect is None:
            raise ValueError("RunRecording needs a file (path) or a viewer to connect to (connect), or both")
        if not animation_rate > 0.0:
            raise ValueError(f"animation_rate = {animation_rate} Hz; expected a positive rate")
        self.model = model
        self.outside_throttle = outside_throttle and model.governor is None  # a throttle without a governor: a
        # controller's outside the model (add_throttles), recorded and shown
        self._lock = threading.Lock()
        self._closed = False
        self._frame_period_ns = max(1, round(NANOSECONDS / animation_rate))
        self._mechanism_frame = self._governor_frame = -1
        self._last_machine_ns = 0
        self._drawing, self._drawn_driven = drawn_mechanism(model)
        self._phi = model.scene.scenario.initial.phi
        self._external_load = model.external_load(0.0)
        self._load_changes = LoadChanges(self._external_load)
        self._delta, self._delta_source = speed_band_delta(model)
        self._set_points: dict[float, float] = {}  # external load [N m] -> direct governor's set point [rad/s]
        self._set_point_load = math.nan
        self._set_point_time = -SET_POINT_REFRESH_NS
        self._set_point = model.governor.set_speed() if model.governor is not None else math.nan
        # a governor without a set speed (NaN: a direct one's) settles where the load puts it: its operating point
        self._set_point_follows_load = model.governor is not None and math.isnan(self._set_point)
        if self._set_point_follows_load:  # the loads the scene holds, computed before the samples come (the ROS
            # recorder's: before the run starts), ~30 ms of CPU each
            held = [model.external_load(piece.start) for piece in model.load_pieces if not piece.slope]
            for load in dict.fromkeys([model.external_load(0.0), *held]):
                self._set_points[load] = operating_point(model, load).speed
        self._series: dict[str, tuple[list[int], list[float]]] = {  # entity -> (times [ns], values)
            entity: ([], []) for entity in recorded_series(model, self.outside_throttle)
        }
        # entity -> (lowest, highest) value recorded; the throttle's plot spans 0..1, the sleeve's its stroke
        self._extents: dict[str, tuple[float, float]] = {}
        if model.governor is not None:
            self._extents = {"throttle": (0.0, 1.0)}
            if model.governor.sensor is not None:  # the sleeve's plot spans its stroke
                stroke = model.governor.sensor.stroke
                self._extents["governor/sleeve"] = (MILLIMETRES * stroke[0], MILLIMETRES * stroke[1])
        if self.outside_throttle:
            self._extents = {"throttle": (0.0, 1.0)}
        self._frames: dict[str, tuple[list[int], list[np.ndarray]]] = {}  # entity -> (times, parts y down)
        self._stream = rr.RecordingStream(APPLICATION_ID)
        self._stream.set_log_time_enabled(False)  # one time line: simulated time, not the wall clock
        sinks = ([rr.FileSink(str(path))] if path is not None else []) + ([rr.GrpcSink(connect)] if connect else [])
        with rerun_write_failures_as_os_errors():
            self._stream.set_sinks(*sinks)
        self._stream.send_blueprint(
            run_blueprint(model, outside_throttle=self.outside_throttle), make_active=True, make_default=True
        )
        self._stream.send_recording_name(recording_name or model.scene.name or "run")
        self._log_static()
        self._log_event(0, start_text(model))

    # ---------------------------------------------------------------------------------------------
    # Samples

    def add_machines(
        self,
        times: np.ndarray,
        phi: np.ndarray,
        omega: np.ndarray,
        driven: dict[str, np.ndarray] | None = None,
        set_point_loads: np.ndarray | None = None,
    ) -> None:
        """Samples of the machine at `times` [ns] (int64, in order): crank angle phi [rad] and speed omega [rad/s]
        and, behind a coupling or a clutch, the driven part's `omega_driven` [rad/s] and a coupling's `twist` = phi -
        phi_driven [rad] (driven, each an array over the times; other keys are ignored). Also the set point and band
        at each time (a direct governor's at the external load [N m] in force there, `set_point_loads`; None: the
        latest add_external_loads gave) and, when a frame is due, the mechanism's picture (a driven part's mechanism
        only when the twist is given)."""
        with self._lock:
            if self._closed or not times.size:
                return
            driven = driven or {}
            stamps = times.tolist()
            self._last_machine_ns = stamps[-1]
            self._extend("speed/omega", times, omega)
            if "omega_driven" in driven and self.model.driven is not None:
                self._extend("speed/driven", times, driven["omega_driven"])
            if "twist" in driven and self.model.coupling is not None:
                self._extend("coupling/twist", times, MILLIRADIANS * driven["twist"])
            loads = set_point_loads.tolist() if set_point_loads is not None else [self._external_load] * len(stamps)
            set_points = np.array([self._current_set_point(when, load) for when, load in zip(stamps, loads)])
            shown = np.isfinite(set_points)
            if shown.any():
                self._extend("speed/set_point", times[shown], set_points[shown])
                self._extend("speed/band_high", times[shown], set_points[shown] * (1.0 + 0.5 * self._delta))
                self._extend("speed/band_low", times[shown], set_points[shown] * (1.0 - 0.5 * self._delta))
            self._phi = float(phi[-1])
            if self._drawn_driven and "twist" not in driven:
                return
            angles = (phi - driven["twist"] if self._drawn_driven else phi).tolist()
            outline_kind = MECHANISM_MOVING_PARTS[mechanism_kind(self._drawing)]
            for row in self._frames_due(times, "_mechanism_frame"):
                self._add_frame("mechanism", stamps[row], mechanism_outline(self._drawing, angles[row]), outline_kind)

    def add_machine(self, t_ns: int, phi: float, omega: float, driven: dict[str, float] | None = None) -> None:
        """One sample of the machine at t_ns [ns] (add_machines), its set point at the latest external load."""
        self.add_machines(
            np.array([t_ns]),
            np.array([phi]),
            np.array([omega]),
            {key: np.array([value]) for key, value in (driven or {}).items()},
        )

    @property
    def external_load(self) -> float:
        """The external load [N m] given last (add_external_loads; at first the scene's at t = 0), in force until the
        next."""
        return self._external_load

    def add_moments(
        self, times: np.ndarray, drive: np.ndarray, resistance: np.ndarray, external: np.ndarray, net: np.ndarray
    ) -> None:
        """Moments on the crank [N m] at `times` [ns] (int64, in order), each an array over the times: the drive as
        applied (throttle included), the machine's resisting moments (loads, link weight, what a coupling or clutch
        takes; not the external load), the external moment (minus the external load; not recorded behind a coupling
        or a clutch, where the load acts on the driven part) and their sum, the net moment J epsilon + 1/2 J'
        omega^2."""
        with self._lock:
            if self._closed:
                return
            for entity, values in (
                ("moments/drive", drive),
                ("moments/resistance", resistance),
                ("moments/external", external),
                ("moments/net", net),
            ):
                if entity in self._series:
                    self._extend(entity, times, values)

    def add_external_loads(self, times: np.ndarray, loads: np.ndarray) -> None:
        """The external load [N m] (its magnitude, opposing motion) applied from each of `times` [ns] (int64, in
        order) on, as samples: the latest sets a direct governor's set point (add_machines), and their changes become
        events (see LoadChanges: a ramp over consecutive samples is one event with its start and end, a change at one
        sample a step)."""
        with self._lock:
            if self._closed or not times.size:
                return
            for when, load in zip(times.tolist(), loads.tolist()):
                for change, text in self._load_changes.sample(when, load):
                    self._log_event(change, text)
            self._external_load = float(loads[-1])

    def add_external_load(self, t_ns: int, load: float) -> None:
        """The external load [N m] applied from t_ns [ns] on, one sample (add_external_loads)."""
        self.add_external_loads(np.array([t_ns]), np.array([load]))

    def add_governors(
        self, times: np.ndarray, values: dict[str, np.ndarray], crank_angles: np.ndarray | None = None
    ) -> None:
        """Samples of the governor at `times` [ns] (int64, in order), each value an array over the times: throttle [-]
        and its signal (governor_signal: a centrifugal governor's sleeve [m], with arm_angle [rad], and with isodromic
        feedback feedback_shift [m]; a PI governor's integral part [-]; other keys, such as an indirect governor's
        servo, which is its throttle, are ignored); also a centrifugal governor's picture when a frame is due, its
        spindle at ratio * the crank angle (`crank_angles` [rad] at each time; None: the latest machine sample's)."""
        with self._lock:
            if self._closed or not times.size:
                return
            governor = self.model.governor
            assert governor is not None, "add_governors records a governed model"
            self._extend("throttle", times, values["throttle"])
            entity, key, factor, _ = governor_signal(governor)
            self._extend(entity, times, factor * values[key])
            if "feedback_shift" in values:
                self._extend("governor/feedback_shift", times, MILLIMETRES * values["feedback_shift"])
            sensor = governor.sensor
            if sensor is None:
                return
            stamps = times.tolist()
            for row in self._frames_due(times, "_governor_frame"):
                crank = self._phi if crank_angles is None else float(crank_angles[row])
                self._add_frame(
                    "governor/drawing",
                    stamps[row],
                    sensor.outline(float(values["arm_angle"][row]), sensor.ratio * crank),
                    GOVERNOR_MOVING_PARTS,
                )

    def add_governor(self, t_ns: int, values: dict[str, float]) -> None:
        """One sample of the governor at t_ns [ns] (add_governors), its spindle at the latest crank angle."""
        self.add_governors(np.array([t_ns]), {key: np.array([value]) for key, value in values.items()})

    def add_throttles(self, times: np.ndarray, throttle: np.ndarray) -> None:
        """The throttle [-] a controller outside the model applied from each of `times` [ns] (outside_throttle; a
        governor's comes with add_governors)."""
        with self._lock:
            if not self._closed:
                self._extend("throttle", times, throttle)

    def add_mode_change(self, t_ns: int, what: str) -> None:
        """A mode change at t_ns [ns] in the text log: the governor's (a stop reached, the sleeve sticking or
        breaking away) or the drive train's (a clutch locking or slipping), `what` as the solvers name it."""
        self.add_event(t_ns, what)

    def add_event(self, t_ns: int, text: str, level: str = "INFO") -> None:
        """A line of the text log `events` at t_ns [ns] (level: TRACE, DEBUG, INFO, WARN, ERROR, CRITICAL)."""
        with self._lock:
            if self._closed:
                return
            self._log_event(t_ns, text, level)

    def flush(self) -> None:
        """Send the buffered samples and animation frames, one column per entity, and empty the buffers."""
        with self._lock:
            self._send_buffers()

    def close(self, status: str | None = None, message: str = "") -> None:
        """Log a load change still going on and the end of the run at the latest machine sample (how the run
        ended: status 'complete', 'tripped' (an overspeed trip closed the throttle), 'interrupted' or 'failed' with
        its message; None: only that the recording ends
        there), send everything, then the final blueprint, whose plots span the values recorded (run_blueprint's
        extents), and finish the sinks (the file gets its footer and is complete); idempotent."""
        with self._lock:
            if self._closed:
                return
            for when, text in self._load_changes.finish():
                self._log_event(when, text)
            self._log_event(
                self._last_machine_ns, end_text(self._last_machine_ns, status, message), END_LEVELS.get(status, "INFO")
            )
            self._closed = True
            self._send_buffers()
            self._stream.send_blueprint(
                run_blueprint(self.model, self._extents, self.outside_throttle), make_active=True, make_default=True
            )
            finish_stream(self._stream)

    # ---------------------------------------------------------------------------------------------

    def _extend(self, entity: str, times: np.ndarray, values: np.ndarray) -> None:
        """Buffer samples of a series at `times` [ns] and widen the series' extent to them (NaN or infinite ones
        leave it)."""
        series_times, series_values = self._series[entity]
        series_times.extend(times.tolist())
        series_values.extend(values.tolist())
        finite = values[np.isfinite(values)]
        if finite.size:
            lowest, highest = float(finite.min()), float(finite.max())
            low, high = self._extents.get(entity, (lowest, highest))
            self._extents[entity] = (min(low, lowest), max(high, highest))

    def _frames_due(self, times: np.ndarray, latest: str) -> list[int]:
        """The rows of `times` [ns] at which a frame of the animation is due (a new frame period begins, the first
        against the frame of the attribute `latest`), which is then set to the last row's frame."""
        frames = times // self._frame_period_ns
        due = np.flatnonzero(frames != np.append(getattr(self, latest), frames[:-1]))
        setattr(self, latest, int(frames[-1]))
        return due.tolist()

    def _log_event(self, t_ns: int, text: str, level: str = "INFO") -> None:
        """Log a line of the text log at t_ns [ns] (the caller holds the lock)."""
        self._stream.set_time(TIMELINE, duration=np.timedelta64(t_ns, "ns"))
        self._stream.log("events", rr.TextLog(text, level=level))

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
            self._send(entity, times, frame_columns(entity.rsplit("/", 1)[1], frames))
            frames.clear()

    def _send(self, entity: str, times: list[int], columns) -> None:
        """send_columns of one entity at times [ns] on the sim_time timeline; empties times."""
        stamps = rr.TimeColumn(TIMELINE, duration=np.array(times, dtype="timedelta64[ns]"))
        self._stream.send_columns(entity, indexes=[stamps], columns=columns)
        times.clear()

    def _current_set_point(self, t_ns: int, load: float) -> float:
        """omega_set [rad/s] at t_ns with the external load `load` [N m] in force (see the module docstring); a
        direct governor's is recomputed when the load changed and SET_POINT_REFRESH_NS passed since the last time,
        and cached by load."""
        if not self._set_point_follows_load:
            return self._set_point
        if load != self._set_point_load and abs(t_ns - self._set_point_time) >= SET_POINT_REFRESH_NS:
            if load not in self._set_points:
                self._set_points[load] = operating_point(self.model, load).speed
            self._set_point, self._set_point_load, self._set_point_time = self._set_points[load], load, t_ns
        return self._set_point

    def _log_static(self) -> None:
        """The series' styles, the drawings' fixed parts and styles, and the `about` document."""
        names = series_names(self.model, self.outside_throttle)
        for entity in self._series:
            _, colour, width = SERIES_STYLE[entity]
            self._stream.log(
                entity, rr.SeriesLines(colors=[colour], names=[names[entity]], widths=[width]), static=True
            )
        initial = self.model.initial_state()
        angle = initial[0] - initial[self.model.coupling_index] if self._drawn_driven else initial[0]
        log_drawing(
            self._stream,
            "mechanism",
            mechanism_outline(self._drawing, angle),
            MECHANISM_STYLE,
            MECHANISM_MOVING_PARTS[mechanism_kind(self._drawing)],
        )
        sensor = self.model.governor.sensor if self.model.governor is not None else None
        if sensor is not None:  # a governor without a centrifugal sensor is not drawn
            log_drawing(
                self._stream,
                "governor/drawing",
                sensor.outline(sensor.stop_angles()[0], 0.0),
                GOVERNOR_STYLE,
                GOVERNOR_MOVING_PARTS,
                sensor.ball_radius(),
            )
        self._stream.log(
            "about",
            rr.TextDocument(
                about_text(self.model, self._delta, self._delta_source, self.outside_throttle),
                media_type=rr.MediaType.MARKDOWN,
            ),
            static=True,
        )


@dataclass
class _Change:
    """A change of the external load in progress: from start_load [N m] at start_ns to end_load at end_ns [ns]
    over `samples` consecutive samples, rising (direction +1) or falling (-1)."""

    start_ns: int
    start_load: float
    end_ns: int
    end_load: float
    direction: float
    samples: int = 1


class LoadChanges:
    """Turns samples of the external load [N m] into events, by what the samples show (the scenario's
    load, or one published by anybody): a change that goes on at consecutive samples in one direction is one
    ramp, 'load ramp a -> b N m over t0-t1 s' at its start t0 (the last sample before it changed) with its end
    t1 (the last sample that changed), logged once the ramp is over; a change at one sample only is a step,
    'load step a -> b N m', at that sample. A sample earlier than the one before starts afresh (a new trial)."""

    def __init__(self, load: float):
        self._load = load  # [N m] at the latest sample (at first: the scene's at t = 0)
        self._time: int | None = None  # [ns] of the latest sample
        self._change: _Change | None = None

    def sample(self, t_ns: int, load: float) -> list[tuple[int, str]]:
        """Take the load [N m] at t_ns [ns]; returns the events (time [ns], text) that it completes."""
        events: list[tuple[int, str]] = []
        if self._time is not None and t_ns < self._time:  # time went back: a new trial starts here
            events, self._time, self._load = self.finish(), t_ns, load
            return events
        if load == self._load:
            events = self.finish()
        else:
            direction = math.copysign(1.0, load - self._load)
            if self._change is not None and direction != self._change.direction:
                events = self.finish()
            if self._change is None:
                start = self._time if self._time is not None else t_ns
                self._change = _Change(start, self._load, t_ns, load, direction, samples=0)
            self._change.end_ns, self._change.end_load = t_ns, load
            self._change.samples += 1
        self._time, self._load = t_ns, load
        return events

    def finish(self) -> list[tuple[int, str]]:
        """End the change in progress, if any: its event (time [ns], text) as a list of none or one."""
        change, self._change = self._change, None
        if change is None:
            return []
        if change.samples == 1:
            return [(change.end_ns, f"load step {change.start_load:.6g} -> {change.end_load:.6g} N m")]
        return [
            (
                change.start_ns,
                f"load ramp {change.start_load:.6g} -> {change.end_load:.6g} N m over "
                f"{change.start_ns / NANOSECONDS:.3f}-{change.end_ns / NANOSECONDS:.3f} s",
            )
        ]


def start_text(model: MachineModel) -> str:
    """The first line of the text log: the initial speed, the external load at t = 0 (with a load in the
    scene), the scene and its governor (or none)."""
    scene = model.scene
    if model.governor is None:
        governor = "no governor"
    else:
        governor = model.governor.title()
    speed = f"start: ω = {scene.scenario.initial.omega:.6g} rad/s"
    if model.load_pieces:
        where = " on the driven part" if model.driven is not None else ""
        speed += f", load {model.external_load(0.0):.6g} N m{where}"
    return f"{speed}; {scene.name or 'run'}, {governor}"


def end_text(t_ns: int, status: str | None, message: str) -> str:
    """The last line of the text log: how the run ended at t_ns [ns] (status None: the recording ends)."""
    when = f"t = {t_ns / NANOSECONDS:.3f} s"
    if status is None:
        return f"end of the recording at {when}"
    return f"end: {status} at {when}" + (f": {message}" if message else "")


@contextlib.contextmanager
def rerun_write_failures_as_os_errors() -> Iterator[None]:
    """Raise a Rerun sink's failure to write (a full disk, a file that cannot be made; Rerun raises RuntimeError and
    logs why) as OSError, as any other failed write of a file is raised, so a command keeps what it computed and
    says which file is incomplete (cli/report/outputs.OutputWriter)."""
    try:
        yield
    except RuntimeError as error:
        raise OSError(errno.EIO, f"the recording's writer stopped ({error})") from None


def finish_stream(stream: rr.RecordingStream) -> None:
    """Send what a Rerun stream holds and end its sinks; a file sink that could not write raises OSError
    (rerun_write_failures_as_os_errors)."""
    try:
        with rerun_write_failures_as_os_errors():
            stream.flush()
    finally:
        stream.disconnect()


def record_run(
    model: MachineModel,
    times: np.ndarray,
    states: np.ndarray,
    path: Path,
    progress: Progress | None = None,
    *,
    mode_changes: Iterable[tuple[float, str]] = (),
    status: str | None = None,
    message: str = "",
) -> None:
    """Record a run sampled at `times` [s] with its states (n_states x n, as `trajectory(times)` gives, or a
    co-simulation's exchange times and states) into the .rrd file `path`, with the same events as the ROS
    recorder logs: the start, the external load's changes as its samples show them (the scenario's load at
    `times`), the mode changes (time [s], what: a Trajectory's `events`, or a co-simulation's events without
    their modes) and the end (status and message of the run; None: the recording just ends).

    Moments from `model.columns`: drive = M_drive; external = M_external (0 without an external load);
    resistance = M_load - M_external + M_weight (the machine's own resisting moments); net = J epsilon +
    1/2 dJ/dphi omega^2. progress(t) is called with the simulated time [s] recorded so far.
    """
    columns = model.columns(times, states)
    count = times.size
    moments = crank_moments(columns)
    governor_keys = [
        key
        for key in ("sleeve", "sleeve_velocity", "arm_angle", "integral", "throttle", "feedback_shift")
        if key in columns
    ]
    driven_keys = [key for key in ("twist", "omega_driven") if key in columns]
    stamps = np.round(np.asarray(times) * NANOSECONDS).astype(np.int64)
    recording = RunRecording(model, path=path)
    for time, what in mode_changes:
        recording.add_mode_change(int(round(time * NANOSECONDS)), what)
    for start in range(0, count, RECORD_RUN_FLUSH_SAMPLES):
        rows = slice(start, start + RECORD_RUN_FLUSH_SAMPLES)
        loads = np.array([model.external_load(float(time)) for time in times[rows]])
        recording.add_external_loads(stamps[rows], loads)
        recording.add_machines(
            stamps[rows],
            columns["phi"][rows],
            columns["omega"][rows],
            {key: columns[key][rows] for key in driven_keys},
            set_point_loads=loads,
        )
        recording.add_moments(
            stamps[rows], *(moments[name][rows] for name in ("drive", "resistance", "external", "net"))
        )
        if governor_keys:
            recording.add_governors(
                stamps[rows], {key: columns[key][rows] for key in governor_keys}, crank_angles=columns["phi"][rows]
            )
        if stamps[rows].size == RECORD_RUN_FLUSH_SAMPLES:
            recording.flush()
            if progress is not None:
                progress(float(times[rows][-1]))
    recording.close(status, message)
    if progress is not None and count:
        progress(float(times[-1]))
