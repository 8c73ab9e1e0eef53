"""A long run's plot (viz/plots.py, plotted_columns): past PLOTTED_POINTS samples each stretch of samples is drawn
as its least and greatest value, so that a 10 000-s run's 2e7 samples neither fill the memory with their columns nor
alias the ripple; below it the plot draws every sample."""

from __future__ import annotations

import numpy as np
import pytest
from support import run_cli

from mech_regulator.model import build_model
from mech_regulator.scene import load_scene
from mech_regulator.solvers import simulate
from mech_regulator.viz import plots


@pytest.fixture(scope="module")
def engine_run():
    """engine_direct, 2 s on the reference path, sampled at its own rate: the model, the times and the states."""
    model = build_model(
        load_scene("engine_direct", ["scenario.duration=2", "scenario.load_events=[]", "solver.path=reference"])
    )
    trajectory = simulate(model)
    times = trajectory.samples(model.scene.solver.sample_rate)
    return model, times, trajectory(times)


def test_a_run_within_the_plotted_points_is_drawn_at_every_sample(engine_run):
    model, times, states = engine_run
    drawn_times, columns = plots.plotted_columns(model, times, states)
    assert drawn_times is times
    whole = model.columns(times, states)
    assert columns.keys() == whole.keys()
    assert all(np.array_equal(columns[name], whole[name], equal_nan=True) for name in whole)


@pytest.mark.parametrize("points", [40, 1000, 3998])
def test_a_longer_run_is_drawn_as_each_stretch_s_least_and_greatest_value(engine_run, monkeypatch, points):
    """Each stretch's two points are its least and greatest value in the order they come, at its first and last
    time; so the whole run's extremes are drawn exactly, and no drawn value leaves the stretch's range."""
    model, times, states = engine_run
    monkeypatch.setattr(plots, "PLOTTED_POINTS", points)
    drawn_times, columns = plots.plotted_columns(model, times, states)
    width = -(-times.size // (points // 2))
    stretches = -(-times.size // width)
    assert drawn_times.size == 2 * stretches <= points
    assert np.all(np.diff(drawn_times) >= 0.0)
    assert drawn_times[0] == times[0] and drawn_times[-1] == times[-1]
    whole = model.columns(times, states)
    for name in ("omega", "M_drive", "throttle", "phi"):
        values, drawn = whole[name], columns[name]
        assert drawn.max() == values.max() and drawn.min() == values.min(), name
        for stretch in range(stretches):
            part = values[stretch * width : (stretch + 1) * width]
            first, last = drawn[2 * stretch], drawn[2 * stretch + 1]
            assert {first, last} == {part.min(), part.max()}, (name, stretch)
            assert (first == part.min()) == (np.argmin(part) <= np.argmax(part)), (name, stretch)


def test_simulate_plot_of_a_long_run_draws_the_envelope(monkeypatch, tmp_path, capsys):
    """`simulate --plot` past PLOTTED_POINTS draws the speed's envelope: at most that many points, its extremes the
    run's."""
    from matplotlib.axes import Axes

    monkeypatch.setattr(plots, "PLOTTED_POINTS", 500)
    drawn = []
    draw = Axes.plot
    monkeypatch.setattr(Axes, "plot", lambda axes, *data, **style: drawn.append(data) or draw(axes, *data, **style))
    picture = tmp_path / "run.png"
    arguments = ["simulate", "engine_direct", "--quiet", "--json", "--plot", str(picture)]
    settings = [
        "--set",
        "scenario.duration=2",
        "--set",
        "scenario.load_events=[]",
        "--set",
        "solver.path=reference",
        "--out",
        str(tmp_path / "run.csv"),
    ]
    assert run_cli(capsys, *arguments, *settings)[0] == 0
    assert picture.stat().st_size > 0
    times, omega = drawn[0]
    assert times.size <= 500
    sampled = np.loadtxt(tmp_path / "run.csv", delimiter=",", skiprows=1, usecols=2)
    assert sampled.size > 500
    assert omega.max() == pytest.approx(sampled.max(), rel=1e-9) and omega.min() == pytest.approx(
        sampled.min(), rel=1e-9
    )
