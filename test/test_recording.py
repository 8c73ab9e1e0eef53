"""Tests of the Rerun recording layer (mech_regulator.viz.recording), read back from the .rrd files with
rerun.chunk.RrdReader: entities, the sim_time time line, every sample fed and its value, the animation's
frame count and geometry, the set point and band, the moments' decomposition, events, the blueprint,
`rerun rrd verify`, and the set-point cache. No ROS.

A .rrd stores the scalars as float64, so values read back equal the values fed exactly; drawings are
stored as float32, hence the 1e-6 m tolerance on positions of size 0.2 m (float32 resolution ~1e-8 m).
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from rerun.chunk import RrdReader

from mech_regulator.analysis import operating_point
from mech_regulator.governors.drawing import COLLAR_RADIUS
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene, validate_scene
from mech_regulator.solvers import simulate
from mech_regulator.viz import recording
from mech_regulator.viz.recording import RunRecording, record_run

RERUN = Path(sys.executable).with_name("rerun")
SAMPLE_RATE = 1000.0        # [Hz] of the samples fed
DURATION = 0.5              # [s] simulated
NS = 1_000_000_000

SHORT_ENGINE = ["scenario.duration=0.5", "scenario.load_events.0.time=0.2", "scenario.load_events.1.time=0.4"]


def chunks(path: Path, entity: str, static: bool = False) -> list:
    """Record batches of one entity's static or temporal chunks."""
    return [chunk.to_record_batch() for chunk in RrdReader(path).store().stream()
            if chunk.entity_path == entity and chunk.is_static == static]


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


@pytest.fixture(scope="module")
def engine_run(tmp_path_factory):
    """engine_direct shortened to 0.5 s (loads 6 -> 8 N m at 0.2 s -> 0 at 0.4 s), recorded at 1 kHz."""
    model = build_model(load_scene("engine_direct", SHORT_ENGINE))
    trajectory = simulate(model)
    assert trajectory.status == "complete", trajectory.message
    times = trajectory.samples(SAMPLE_RATE)
    states = trajectory(times)
    path = tmp_path_factory.mktemp("recording") / "engine_direct.rrd"
    record_run(model, times, states, path)
    return model, times, states, path


def test_short_engine_scene_validates_with_its_overrides():
    scene = load_scene("engine_direct", SHORT_ENGINE)
    assert scene.scenario.duration == DURATION
    assert [event.time for event in scene.scenario.load_events] == [0.2, 0.4]
    assert [event.torque for event in scene.scenario.load_events] == [8.0, 0.0]


def test_recording_has_the_entities_one_time_line_and_a_blueprint(engine_run):
    _, _, _, path = engine_run
    reader = RrdReader(path)
    assert len(reader.recordings()) == 1 and len(reader.blueprints()) == 1
    schema = reader.store().schema()
    expected = {"/speed/omega", "/speed/set_point", "/speed/band_high", "/speed/band_low", "/throttle",
                "/governor/sleeve", "/moments/drive", "/moments/resistance", "/moments/external", "/moments/net",
                "/events", "/about", "/mechanism/crank", "/mechanism/rod", "/mechanism/slider", "/mechanism/guide",
                "/mechanism/joints", "/governor/drawing/spindle", "/governor/drawing/upper_arms",
                "/governor/drawing/lower_links", "/governor/drawing/balls", "/governor/drawing/sleeve",
                "/governor/drawing/stops"}
    entities = set(schema.entity_paths())
    assert expected <= entities, expected - entities
    assert "/governor/servo" not in entities          # a direct governor has no servo-motor
    assert [index.name for index in schema.index_columns()] == ["sim_time"]   # no wall-clock log_time


def test_every_sample_fed_is_recorded_at_its_time_with_its_value(engine_run):
    model, times, states, path = engine_run
    stamps = np.round(times * NS).astype(np.int64)
    omega_times, omega = scalars(path, "/speed/omega")
    assert omega.size == times.size == int(DURATION * SAMPLE_RATE) + 1
    assert np.array_equal(omega_times, stamps)
    assert np.array_equal(omega, states[1])
    columns = model.columns(times, states)
    sleeve_times, sleeve = scalars(path, "/governor/sleeve")
    assert np.array_equal(sleeve_times, stamps)
    assert np.allclose(sleeve, 1000.0 * columns["sleeve"], rtol=1e-15, atol=0.0)   # plotted in mm
    assert "[mm]" in static_value(path, "/governor/sleeve", "SeriesLines:names")[0]
    assert np.array_equal(scalars(path, "/throttle")[1], columns["throttle"])


