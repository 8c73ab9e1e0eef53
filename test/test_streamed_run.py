"""A streamed run (analysis/stream.py; docs/hard_cases.md §4, memory): the trajectory hands its oldest steps to what
the summary and the CSV need of them and drops them, so what it holds does not grow with the run's length, and the
summary and CSV are those of the run kept whole.

Oracles: the run kept whole (the streamed figures are read on the same sample times and in the same chunks, so they
are the same numbers), and the run of a quarter of the length (the steps it holds at its end bound the longer run's).
Here the chunks are made small (a few hundred steps; a few for clutch_start) so that a few seconds of engine_direct,
of the two-mass machines and of a drive train stream.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from support import model_of, run_cli, write_scene
from test_compiled_path import shortened

from mech_regulator.analysis import RunDigest, energy, load_response, stream
from mech_regulator.solvers import cam_contact, simulate

RETAINED, CHUNK, WINDOW_SPAN = 300, 100, 0.05  # steps kept at the end, steps a chunk, a load window's chunk [s]
CHECK_STEPS = 50  # steps whose cam contacts are checked at once


@pytest.fixture
def small_chunks(monkeypatch):
    """Stream engine_direct after a few hundred steps (its load windows read WINDOW_SPAN at a time; a machine with cams
    has its contacts checked CHECK_STEPS at a time)."""
    monkeypatch.setattr(stream, "RETAINED_STEPS", RETAINED)
    monkeypatch.setattr(cam_contact, "CHECK_CHUNK_STEPS", CHECK_STEPS)
    monkeypatch.setattr(stream, "BALANCE_CHUNK_STEPS", CHUNK)
    monkeypatch.setattr(energy, "BALANCE_CHUNK_STEPS", CHUNK)
    monkeypatch.setattr(load_response, "WINDOW_CHUNK_SPAN", WINDOW_SPAN)


def steps_dropped_by_each_run(monkeypatch) -> list[int]:
    """A list to which each run analysis.simulate_streamed makes from now on adds how many steps it dropped."""
    from mech_regulator import analysis

    dropped: list[int] = []

    def simulate_streamed(model, *arguments, **options):
        trajectory, digest = stream.simulate_streamed(model, *arguments, **options)
        dropped.append(trajectory.steps_dropped)
        return trajectory, digest

    monkeypatch.setattr(analysis, "simulate_streamed", simulate_streamed)
    return dropped


def test_a_streamed_run_hands_off_only_steps_whose_cam_contacts_are_checked():
    """The contact check reads its chunks (cam_contact.CHECK_CHUNK_STEPS) before the stream hands steps off: the
    stream keeps more steps than a check's chunk."""
    assert cam_contact.CHECK_CHUNK_STEPS < stream.RETAINED_STEPS


@pytest.mark.parametrize("path", ["reference", "fast"])
def test_a_streamed_run_holds_as_many_steps_after_4_t_as_after_t(small_chunks, path):
    """engine_direct for 1 s and for 4 s (its load change at 2 s in the longer one): at their ends both trajectories
    hold at most the retained steps, a chunk and the steps of a load window's chunk (some 40 at 700 steps a second),
    though the longer run took some 2600 steps."""
    held = {}
    for duration in (1.0, 4.0):
        model = model_of(shortened("engine_direct", duration, solver__path=path))
        trajectory = simulate(model, stream=RunDigest(model).take)
        assert trajectory.status == "complete"
        held[duration] = trajectory.held_steps
    bound = RETAINED + 2 * CHUNK + 100
    assert held[4.0] <= bound and held[1.0] <= bound
    assert trajectory.steps_dropped > 4 * held[4.0]  # the longer run streamed most of its steps


