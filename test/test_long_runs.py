"""Long runs (docs/hard_cases.md, "Long runs"): the crank angle grows without bound (1e7 rad after about 10 000 s of
an engine), and a double's last place grows with it (2e-9 rad at 1e7 rad). The solvers carry the angle as whole
dynamic periods plus the phase within one (time_domain.turns_and_phase) across their restarts, and compare switch
angles and windows with the phase; a run whose restarts stop advancing the time ends failed with what repeats, never
spins.

Oracles: the same scene started at phi = 0 (a machine is periodic in its dynamic period, so a run started K whole
periods further is the same run, K periods further on: the same states bit for bit but phi, the same steps,
switches and events), and the shorter run of the same scene (a longer run is the shorter one where they overlap).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from support import model_of, run_cli
from test_compiled_path import shortened

from mech_regulator.analysis import load_response
from mech_regulator.analysis.energy import step_edges
from mech_regulator.analysis.load_response import cycle_mean_speed
from mech_regulator.cli import simulate as simulate_command
from mech_regulator.scene.limits import MAX_STEPS
from mech_regulator.solvers import simulate, step_limit_refusal, time_domain
from mech_regulator.solvers import trajectory as trajectory_module
from mech_regulator.solvers.compiled import run
from mech_regulator.solvers.time_domain import MAX_RESTARTS_WITHOUT_PROGRESS, turns_and_phase

FAR = 1e7  # [rad]: about 10 000 s of the engines at 230 rad/s


def far_start(period: float, far: float = FAR) -> float:
    """A crank angle near `far` [rad] that is a whole number K of dynamic periods (period [rad]) as turns_and_phase
    reads it: (K, 0.0), so that the run started there is the run started at 0, K periods on."""
    turns = round(far / period)
    while turns_and_phase(turns * period, period) != (turns, 0.0):
        turns += 1
    return turns * period


def near_and_far(name: str, duration: float, **changes):
    """The runs of a shortened bundled scene started at phi = 0 and at far_start; returns them and the far start."""
    near = model_of(shortened(name, duration, **changes))
    start = far_start(near.dynamic_period())
    far = model_of(shortened(name, duration, **changes, scenario__initial__phi=start))
    return simulate(near), simulate(far), start


# each kind of restart: switch windows (the engines' tables of the indicator diagram, the lathe's cutting on and
# off), governor modes and hard stops (engine_direct started fast: its sleeve flies to the high stop and leaves it;
# the indirect governor's servo stops), joint friction's guides and the crank's stop, a clutch's stick and slip, the
# knots of a driven part's table and of a coupling's characteristic
CASES = [
    ("engine_direct", 0.4, {"scenario__initial__omega": 300.0}),
    ("engine_direct", 0.4, {"scenario__initial__omega": 300.0, "solver__method": "RK45"}),
    ("engine_direct", 0.2, {"scenario__initial__omega": 300.0, "solver__method": "RK4", "solver__step": 5e-4}),
    ("engine_indirect_none", 0.4, {}),
    ("lathe", 1.0, {}),
    ("compressor_friction", 0.3, {}),
    ("press_coupling", 0.5, {}),
]


@pytest.mark.parametrize("path", ["fast", "reference"])
@pytest.mark.parametrize(
    "name, duration, changes",
    CASES,
    ids=[f"{name}-{changes.get('solver__method', 'DOP853')}" for name, _, changes in CASES],
)
def test_a_run_started_at_1e7_rad_is_the_run_started_at_0(name, duration, changes, path):
    near, far, start = near_and_far(name, duration, solver__path=path, **changes)
    assert near.status == far.status == "complete", (near.message, far.message)
    assert start > 0.9 * FAR
    assert far.stats == near.stats and near.stats.switches + len(near.events) > 0, near.stats
    assert far.events == near.events
    times = np.linspace(0.0, duration, 401)
    near_states, far_states = near(times), far(times)
    np.testing.assert_array_equal(far_states[1:], near_states[1:])  # every state but phi, bit for bit
    last_place = math.ulp(start + near_states[0].max())
    np.testing.assert_allclose(far_states[0] - start, near_states[0], rtol=0.0, atol=2.0 * last_place)


@pytest.mark.parametrize("path", ["fast", "reference"])
def test_a_machine_whose_phi_is_only_an_output_runs_the_same_at_1e7_rad(path):
    """clutch_start (a motor and a working machine joined by a friction clutch, no mechanism): nothing depends on phi,
    so the solver steps it as it is; its error control weighs phi's error against rtol |phi|, and the steps far out
    differ within the tolerance (docs/hard_cases.md). The clutch locks at the same instant and the speeds agree."""
    near, far, start = near_and_far("clutch_start", 2.0, solver__path=path)
    assert near.status == far.status == "complete", (near.message, far.message)
    assert [name for _, name in far.events] == [name for _, name in near.events] == ["clutch locks (slip ends)"]
    assert far.events[0][0] == pytest.approx(near.events[0][0], abs=1e-6)
    times = np.linspace(0.0, 2.0, 201)
    np.testing.assert_allclose(far(times)[1:], near(times)[1:], rtol=1e-7, atol=1e-7)


@pytest.mark.parametrize("name, duration", [("lathe", 3.0), ("press", 1.0)])
def test_the_energy_method_started_at_1e7_rad_is_the_run_started_at_0(name, duration):
    """The energy method steps in the phase too: its steps end on the same switch angles, at the same times."""
    near, far, start = near_and_far(name, duration, solver__method="energy", solver__phi_step_deg=5.0)
    assert near.status == far.status == "complete", (near.message, far.message)
    assert far.stats == near.stats and near.stats.steps > 50
    times = np.linspace(0.0, duration, 201)
    near_states, far_states = near(times), far(times)
    np.testing.assert_array_equal(far_states[1:], near_states[1:])
    np.testing.assert_allclose(
        far_states[0] - start, near_states[0], rtol=0.0, atol=2.0 * math.ulp(start + near_states[0].max())
    )


@pytest.mark.parametrize("path", ["fast", "reference"])
def test_a_switch_at_1e7_rad_is_located_on_its_angle(path):
    """The lathe's cutting starts and stops at fixed crank angles: started 1e7 rad on, the steps that end on a
    switch end on its angle to the last place of phi (the phase is set onto the angle, not read back off phi)."""
    near, far, start = near_and_far("lathe", 3.0, solver__path=path)
    model = model_of(shortened("lathe", 1.0))
    period, grid = model.dynamic_period(), np.array(model.switch_grid())
    angles = np.concatenate((grid, grid + period))
    phis = far(step_edges(far))[0]
    phases = phis - start - period * np.floor((phis - start) / period)
    distance = np.min(np.abs(phases[:, None] - angles[None, :]), axis=1)
    on_switches = distance[distance < 1e-6]
    assert on_switches.size >= far.stats.switches >= 20
    assert np.all(on_switches <= 4.0 * math.ulp(FAR)), on_switches.max()


def test_engine_direct_runs_past_73_s_and_a_longer_run_is_the_shorter_where_they_overlap():
    """Before the phase was carried, the fast path stopped advancing at t = 72.19 s of engine_direct (phi = 16 387
    rad, where a switch window's edge read back off phi fell 1.7e-12 rad short of the edge: its guard fired at once,
    for ever). (The reference path takes minutes for 80 s of the engine; its phase is tested at 1e7 rad above.)"""
    shorter = simulate(model_of(shortened("engine_direct", 72.0, solver__path="fast")))
    longer = simulate(model_of(shortened("engine_direct", 80.0, solver__path="fast")))
    assert shorter.status == longer.status == "complete", (shorter.message, longer.message)
    assert longer.t_end == 80.0 and longer(np.array([80.0]))[0, 0] > 17_000.0
    times = np.linspace(0.0, 71.0, 2001)
    np.testing.assert_array_equal(longer(times), shorter(times))
    assert [event for event in longer.events if event[0] <= 71.0] == shorter.events


def test_a_restart_that_makes_no_progress_ends_the_fast_run_failed(monkeypatch):
    """A switch window that the phase is always just below (the kind of restart that spun before): the stepper's
    window guard fires at its start, again and again; the run ends failed, naming the time, the restart and the
    state, after MAX_RESTARTS_WITHOUT_PROGRESS of them."""
    true_layout = run._Layout.of

    def with_window_ahead(model, compiled):
        layout = true_layout(model, compiled)
        true_window = layout.switch_window  # the compiled time_domain.switch_window a call starts in

        def window_ahead(grid, period, phase, forward):
            lo, hi = true_window(grid, period, phase, forward)
            return (phase + 1e-9, hi) if phase > 0.5 else (lo, hi)  # the edge ahead of where the crank is

        return layout._replace(switch_window=window_ahead)

    monkeypatch.setattr(run, "_LAYOUTS", {})  # the layouts made anew here, and dropped after
    monkeypatch.setattr(run._Layout, "of", with_window_ahead)
    trajectory = simulate(model_of(shortened("engine_direct", 0.3, solver__path="fast")))
    assert trajectory.status == "failed"
    assert "no progress at t = " in trajectory.message and "switch angle" in trajectory.message
    assert "omega = " in trajectory.message and str(MAX_RESTARTS_WITHOUT_PROGRESS) in trajectory.message
    assert 0.0 < trajectory.t_end < 0.3


def test_a_restart_that_makes_no_progress_ends_the_reference_run_failed(monkeypatch):
    """An event at the start of every step (a guard that fires and restarts without moving): the reference path ends
    failed the same way."""
    real_first_event = time_domain._first_event

    def at_once(dense, t_old, t_new, counts, switches, guards, noise=None, wrapped=None):
        if t_old > 0.01:
            y = dense(t_old)
            return t_old, y, counts, None, "switch", (wrapped or dense)(t_old)[0]
        return real_first_event(dense, t_old, t_new, counts, switches, guards, noise, wrapped=wrapped)

    monkeypatch.setattr(time_domain, "_first_event", at_once)
    trajectory = simulate(model_of(shortened("lathe", 0.3, solver__path="reference")))
    assert trajectory.status == "failed"
    assert "no progress at t = " in trajectory.message and "omega = " in trajectory.message
    assert 0.01 <= trajectory.t_end < 0.3


@pytest.mark.parametrize(
    "phi, period", [(0.0, 4 * math.pi), (1e7, 4 * math.pi), (-3.0, 2 * math.pi), (123456.789, 0.7)]
)
def test_turns_and_phase_split_the_angle_into_whole_periods_and_the_rest(phi, period):
    turns, phase = turns_and_phase(phi, period)
    assert isinstance(turns, int)
    assert 0.0 <= phase < period
    assert turns * period + phase == pytest.approx(phi, rel=0.0, abs=2 * math.ulp(phi or 1.0))


def test_a_run_the_step_limit_cannot_finish_is_refused_before_it_starts(capsys):
    """RK45 on engine_direct takes some 1 500 steps a second: 10 000 s would stop at MAX_STEPS after some 6 400 s.
    Its first second, probed, says so at once: exit code 2, the key, the value, the estimate and the limit."""
    code, out, err = run_cli(
        capsys,
        "simulate",
        "engine_direct",
        "--set",
        "scenario.duration=10000",
        "--set",
        "solver.method=RK45",
        "--set",
        "solver.path=reference",
        "--quiet",
    )
    assert code == 2 and out == "", (out, err)
    assert "scenario.duration = 10000 s: solver.method = RK45 took " in err and "steps over the run's first 1 s" in err
    assert f"beyond the limit of {MAX_STEPS:g} steps of one run; expected scenario.duration <= " in err, err
    estimate = float(err.split("so some ")[1].split(" steps")[0])
    assert MAX_STEPS < estimate < 3 * MAX_STEPS, err


def test_an_rk4_run_whose_restarts_pass_the_step_limit_is_refused_before_it_starts():
    """The lathe with RK4's step of 1e-4 s for 1000 s: duration / step is the limit itself, but every switch of its
    cutting adds a step (it stopped at t = 999.47 s after 1e7 steps). Its first second, probed, says so at once."""
    reason = step_limit_refusal(
        model_of(shortened("lathe", 1000.0, solver__path="fast", solver__method="RK4", solver__step=1e-4))
    )
    assert reason.startswith("scenario.duration = 1000 s: solver.method = RK4 took 100"), reason
    assert "beyond the limit of 1e+07 steps of one run; expected scenario.duration <= 99" in reason, reason
    assert "s, or a longer solver.step (docs/scenes.md, Limits)" in reason, reason


def test_a_long_run_within_the_step_limit_is_not_refused():
    """DOP853 on engine_direct takes some 700 steps a second: its first second, probed, finds 10 000 s within the
    limit (the run of docs/scenes.md, Limits, 6.9 million steps)."""
    model = model_of(shortened("engine_direct", 10_000.0, solver__path="fast"))
    assert step_limit_refusal(model) is None


def test_a_long_runs_outputs_are_worked_out_in_chunks_with_the_same_numbers(tmp_path, capsys, monkeypatch):
    """Memory bounded however long the run (docs/scenes.md, Limits): the CSV is written SAMPLE_CHUNK samples at a
    time, a Trajectory evaluates EVALUATION_CHUNK times at a time and the cycle-mean speed CYCLE_CHUNK times at a
    time. Made tiny here, they give the rows and states they give whole, and the cycle-mean speed to the grid's
    interpolation error."""
    arguments = ["simulate", "lathe", "--set", "solver.path=reference", "--set", "scenario.duration=1.0", "--quiet"]
    whole, chunked = tmp_path / "whole.csv", tmp_path / "chunked.csv"
    assert run_cli(capsys, *arguments, "--out", str(whole))[0] == 0
    monkeypatch.setattr(simulate_command, "SAMPLE_CHUNK", 7)
    assert run_cli(capsys, *arguments, "--out", str(chunked))[0] == 0
    rows = whole.read_text().splitlines()
    assert len(rows) > 100 and rows[0].startswith("t,phi,omega")
    assert chunked.read_text().splitlines() == rows

    model = model_of(shortened("lathe", 1.0, solver__path="reference"))
    trajectory = simulate(model)
    times = np.linspace(0.0, 1.0, 1001)
    states, means = trajectory(times), cycle_mean_speed(model, trajectory, times)
    monkeypatch.setattr(trajectory_module, "EVALUATION_CHUNK", 13)
    monkeypatch.setattr(load_response, "CYCLE_CHUNK", 17)
    np.testing.assert_array_equal(trajectory(times), states)
    chunked_means = cycle_mean_speed(model, trajectory, times)
    assert np.isnan(means[0]) and np.array_equal(np.isnan(chunked_means), np.isnan(means))
    assert np.count_nonzero(np.isfinite(means)) > 500
    np.testing.assert_allclose(chunked_means, means, rtol=1e-7)