def test_moments_add_up_to_the_net_moment(engine_run):
    model, times, states, path = engine_run
    drive, resistance, external, net = (scalars(path, f"/moments/{name}")[1]
                                        for name in ("drive", "resistance", "external", "net"))
    assert drive.size == times.size
    scale = np.max(np.abs(drive))
    assert np.max(np.abs(drive + resistance + external - net)) <= 1e-12 * scale
    loads = np.array([model.external_load(t) for t in times])
    assert np.array_equal(external, -loads)
    assert np.all(resistance < 0.0)                   # viscous and fan loads resist a turning crank


def test_set_point_follows_the_load_and_the_band_is_the_permitted_delta(engine_run):
    model, times, _, path = engine_run
    set_times, set_point = scalars(path, "/speed/set_point")
    assert set_point.size == times.size
    for load, start, end in ((6.0, 0.0, 0.2), (8.0, 0.2, 0.4), (0.0, 0.4, DURATION)):
        speed = operating_point(model, load).speed
        # the load is known from the moments sample of the same time on: from the next machine sample
        inside = (set_times > start * NS) & (set_times <= end * NS)
        assert np.all(set_point[inside] == speed), (load, np.unique(set_point[inside]))
    delta = model.scene.analysis.permitted_delta
    assert delta == 0.05
    assert np.allclose(scalars(path, "/speed/band_high")[1], set_point * (1 + delta / 2), rtol=1e-15)
    assert np.allclose(scalars(path, "/speed/band_low")[1], set_point * (1 - delta / 2), rtol=1e-15)


def test_animation_is_decimated_to_the_animation_rate_and_flipped(engine_run):
    model, times, states, path = engine_run
    rate = 200.0                                          # RunRecording's default [Hz]
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


def test_load_changes_are_in_the_text_log(engine_run):
    _, _, _, path = engine_run
    stamps, texts = temporal(path, "/events", "TextLog:text")
    assert list(stamps) == [0, int(0.2 * NS), int(0.4 * NS)]
    assert texts == [["external load 6 N m"], ["external load steps to 8 N m"], ["external load steps to 0 N m"]]