@pytest.mark.parametrize("path", ["reference", "fast"])
def test_a_streamed_run_gives_the_summary_and_csv_of_the_run_kept_whole(
    small_chunks, monkeypatch, tmp_path, capsys, path
):
    """`simulate engine_direct` for 4 s (a load change at 2 s: its window, the energy balance, the mode log of the
    governor's sleeve), streamed and kept whole (its trajectory keeping every step): the same JSON summary and the
    same CSV, byte for byte, but the steady state, which the streamed run judges on the tail it keeps (fewer
    periods; the last one's speeds located on a grid over the tail, to 1e-9)."""
    scene_file = write_scene(tmp_path, yaml.safe_dump(shortened("engine_direct", 4.0, solver__path=path)))
    arguments = ["simulate", str(scene_file)]
    streamed_csv, whole_csv = tmp_path / "streamed.csv", tmp_path / "whole.csv"
    code, streamed, _ = run_cli(capsys, *arguments, "--json", "--quiet", "--out", str(streamed_csv))
    assert code == 0
    monkeypatch.setattr(stream, "RETAINED_STEPS", 10**9)
    code, whole, _ = run_cli(capsys, *arguments, "--json", "--quiet", "--out", str(whole_csv))
    assert code == 0
    streamed_summary, whole_summary = json.loads(streamed), json.loads(whole)
    assert streamed_summary.pop("csv") == str(streamed_csv) and whole_summary.pop("csv") == str(whole_csv)
    streamed_steady, whole_steady = streamed_summary.pop("steady"), whole_summary.pop("steady")
    assert streamed_summary == whole_summary
    assert whole_summary["governor"]["load_responses"] and whole_summary["energy"]["works"]
    assert streamed_steady["steady"] == whole_steady["steady"] and streamed_steady["periods"] < whole_steady["periods"]
    for name, value in whole_steady["last_period"].items():
        assert streamed_steady["last_period"][name] == pytest.approx(value, rel=1e-9, abs=1e-12)
    assert streamed_csv.read_bytes() == whole_csv.read_bytes()


def test_a_streamed_run_records_the_samples_of_the_run_kept_whole(small_chunks, monkeypatch, tmp_path, capsys):
    """`simulate engine_direct --record` for 4 s on the fast path streams (a recording once kept the whole run in
    memory) and hands the recording the sample times and states of the run kept whole, bit for bit."""
    from mech_regulator.viz import recording

    recorded = []
    monkeypatch.setattr(
        recording,
        "record_run",
        lambda model, times, states, path, **options: recorded.append((times, states)),
    )
    sampled = []
    take_samples = RunDigest.samples
    monkeypatch.setattr(
        RunDigest, "samples", lambda digest, trajectory: sampled.append(1) or take_samples(digest, trajectory)
    )
    scene_file = write_scene(tmp_path, yaml.safe_dump(shortened("engine_direct", 4.0, solver__path="fast")))
    arguments = ["simulate", str(scene_file), "--json", "--quiet", "--record", str(tmp_path / "run.rrd")]
    assert run_cli(capsys, *arguments)[0] == 0
    assert sampled  # streamed: the samples are the digest's
    monkeypatch.setattr(stream, "RETAINED_STEPS", 10**9)
    assert run_cli(capsys, *arguments)[0] == 0
    assert len(sampled) == 1  # kept whole: read off the trajectory
    (streamed_times, streamed_states), (times, states) = recorded
    assert streamed_times.size == 4 * 2000 + 1 and np.array_equal(streamed_times, times)
    assert np.array_equal(streamed_states, states)


def test_a_streamed_bench_long_row_is_the_row_of_the_run_kept_whole(small_chunks, monkeypatch, tmp_path):
    """`bench long`'s simulate row of engine_direct for 4 s on the fast path streams as `simulate` does (it once kept
    the whole run: 2.8 GB at 10 000 s) and is the row of the run kept whole: the same status, steps and energy
    residual, the last period's omega_m and delta to 1e-9 (judged on the tail), for the row and its own-duration
    run alike."""
    from mech_regulator.bench.long import run_row

    dropped = steps_dropped_by_each_run(monkeypatch)
    scene_file = str(write_scene(tmp_path, yaml.safe_dump(shortened("engine_direct", 4.0))))
    streamed = run_row(scene_file, "fast", "DOP853", "simulate", 4.0, 600.0)
    assert len(dropped) == 2 and min(dropped) > 0  # the row and its own-duration run streamed
    monkeypatch.setattr(stream, "RETAINED_STEPS", 10**9)
    whole = run_row(scene_file, "fast", "DOP853", "simulate", 4.0, 600.0)
    assert dropped[2:] == [0, 0]
    assert streamed.status == whole.status == "complete"
    assert (streamed.steps, streamed.residual) == (whole.steps, whole.residual)
    for name in ("omega_m", "delta", "omega_m_short", "delta_short"):
        assert getattr(streamed, name) == pytest.approx(getattr(whole, name), rel=1e-9), name


