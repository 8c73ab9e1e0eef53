"""Tests of the Rerun recording layer (mech_regulator.viz.recording), read back from the .rrd files with
rerun.chunk.RrdReader: entities, the sim_time time line, every sample fed and its value, the animation's
frame count and geometry, the set point and band, the moments' decomposition, the events (start, load steps
and ramps as one row each, mode changes, end) from a monolithic and a co-simulated run, the blueprints (views
named for what the scene has, hidden legends, y axes over the data), `rerun rrd verify`, the set-point
cache, and the animation's columns (the strips as Rerun converts them one by one; a linkage's frames sent without
the C heap keeping what the conversion took). No ROS.

A .rrd stores the scalars as float64, so values read back equal the values fed exactly; drawings are
stored as float32, hence the 1e-6 m tolerance on positions of size 0.2 m (float32 resolution ~1e-8 m).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
import rerun as rr
from rerun.chunk import RrdReader

from mech_regulator.analysis import operating_point
from mech_regulator.governors.drawing import COLLAR_RADIUS
from mech_regulator.mechanisms.drawing import MOVING_PARTS as MECHANISM_MOVING_PARTS
from mech_regulator.mechanisms.drawing import mechanism_kind, mechanism_outline
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene, validate_scene
from mech_regulator.solvers import simulate
from mech_regulator.solvers.cosim import cosimulate
from mech_regulator.viz import recording, recording_layout, recording_pictures
from mech_regulator.viz.recording import LoadChanges, RunRecording, record_run

RERUN = Path(sys.executable).with_name("rerun")
SAMPLE_RATE = 1000.0  # [Hz] of the samples fed
DURATION = 0.5  # [s] simulated
NS = 1_000_000_000

SHORT_ENGINE = ["scenario.duration=0.5", "scenario.load_events.0.time=0.2", "scenario.load_events.1.time=0.4"]
# engine_indirect_isodromic in 0.6 s: 6 -> 8 N m at 0.1 s, then ramped down to 4 N m over 0.3-0.5 s
SHORT_ISODROMIC = [
    "scenario.duration=0.6",
    "scenario.load_events.0.time=0.1",
    "scenario.load_events.1.time=0.3",
    "scenario.load_events.1.ramp=0.2",
]
SHORT_TWO_MASS = ["scenario.duration=0.3", "scenario.load_events.0.time=0.1"]  # 6 -> 8 N m at 0.1 s


def chunks(path: Path, entity: str, static: bool = False) -> list:
    """Record batches of one entity's static or temporal chunks."""
    return [
        chunk.to_record_batch()
        for chunk in RrdReader(path).store().stream()
        if chunk.entity_path == entity and chunk.is_static == static
    ]


def temporal(path: Path, entity: str, component: str) -> tuple[np.ndarray, list]:
    """(sim_time stamps [ns], values of `component`) of one entity, in time order."""
    times, values = [], []
    for batch in chunks(path, entity):
        times += batch.column("sim_time").cast(pa.int64()).to_pylist()
        values += batch.column(component).to_pylist()
    order = np.argsort(times, kind="stable")
    return np.asarray(times)[order], [values[i] for i in order]