def test_rerun_verifies_the_file(engine_run):
    _, _, _, path = engine_run
    result = subprocess.run([str(RERUN), "rrd", "verify", str(path)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr


# --------------------------------------------------------------------------------------------
# RunRecording fed by hand


def governed_model(load_events: list[dict], indirect: bool = False):
    """The constant-J machine of docs' governor example (fast statics), direct or indirect."""
    governor = {"type": "direct", "ball_mass": 1.0, "arm_length": 0.2, "sleeve_mass": 5.0, "damping": 200.0,
                "ratio": 0.16, "stroke": [0.02, 0.08], "valve": {"open_at": 0.02, "closed_at": 0.08}}
    if indirect:
        governor = {**{k: v for k, v in governor.items() if k != "valve"}, "type": "indirect",
                    "pilot_neutral": 0.05, "servo": {"gain": 20.0},
                    "feedback": {"type": "isodromic", "gain": 0.3, "time_constant": 1.5}}
    scene = {"machine": {"inertia": 0.5, "drive": {"type": "linear_motor", "stall_torque": 200.0,
                                                     "no_load_speed": 150.0},
                         "loads": [{"type": "viscous", "coefficient": 0.3}]},
             "governor": governor,
             "scenario": {"initial": {"omega": 112.86}, "duration": 2.0, "load_events": load_events}}
    return build_model(validate_scene(scene))


def test_interleaved_streams_flushed_in_pieces_and_closed_twice(tmp_path):
    """Streams interleave, flush() comes every so often, close() twice; samples after close are dropped."""
    model = governed_model([], indirect=True)
    path = tmp_path / "indirect.rrd"
    run = RunRecording(model, path=path, animation_rate=50.0)
    count = 400
    for i in range(count):
        t_ns = i * 1_000_000                              # 1 kHz for 0.4 s
        run.add_governor(t_ns, {"sleeve": 0.05, "sleeve_velocity": 0.0, "throttle": 0.5, "servo": 0.5,
                                "arm_angle": model.governor.sensor.arm_angle(0.05),
                                "feedback_shift": 0.001 * i / count})
        run.add_machine(t_ns, 0.1 * i, 110.0)
        run.add_moments(t_ns, 10.0, -9.0, 0.0, 1.0)
        if i % 97 == 0:
            run.flush()
    run.close()
    run.close()
    run.add_machine(count * 1_000_000, 0.0, 1.0)
    assert scalars(path, "/speed/omega")[1].size == count
    assert scalars(path, "/governor/servo")[1].size == count
    shift = scalars(path, "/governor/feedback_shift")[1]
    assert shift[-1] == pytest.approx(1000.0 * 0.001 * (count - 1) / count)    # in mm
    set_point = scalars(path, "/speed/set_point")[1]
    assert np.all(set_point == model.governor.set_speed())                      # indirect: constant
    assert len(temporal(path, "/mechanism/spoke", "LineStrips2D:strips")[0]) == 20   # 0.4 s at 50 Hz
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
    for i in range(2001):                                # 2 s at 1 kHz: 0.5 s still, 1 s ramp, 0.5 s still
        run.add_machine(i * 1_000_000, 0.0, 112.0)
        run.add_moments(i * 1_000_000, 0.0, 0.0, -model.external_load(i / 1000.0), 0.0)
    run.close()
    # once for the load 0 N m, then every 10 ms along the 1 s ramp (about 100 loads), the last one 10 N m
    assert calls[0] == 0.0 and calls[-1] == 10.0
    assert 95 <= len(calls) <= 102, len(calls)
    assert np.all(np.diff(calls) > 0.0)
    set_point = scalars(tmp_path / "ramp.rrd", "/speed/set_point")[1]
    assert set_point[-1] == operating_point(model, 10.0).speed


def test_direct_set_point_is_cached_by_load(tmp_path, monkeypatch):
    """Loads 0, 10, 0, 10 N m for 0.1 s each: two operating points computed, four stretches recorded."""
    model = governed_model([])
    calls = counting_operating_point(monkeypatch)
    run = RunRecording(model, path=tmp_path / "steps.rrd")
    loads = [0.0, 10.0, 0.0, 10.0]
    for i in range(400):
        run.add_moments(i * 1_000_000, 0.0, 0.0, -loads[i // 100], 0.0)
        run.add_machine(i * 1_000_000, 0.0, 112.0)
    run.close()
    assert calls == [0.0, 10.0]
    set_point = scalars(tmp_path / "steps.rrd", "/speed/set_point")[1]
    speeds = {load: operating_point(model, load).speed for load in (0.0, 10.0)}
    assert speeds[0.0] > speeds[10.0]                    # a direct governor droops under load
    assert np.array_equal(set_point, [speeds[loads[i // 100]] for i in range(400)])


def test_machine_without_governor_has_no_set_point_and_draws_its_four_bar(tmp_path):
    model = build_model(load_scene("four_bar_rocker", ["scenario.duration=0.2"]))
    trajectory = simulate(model)
    times = trajectory.samples(SAMPLE_RATE)
    path = tmp_path / "four_bar.rrd"
    progress = []
    record_run(model, times, trajectory(times), path, progress=progress.append)
    assert progress[-1] == times[-1]
    entities = set(RrdReader(path).store().schema().entity_paths())
    assert {"/speed/omega", "/moments/net", "/mechanism/crank", "/mechanism/coupler", "/mechanism/rocker",
            "/mechanism/frame", "/mechanism/joints"} <= entities
    assert not any(entity.startswith(("/speed/set_point", "/speed/band", "/governor", "/throttle"))
                   for entity in entities)
    assert "/events" not in entities                     # no external load, nothing happens
    assert scalars(path, "/speed/omega")[1].size == times.size