@pytest.mark.parametrize(
    "name, duration, retained, chunk",
    [
        ("two_mass", 3.0, RETAINED, CHUNK),  # a coupling: its largest moment (refined) and the twist's range
        ("press_coupling", 3.0, RETAINED, CHUNK),  # a hardening coupling, the press held by friction at the start
        ("clutch_start", 4.0, 10, 5),  # a clutch and two branches: their largest section torques (34 steps)
        ("valve_gear", 0.4, RETAINED, CHUNK),  # a cam: its contact checked as the steps come (some 740 steps)
    ],
)
def test_a_streamed_two_mass_or_drive_train_run_gives_the_summary_of_the_run_kept_whole(
    small_chunks, monkeypatch, tmp_path, capsys, name, duration, retained, chunk
):
    """`simulate` of a two-mass machine, a drive train or a machine with cams on the reference path, streamed (the
    coupling's and the sections' figures read chunk by chunk, the cam's contact checked, while the run drops its
    oldest steps) and kept whole: the same JSON summary and CSV, but the steady state, which the streamed run judges
    on the tail it keeps, and the figures that follow from it (the coupling peak's period, the steady mean moment and
    their ratio, to 1e-9)."""

    monkeypatch.setattr(stream, "RETAINED_STEPS", retained)
    monkeypatch.setattr(stream, "BALANCE_CHUNK_STEPS", chunk)
    monkeypatch.setattr(energy, "BALANCE_CHUNK_STEPS", chunk)
    dropped = steps_dropped_by_each_run(monkeypatch)
    scene_file = write_scene(tmp_path, yaml.safe_dump(shortened(name, duration, solver__path="reference")))
    summaries, csv_files = [], [tmp_path / "streamed.csv", tmp_path / "whole.csv"]
    for csv_file in csv_files:
        code, output, _ = run_cli(capsys, "simulate", str(scene_file), "--json", "--quiet", "--out", str(csv_file))
        assert code == 0
        summaries.append(json.loads(output))
        monkeypatch.setattr(stream, "RETAINED_STEPS", 10**9)
    assert dropped[0] > 0 and dropped[1] == 0  # the first run streamed, the second kept every step
    streamed, whole = summaries
    assert streamed.pop("csv") == str(csv_files[0]) and whole.pop("csv") == str(csv_files[1])
    streamed_steady, whole_steady = streamed.pop("steady"), whole.pop("steady")
    assert streamed_steady["steady"] == whole_steady["steady"]
    if whole["two_mass"] is not None:
        streamed_peak, whole_peak = streamed["two_mass"].pop("peak"), whole["two_mass"].pop("peak")
        assert (streamed_peak["moment"], streamed_peak["time"]) == (whole_peak["moment"], whole_peak["time"])
        for figure in ("steady_mean", "ratio"):  # None where the run is not steady
            value = whole_peak[figure]
            assert streamed_peak[figure] == (value if value is None else pytest.approx(value, rel=1e-9)), figure
        streamed["two_mass"].pop("steady_from"), whole["two_mass"].pop("steady_from")
    assert streamed == whole
    if name == "clutch_start":
        assert all(section["max"] > section["nominal"] for section in whole["drive_train"]["sections"].values())
    assert csv_files[0].read_bytes() == csv_files[1].read_bytes()