def scalars(path: Path, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """(sim_time stamps [ns], scalar values) of one Scalars entity, in time order."""
    times, values = temporal(path, entity, "Scalars:scalars")
    assert all(len(value) == 1 for value in values)
    return times, np.array([value[0] for value in values])


def static_value(path: Path, entity: str, component: str):
    (batch,) = chunks(path, entity, static=True)
    return batch.column(component).to_pylist()[0]


def events(path: Path) -> list[tuple[int, str, str]]:
    """(sim_time [ns], level, text) of every row of the text log, in time order."""
    stamps, texts = temporal(path, "/events", "TextLog:text")
    levels = temporal(path, "/events", "TextLog:level")[1]
    return [(int(stamp), level[0], text[0]) for stamp, level, text in zip(stamps, levels, texts)]


def blueprint_views(path: Path) -> list[dict[str, dict]]:
    """The views of each blueprint in the file: view id -> {'name', and 'range' (ScalarAxis), 'legend_visible'
    (PlotLegend) when the blueprint sets them}."""
    reader = RrdReader(path)
    blueprints = []
    for entry in reader.blueprints():
        views: dict[str, dict] = {}
        for chunk in reader.store(store=entry).stream():
            parts = chunk.entity_path.strip("/").split("/")
            if parts[0] != "view":
                continue
            batch = chunk.to_record_batch()
            view = views.setdefault(parts[1], {})
            for column, key in (
                ("ViewBlueprint:display_name", "name"),
                ("ScalarAxis:range", "range"),
                ("PlotLegend:visible", "legend_visible"),
            ):
                if column in batch.schema.names:
                    view[key] = batch.column(column).to_pylist()[-1][0]
        blueprints.append(views)
    return blueprints


def final_blueprint(path: Path) -> dict[str, dict]:
    """The views of the blueprint close() sends, which frames the plots' y axes: view name -> its settings."""
    (views,) = [views for views in blueprint_views(path) if any("range" in view for view in views.values())]
    return {view["name"]: view for view in views.values()}


@pytest.fixture(scope="module")
def engine_run(tmp_path_factory):
    """engine_direct shortened to 0.5 s (loads 6 -> 8 N m at 0.2 s -> 0 at 0.4 s), recorded at 1 kHz."""
    model = build_model(load_scene("engine_direct", SHORT_ENGINE))
    trajectory = simulate(model)
    assert trajectory.status == "complete", trajectory.message
    times = trajectory.samples(SAMPLE_RATE)
    states = trajectory(times)
    path = tmp_path_factory.mktemp("recording") / "engine_direct.rrd"
    record_run(
        model, times, states, path, mode_changes=trajectory.events, status=trajectory.status, message=trajectory.message
    )
    return model, times, states, path, trajectory.events


def test_short_engine_scene_validates_with_its_overrides():
    scene = load_scene("engine_direct", SHORT_ENGINE)
    assert scene.scenario.duration == DURATION
    assert [event.time for event in scene.scenario.load_events] == [0.2, 0.4]
    assert [event.torque for event in scene.scenario.load_events] == [8.0, 0.0]


def test_recording_has_the_entities_one_time_line_and_a_blueprint(engine_run):
    _, _, _, path, _ = engine_run
    reader = RrdReader(path)
    # the blueprint of the start (a recording cut short keeps a layout) and the final one of close()
    assert len(reader.recordings()) == 1 and len(reader.blueprints()) == 2
    schema = reader.store().schema()
    expected = {
        "/speed/omega",
        "/speed/set_point",
        "/speed/band_high",
        "/speed/band_low",
        "/throttle",
        "/governor/sleeve",
        "/moments/drive",
        "/moments/resistance",
        "/moments/external",
        "/moments/net",
        "/events",
        "/about",
        "/mechanism/crank",
        "/mechanism/rod",
        "/mechanism/slider",
        "/mechanism/guide",
        "/mechanism/joints",
        "/governor/drawing/spindle",
        "/governor/drawing/upper_arms",
        "/governor/drawing/lower_links",
        "/governor/drawing/balls",
        "/governor/drawing/sleeve",
        "/governor/drawing/stops",
    }
    entities = set(schema.entity_paths())
    assert expected <= entities, expected - entities
    assert "/governor/servo" not in entities  # a direct governor has no servo-motor
    assert not any(entity.startswith(("/speed/driven", "/coupling")) for entity in entities)  # nor a driven part
    assert [index.name for index in schema.index_columns()] == ["sim_time"]  # no wall-clock log_time


def test_every_sample_fed_is_recorded_at_its_time_with_its_value(engine_run):
    model, times, states, path, _ = engine_run
    stamps = np.round(times * NS).astype(np.int64)
    omega_times, omega = scalars(path, "/speed/omega")
    assert omega.size == times.size == int(DURATION * SAMPLE_RATE) + 1
    assert np.array_equal(omega_times, stamps)
    assert np.array_equal(omega, states[1])
    columns = model.columns(times, states)
    sleeve_times, sleeve = scalars(path, "/governor/sleeve")
    assert np.array_equal(sleeve_times, stamps)
    assert np.allclose(sleeve, 1000.0 * columns["sleeve"], rtol=1e-15, atol=0.0)  # plotted in mm
    assert "[mm]" in static_value(path, "/governor/sleeve", "SeriesLines:names")[0]
    assert np.array_equal(scalars(path, "/throttle")[1], columns["throttle"])


def test_moments_add_up_to_the_net_moment(engine_run):
    model, times, states, path, _ = engine_run
    drive, resistance, external, net = (
        scalars(path, f"/moments/{name}")[1] for name in ("drive", "resistance", "external", "net")
    )
    assert drive.size == times.size
    scale = np.max(np.abs(drive))
    assert np.max(np.abs(drive + resistance + external - net)) <= 1e-12 * scale
    loads = np.array([model.external_load(t) for t in times])
    assert np.array_equal(external, -loads)
    assert np.all(resistance < 0.0)  # viscous and fan loads resist a turning crank


def test_set_point_follows_the_load_and_the_band_is_the_permitted_delta(engine_run):
    model, times, _, path, _ = engine_run
    set_times, set_point = scalars(path, "/speed/set_point")
    assert set_point.size == times.size
    for load, start, end in ((6.0, 0.0, 0.2), (8.0, 0.2, 0.4), (0.0, 0.4, DURATION + 1.0)):
        speed = operating_point(model, load).speed
        # record_run gives the load of a time before the machine's sample of that time
        inside = (set_times >= start * NS) & (set_times < end * NS)
        assert np.any(inside) and np.all(set_point[inside] == speed), (load, np.unique(set_point[inside]))
    delta = model.scene.analysis.permitted_delta
    assert delta == 0.05
    assert np.allclose(scalars(path, "/speed/band_high")[1], set_point * (1 + delta / 2), rtol=1e-15)
    assert np.allclose(scalars(path, "/speed/band_low")[1], set_point * (1 - delta / 2), rtol=1e-15)


def test_animation_is_decimated_to_the_animation_rate_and_flipped(engine_run):
    model, times, states, path, _ = engine_run
    rate = 200.0  # RunRecording's default [Hz]
    frame_times, strips = temporal(path, "/mechanism/crank", "LineStrips2D:strips")
    assert abs(len(frame_times) - DURATION * rate) <= 1
    assert np.allclose(np.diff(frame_times), NS / rate)
    R = model.scene.machine.mechanism.crank
    for stamp, (strip,) in zip(frame_times, strips):
        phi = np.interp(stamp / NS, times, states[0])
        # the pin B = R (cos phi, sin phi), y up, drawn with y down
        assert np.allclose(strip[1], [R * math.cos(phi), -R * math.sin(phi)], atol=1e-6)
    ball_times, balls = temporal(path, "/governor/drawing/balls", "Points2D:positions")
    assert np.array_equal(ball_times, frame_times)
    l = model.governor.sensor.arm_length
    ratio = model.governor.sensor.ratio
    mark_times, marks = temporal(path, "/governor/drawing/spindle_mark", "Points2D:positions")
    assert np.array_equal(mark_times, frame_times)
    radius = COLLAR_RADIUS * l
    for stamp, (ball, _), (mark,) in zip(ball_times, balls, marks):
        phi, arm = (np.interp(stamp / NS, times, row) for row in (states[0], states[2]))
        assert np.allclose(ball, [l * math.sin(arm), l * math.cos(arm)], atol=1e-6)
        assert mark[0] == pytest.approx(radius * math.cos(ratio * phi), abs=1e-6)  # turns with the spindle


def test_text_log_has_the_start_the_load_steps_the_mode_changes_and_the_end(engine_run):
    model, _, _, path, mode_changes = engine_run
    expected = [
        (0, "INFO", "start: ω = 224.17 rad/s, load 6 N m; engine_direct, direct governor"),
        (int(0.2 * NS), "INFO", "load step 6 -> 8 N m"),
        (int(0.4 * NS), "INFO", "load step 8 -> 0 N m"),
        (int(DURATION * NS), "INFO", "end: complete at t = 0.500 s"),
    ]
    expected += [(int(round(time * NS)), "INFO", what) for time, what in mode_changes]
    assert model.scene.scenario.initial.omega == 224.17
    assert sorted(events(path)) == sorted(expected)


def test_final_blueprint_hides_the_legends_and_spans_the_data(engine_run):
    """The titles name the series and their colours; the y axes span the values recorded with a margin (the
    throttle at least 0..1, the sleeve its stroke), so no legend and no curve sits on the frame."""
    model, _, _, path, _ = engine_run
    views = final_blueprint(path)
    plots = {name: view for name, view in views.items() if "range" in view}
    assert set(plots) == {
        "speed [rad/s]: ω crank (blue) · ω_set (white) · band (orange) ±δ/2, permitted δ = 0.05",
        "throttle [-]",
        "sleeve z [mm]",
        f"moments [N m], last {recording_layout.moments_window(model):.2g} s: drive (green) · "
        "resistance (red) · external (violet) · net (white)",
    }
    assert all(view["legend_visible"] is False for view in plots.values())
    omega = scalars(path, "/speed/omega")[1]
    band = scalars(path, "/speed/band_high")[1], scalars(path, "/speed/band_low")[1]
    low, high = plots[next(name for name in plots if name.startswith("speed"))]["range"]
    data_low, data_high = min(omega.min(), band[1].min()), max(omega.max(), band[0].max())
    margin = recording_layout.Y_MARGIN * (data_high - data_low)
    assert (low, high) == pytest.approx((data_low - margin, data_high + margin), rel=1e-12)
    throttle = plots["throttle [-]"]["range"]
    assert throttle[0] < 0.0 and throttle[1] > 1.0
    stroke = model.governor.sensor.stroke
    sleeve = plots["sleeve z [mm]"]["range"]
    assert sleeve[0] < 1000.0 * stroke[0] and sleeve[1] > 1000.0 * stroke[1]
    assert "crank–slider" in views and "governor" in views


def test_rerun_verifies_the_file(engine_run):
    _, _, _, path, _ = engine_run
    result = subprocess.run([str(RERUN), "rrd", "verify", str(path)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr


# --------------------------------------------------------------------------------------------
# RunRecording fed by hand


def governed_model(load_events: list[dict], indirect: bool = False):
    """The constant-J machine of docs' governor example (fast statics), direct or indirect."""
    governor = {
        "type": "direct",
        "ball_mass": 1.0,
        "arm_length": 0.2,
        "sleeve_mass": 5.0,
        "damping": 200.0,
        "ratio": 0.16,
        "stroke": [0.02, 0.08],
        "valve": {"open_at": 0.02, "closed_at": 0.08},
    }
    if indirect:
        governor = {
            **{k: v for k, v in governor.items() if k != "valve"},
            "type": "indirect",
            "pilot_neutral": 0.05,
            "servo": {"gain": 20.0},
            "feedback": {"type": "isodromic", "gain": 0.3, "time_constant": 1.5},
        }
    scene = {
        "machine": {
            "inertia": 0.5,
            "drive": {"type": "linear_motor", "stall_torque": 200.0, "no_load_speed": 150.0},
            "loads": [{"type": "viscous", "coefficient": 0.3}],
        },
        "governor": governor,
        "scenario": {"initial": {"omega": 112.86}, "duration": 2.0, "load_events": load_events},
    }
    return build_model(validate_scene(scene))


def test_interleaved_streams_flushed_in_pieces_and_closed_twice(tmp_path):
    """Streams interleave, flush() comes every so often, close() twice; samples after close are dropped."""
    model = governed_model([], indirect=True)
    path = tmp_path / "indirect.rrd"
    run = RunRecording(model, path=path, animation_rate=50.0)
    count = 400
    for i in range(count):
        t_ns = i * 1_000_000  # 1 kHz for 0.4 s
        run.add_governor(
            t_ns,
            {
                "sleeve": 0.05,
                "sleeve_velocity": 0.0,
                "throttle": 0.5,
                "servo": 0.5,
                "arm_angle": model.governor.sensor.arm_angle(0.05),
                "feedback_shift": 0.001 * i / count,
            },
        )
        run.add_machine(t_ns, 0.1 * i, 110.0)
        run.add_moments(np.array([t_ns]), *np.array([[10.0], [-9.0], [0.0], [1.0]]))  # a batch of one
        if i % 97 == 0:
            run.flush()
    run.close()
    run.close()
    run.add_machine(count * 1_000_000, 0.0, 1.0)
    assert scalars(path, "/speed/omega")[1].size == count
    assert scalars(path, "/throttle")[1].size == count
    assert "/governor/servo" not in RrdReader(path).store().schema().entity_paths()  # the servo is the throttle
    # no status given: the end row says only where the recording ends (the latest machine sample)
    assert events(path)[-1] == ((count - 1) * 1_000_000, "INFO", "end of the recording at t = 0.399 s")
    shift = scalars(path, "/governor/feedback_shift")[1]
    assert shift[-1] == pytest.approx(1000.0 * 0.001 * (count - 1) / count)  # in mm
    set_point = scalars(path, "/speed/set_point")[1]
    assert np.all(set_point == model.governor.set_speed())  # indirect: constant
    assert len(temporal(path, "/mechanism/spoke", "LineStrips2D:strips")[0]) == 20  # 0.4 s at 50 Hz
    assert len(temporal(path, "/governor/drawing/upper_arms", "LineStrips2D:strips")[0]) == 20
    result = subprocess.run([str(RERUN), "rrd", "verify", str(path)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr


def counting_operating_point(monkeypatch) -> list[float]:
    """Make the recording's operating_point count its calls; returns the list of loads it was called with."""
    calls = []

    def counted(model, load):
        calls.append(load)
        return operating_point(model, load)

    monkeypatch.setattr(recording, "operating_point", counted)
    return calls


def test_direct_set_point_follows_a_ramp_at_most_every_10_ms(tmp_path, monkeypatch):
    model = governed_model([{"time": 0.5, "torque": 10.0, "ramp": 1.0}])
    calls = counting_operating_point(monkeypatch)
    run = RunRecording(model, path=tmp_path / "ramp.rrd")
    for i in range(2001):  # 2 s at 1 kHz: 0.5 s still, 1 s ramp, 0.5 s still
        run.add_machine(i * 1_000_000, 0.0, 112.0)
        run.add_external_load(i * 1_000_000, model.external_load(i / 1000.0))
    run.close("complete")
    # the loads the scene holds, 0 and 10 N m, before the samples; then every 10 ms along the 1 s ramp (about 100
    # loads between them)
    assert calls[:2] == [0.0, 10.0]
    assert 93 <= len(calls) - 2 <= 100, len(calls)
    assert np.all(np.diff(calls[2:]) > 0.0) and 0.0 < calls[2] and calls[-1] < 10.0
    set_point = scalars(tmp_path / "ramp.rrd", "/speed/set_point")[1]
    assert set_point[-1] == operating_point(model, 10.0).speed
    # the ramp over 1000 samples is one row, at its start, with its end
    assert [text for _, _, text in events(tmp_path / "ramp.rrd")][1:] == [
        "load ramp 0 -> 10 N m over 0.500-1.500 s",
        "end: complete at t = 2.000 s",
    ]
    assert events(tmp_path / "ramp.rrd")[1][0] == int(0.5 * NS)


def test_direct_set_point_is_cached_by_load(tmp_path, monkeypatch):
    """Loads 0, 10, 0, 10 N m for 0.1 s each: two operating points computed, four stretches recorded."""
    model = governed_model([])
    calls = counting_operating_point(monkeypatch)
    run = RunRecording(model, path=tmp_path / "steps.rrd")
    loads = [0.0, 10.0, 0.0, 10.0]
    for i in range(400):
        run.add_external_load(i * 1_000_000, loads[i // 100])
        run.add_machine(i * 1_000_000, 0.0, 112.0)
    run.close()
    assert calls == [0.0, 10.0]
    set_point = scalars(tmp_path / "steps.rrd", "/speed/set_point")[1]
    speeds = {load: operating_point(model, load).speed for load in (0.0, 10.0)}
    assert speeds[0.0] > speeds[10.0]  # a direct governor droops under load
    assert np.array_equal(set_point, [speeds[loads[i // 100]] for i in range(400)])
    assert events(tmp_path / "steps.rrd")[1:4] == [
        (int(0.1 * NS), "INFO", "load step 0 -> 10 N m"),
        (int(0.2 * NS), "INFO", "load step 10 -> 0 N m"),
        (int(0.3 * NS), "INFO", "load step 0 -> 10 N m"),
    ]


def test_machine_without_governor_has_no_set_point_and_draws_its_four_bar(tmp_path):
    model = build_model(load_scene("four_bar_rocker", ["scenario.duration=0.2"]))
    trajectory = simulate(model)
    times = trajectory.samples(SAMPLE_RATE)
    path = tmp_path / "four_bar.rrd"
    progress = []
    record_run(model, times, trajectory(times), path, progress=progress.append, status=trajectory.status)
    assert progress[-1] == times[-1]
    entities = set(RrdReader(path).store().schema().entity_paths())
    assert {
        "/speed/omega",
        "/moments/net",
        "/mechanism/crank",
        "/mechanism/coupler",
        "/mechanism/rocker",
        "/mechanism/frame",
        "/mechanism/joints",
    } <= entities
    assert not any(
        entity.startswith(("/speed/set_point", "/speed/band", "/governor", "/throttle")) for entity in entities
    )
    assert scalars(path, "/speed/omega")[1].size == times.size
    # nothing happens but the start and the end
    assert events(path) == [
        (0, "INFO", "start: ω = 0 rad/s; four_bar_rocker, no governor"),
        (int(0.2 * NS), "INFO", "end: complete at t = 0.200 s"),
    ]
    names = set(final_blueprint(path))
    assert "four-bar linkage" in names
    assert not any(word in name for name in names for word in ("throttle", "governor", "sleeve", "slider", "ω_set"))
    # no throttle on an ungoverned machine's drive
    assert static_value(path, "/moments/drive", "SeriesLines:names") == ["drive M_d"]


def two_mass_recordings(tmp_path) -> tuple:
    """two_mass in 0.3 s (load 6 -> 8 N m on the driven part at 0.1 s) recorded from a monolithic run at 1 kHz
    and from the co-simulation at 1 ms exchanges: (model, monolithic path, co-simulated path)."""
    model = build_model(load_scene("two_mass", SHORT_TWO_MASS))
    trajectory = simulate(model)
    times = trajectory.samples(SAMPLE_RATE)
    monolithic = tmp_path / "two_mass.rrd"
    record_run(
        model,
        times,
        trajectory(times),
        monolithic,
        mode_changes=trajectory.events,
        status=trajectory.status,
        message=trajectory.message,
    )
    run = cosimulate(model, 1e-3)
    cosimulated = tmp_path / "two_mass_cosim.rrd"
    record_run(
        model,
        run.times,
        run.states,
        cosimulated,
        mode_changes=[(t, what) for t, what, _ in run.events],
        status=run.status,
        message=run.message,
    )
    return model, monolithic, cosimulated, (times, trajectory(times))


def test_ungoverned_two_mass_machine_logs_start_load_change_and_end_and_shows_its_driven_part(tmp_path):
    model, monolithic, cosimulated, (times, states) = two_mass_recordings(tmp_path)
    expected = [
        (0, "INFO", "start: ω = 230 rad/s, load 6 N m on the driven part; two_mass, no governor"),
        (int(0.1 * NS), "INFO", "load step 6 -> 8 N m"),
        (int(0.3 * NS), "INFO", "end: complete at t = 0.300 s"),
    ]
    assert events(monolithic) == expected
    assert events(cosimulated) == expected  # the co-simulation's recording says the same
    for path in (monolithic, cosimulated):
        entities = set(RrdReader(path).store().schema().entity_paths())
        assert {"/speed/omega", "/speed/driven", "/coupling/twist", "/moments/resistance"} <= entities
        assert not any(
            entity.startswith(("/throttle", "/governor", "/speed/set_point", "/speed/band")) for entity in entities
        )
        assert "/moments/external" not in entities  # the load acts on the driven part, not on the crank
    names = model.state_names()
    assert names == ("phi", "omega", "twist", "omega_driven")
    assert np.array_equal(scalars(monolithic, "/speed/driven")[1], states[names.index("omega_driven")])
    assert np.array_equal(scalars(monolithic, "/coupling/twist")[1], 1000.0 * states[names.index("twist")])  # mrad
    views = set(final_blueprint(monolithic))
    assert "speed [rad/s]: ω crank (blue) · ω₂ driven part (pink)" in views
    assert "coupling twist φ − φ₂ [mrad]" in views
    assert not any(word in name for name in views for word in ("throttle", "governor", "sleeve"))


def test_driven_mechanism_is_drawn_at_the_driven_angle(tmp_path):
    """press_coupling has its crank-slider behind the coupling: drawn at phi_driven = phi - twist."""
    model = build_model(load_scene("press_coupling", ["scenario.duration=0.2"]))
    trajectory = simulate(model)
    times = trajectory.samples(SAMPLE_RATE)
    states = trajectory(times)
    path = tmp_path / "press_coupling.rrd"
    record_run(model, times, states, path)
    frame_times, strips = temporal(path, "/mechanism/crank", "LineStrips2D:strips")
    assert len(frame_times) > 10
    R = model.scene.machine.coupling.driven.mechanism.crank
    twist = model.state_names().index("twist")
    for stamp, (strip,) in zip(frame_times, strips):
        angle = np.interp(stamp / NS, times, states[0] - states[twist])
        assert np.allclose(strip[1], [R * math.cos(angle), -R * math.sin(angle)], atol=1e-6)
    assert "driven crank–slider at φ₂ = φ − twist" in final_blueprint(path)


def test_a_ramp_is_one_event_from_a_monolithic_and_a_cosimulated_run(tmp_path):
    """engine_indirect_isodromic with its load ramped from 8 to 4 N m over 0.3-0.5 s: one row each way."""
    model = build_model(load_scene("engine_indirect_isodromic", SHORT_ISODROMIC))
    trajectory = simulate(model)
    times = trajectory.samples(SAMPLE_RATE)
    monolithic = tmp_path / "isodromic.rrd"
    record_run(model, times, trajectory(times), monolithic, mode_changes=trajectory.events, status=trajectory.status)
    run = cosimulate(model, 1e-3)
    cosimulated = tmp_path / "isodromic_cosim.rrd"
    record_run(
        model,
        run.times,
        run.states,
        cosimulated,
        mode_changes=[(t, what) for t, what, _ in run.events],
        status=run.status,
    )
    for path, mode_changes in ((monolithic, trajectory.events), (cosimulated, [(t, w) for t, w, _ in run.events])):
        rows = events(path)
        assert [row for row in rows if not row[2].startswith("sleeve")] == [
            (
                0,
                "INFO",
                "start: ω = 230.55 rad/s, load 6 N m; engine_indirect_isodromic, indirect governor, isodromic feedback",
            ),
            (int(0.1 * NS), "INFO", "load step 6 -> 8 N m"),
            (int(0.3 * NS), "INFO", "load ramp 8 -> 4 N m over 0.300-0.500 s"),
            (int(0.6 * NS), "INFO", "end: complete at t = 0.600 s"),
        ]
        assert sorted(text for _, _, text in rows if text.startswith("sleeve")) == sorted(w for _, w in mode_changes)
        entities = set(RrdReader(path).store().schema().entity_paths())
        assert {"/throttle", "/governor/sleeve", "/governor/feedback_shift"} <= entities


def test_mode_changes_are_in_the_text_log_from_a_monolithic_and_a_cosimulated_run(tmp_path):
    """engine_direct started at 300 rad/s (about 224 on its orbit): the sleeve flies to its high stop and leaves
    it; both runs' recordings log the two mode changes at their times, between the start and the end."""
    model = build_model(
        load_scene("engine_direct", ["scenario.duration=0.5", "scenario.initial.omega=300", "scenario.load_events=[]"])
    )
    trajectory = simulate(model)
    times = trajectory.samples(SAMPLE_RATE)
    run = cosimulate(model, 1e-3)
    runs = {
        "monolithic": (times, trajectory(times), trajectory.events),
        "cosimulated": (run.times, run.states, [(t, what) for t, what, _ in run.events]),
    }
    for name, (times, states, mode_changes) in runs.items():
        path = tmp_path / f"{name}.rrd"
        record_run(model, times, states, path, mode_changes=mode_changes, status="complete")
        assert [what for _, what in mode_changes] == ["sleeve reaches the high stop", "sleeve leaves the high stop"]
        rows = events(path)
        assert [text for _, _, text in rows] == [
            "start: ω = 300 rad/s, load 6 N m; engine_direct, direct governor",
            "sleeve reaches the high stop",
            "sleeve leaves the high stop",
            "end: complete at t = 0.500 s",
        ], name
        assert [stamp for stamp, _, _ in rows[1:3]] == [int(round(t * NS)) for t, _ in mode_changes]


def test_load_changes_merge_consecutive_samples_and_split_at_a_reversal():
    """Steps, a ramp, a ramp down then up at once (two ramps), a new trial (time goes back), a ramp going on."""
    changes = LoadChanges(8.0)
    loads = [8.0, 8.0, 6.0, 6.0, 5.0, 4.0, 3.0, 3.0, 2.0, 1.0, 2.0, 3.0, 3.0]  # one every 0.1 s
    logged = [event for i, load in enumerate(loads) for event in changes.sample(i * NS // 10, load)]
    assert logged == [
        (int(0.2 * NS), "load step 8 -> 6 N m"),
        (int(0.3 * NS), "load ramp 6 -> 3 N m over 0.300-0.600 s"),
        (int(0.7 * NS), "load ramp 3 -> 1 N m over 0.700-0.900 s"),
        (int(0.9 * NS), "load ramp 1 -> 3 N m over 0.900-1.100 s"),
    ]
    assert changes.sample(0, 3.0) == []  # time goes back: a new trial from this sample on
    assert changes.sample(NS // 10, 4.0) == [] and changes.sample(2 * NS // 10, 5.0) == []
    assert changes.finish() == [(0, "load ramp 3 -> 5 N m over 0.000-0.200 s")]
    assert changes.finish() == []


def test_close_logs_a_ramp_still_going_and_how_the_run_failed(tmp_path):
    model = governed_model([])
    path = tmp_path / "failed.rrd"
    run = RunRecording(model, path=path)
    for i in range(5):
        run.add_machine(i * NS // 10, 0.0, 112.0)
        run.add_external_load(i * NS // 10, float(i))
    run.close("failed", "the governor changed mode 100 times")
    assert sorted(events(path)) == [
        (0, "INFO", "load ramp 0 -> 4 N m over 0.000-0.400 s"),
        (0, "INFO", "start: ω = 112.86 rad/s; run, direct governor"),
        (int(0.4 * NS), "ERROR", "end: failed at t = 0.400 s: the governor changed mode 100 times"),
    ]


# The animation's columns and the recorder's memory


def strip_by_strip(frames: list[np.ndarray]):
    """The LineStrips2D column of `frames` (each one strip, points x 2, or a bundle, strips x points x 2) built from a
    list of one array per strip, partitioned by frame: Rerun's conversion taken as it comes, the reference."""
    bundles = [frame if frame.ndim == 3 else frame[np.newaxis] for frame in frames]
    strips = [strip for bundle in bundles for strip in bundle]
    return rr.LineStrips2D.columns(strips=strips).partition([len(bundle) for bundle in bundles])


@pytest.mark.parametrize(
    "shapes",
    [
        [(4, 4, 2)] * 30,  # a linkage's links: a bundle of strips a frame
        [(2, 2)] * 30,  # a crank: one strip a frame
        [(0, 74, 2)] * 30,  # a linkage without gears: no strip
        [(2, 4, 2), (3, 4, 2), (1, 4, 2)] * 10,  # bundles of as many points, not as many strips
        [(2, 4, 2), (2, 5, 2), (5, 2)] * 10,  # strips of different lengths: the list, as Rerun takes it
    ],
)
def test_frame_columns_are_the_strips_as_rerun_converts_them_one_by_one(shapes):
    generator = np.random.default_rng(7)
    frames = [generator.normal(size=shape) for shape in shapes]
    (expected,) = strip_by_strip(frames)
    (columns,) = recording_pictures.frame_columns("links", frames)
    assert columns.as_arrow_array().equals(expected.as_arrow_array())
    assert len(columns.as_arrow_array()) == len(frames)


class Mallinfo2(ctypes.Structure):
    """glibc's struct mallinfo2 (malloc.h): `arena` the bytes its heaps hold from the system, in use or free."""

    _fields_ = [
        (name, ctypes.c_size_t)
        for name in "arena ordblks smblks hblks hblkhd usmblks fsmblks uordblks fordblks keepcost".split()
    ]


def c_heap_bytes() -> int:
    """The bytes glibc's malloc holds from the system for its heaps (mallinfo2's arena: in use or free, not given
    back); the test is skipped without glibc 2.33's mallinfo2."""
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    if not hasattr(libc, "mallinfo2"):
        pytest.skip("no glibc mallinfo2 here")
    libc.mallinfo2.restype = Mallinfo2
    gc.collect()
    return libc.mallinfo2().arena


def test_sending_a_linkages_frames_leaves_the_c_heap_as_it_was():
    """10 000 frames of the six-bar press's moving parts (a recorder's send of 200 s of exchanges, twice the
    RECORDING_CHUNK it sends in, as a recorder that fell behind sends them) made into columns three times: the
    C heap grows by under 15 MB (6 MB measured; when Rerun converted the strips one by one it grew by 35 MB at the
    first send and kept it, free but not given back, so that the recorder's resident memory rose with its largest
    send)."""
    model = build_model(load_scene("six_bar_press"))
    drawing, _ = recording_pictures.drawn_mechanism(model)
    parts = MECHANISM_MOVING_PARTS[mechanism_kind(drawing)]
    outlines = [mechanism_outline(drawing, 0.01 * frame) for frame in range(200)]
    frames = {
        part: [outlines[frame % 200][part] * recording_pictures.FLIP_Y for frame in range(10_000)] for part in parts
    }
    before = c_heap_bytes()
    for _ in range(3):
        for part, part_frames in frames.items():
            recording_pictures.frame_columns(part, part_frames)
    grown = c_heap_bytes() - before
    assert grown < 15e6, f"the C heap grew by {grown / 1e6:.1f} MB"