@pytest.mark.parametrize(
    "name, duration, retained, chunk",
    [("engine_direct", 4.0, RETAINED, CHUNK), ("clutch_start", 4.0, 10, 5)],  # a governor's panel, a clutch's
)
def test_a_streamed_run_plots_the_samples_of_the_run_kept_whole(
    small_chunks, monkeypatch, tmp_path, capsys, name, duration, retained, chunk
):
    """`simulate --plot` on the reference path streams (the plot once kept the whole run) and draws the speed of the
    run kept whole against time, bit for bit: the streamed output samples (and, for the clutch, the events)."""
    from matplotlib.axes import Axes

    monkeypatch.setattr(stream, "RETAINED_STEPS", retained)
    monkeypatch.setattr(stream, "BALANCE_CHUNK_STEPS", chunk)
    monkeypatch.setattr(energy, "BALANCE_CHUNK_STEPS", chunk)
    drawn = []
    draw = Axes.plot
    monkeypatch.setattr(Axes, "plot", lambda axes, *data, **style: drawn.append(data) or draw(axes, *data, **style))
    sampled = []
    take_samples = RunDigest.samples
    monkeypatch.setattr(
        RunDigest, "samples", lambda digest, trajectory: sampled.append(1) or take_samples(digest, trajectory)
    )
    scene_file = write_scene(tmp_path, yaml.safe_dump(shortened(name, duration, solver__path="reference")))
    speeds = []
    for picture in ("streamed.png", "whole.png"):
        drawn.clear()
        arguments = ["simulate", str(scene_file), "--json", "--quiet", "--plot", str(tmp_path / picture)]
        assert run_cli(capsys, *arguments)[0] == 0
        assert (tmp_path / picture).stat().st_size > 0
        speeds.append(drawn[0])  # omega against t, the first curve drawn
        monkeypatch.setattr(stream, "RETAINED_STEPS", 10**9)
    assert sampled == [1]  # the first run streamed: its plot took the digest's samples
    (streamed_times, streamed_omega), (times, omega) = speeds
    assert streamed_times.size > 4 * 1000 and np.array_equal(streamed_times, times)
    assert np.array_equal(streamed_omega, omega)


def test_the_samples_within_a_stretch_are_those_of_the_planned_grid():
    """sample_times_within (what the two-mass and drive-train readers take of the output grid a chunk at a time) is
    the planned grid, sample_times, cut to [low, high], bit for bit: at the ends, at grid points, outside the run."""
    from mech_regulator.solvers.trajectory import sample_times, sample_times_within

    rng = np.random.default_rng(29)
    for duration, rate in ((3.0, 5000.0), (10_000.0, 100.0), (7.3, 333.3), (0.01, 100.0)):
        grid = sample_times(0.0, duration, rate)
        picks = list(grid[rng.integers(grid.size, size=20)]) + list(rng.uniform(-0.1, 1.1, 20) * duration)
        for low, high in zip(picks[::2], picks[1::2]):
            low, high = min(low, high), max(low, high)
            inside = grid[(grid >= low) & (grid <= high)]
            assert np.array_equal(sample_times_within(0.0, duration, rate, low, high), inside), (duration, low, high)
        assert np.array_equal(sample_times_within(0.0, duration, rate, 0.0, duration), grid)


def test_a_drive_train_s_section_torques_read_a_few_samples_at_a_time_are_those_read_at_once(monkeypatch):
    """The largest section torque of each branch (analysis/drivetrain.py read_sections), its samples evaluated 7 at a
    time instead of EVALUATION_CHUNK: the same peak and time to the bit (a chunk of few long steps holds many
    samples: clutch_start over 10 000 s is one chunk of 1e7 samples, which evaluated at once took 6.7 GB)."""
    from mech_regulator.analysis import drivetrain

    model = model_of(shortened("clutch_start", 4.0, solver__path="reference"))
    trajectory = simulate(model)
    at_once = drivetrain.drive_train_summary(model, trajectory)["sections"]
    monkeypatch.setattr(drivetrain, "EVALUATION_CHUNK", 7)
    a_few_at_a_time = drivetrain.drive_train_summary(model, trajectory)["sections"]
    assert at_once and a_few_at_a_time == at_once
