"""Every run checks itself (analysis/self_check.py): a run whose energy residual exceeds what its tolerance allows, or
whose mode log misses an event, is
reported `inaccurate` with the check, its value, the allowed value and the fix, in the summary and the JSON;
`--strict` makes it exit 3. The deliberately loose run: a load switched on for 3 deg of each turn by a table in phi,
integrated by LSODA, a multistep method that steps over the knots of tables (time_domain.STEPS_OVER_KINKS: it does not
restart on them), whose steps stride over the pulse (the speed runs up as if the load were not there: residual 17 %);
the advised solver.max_step = 1e-4 s resolves it (residual 3e-9). (Before kinks became switches it was a slider force
table over 5 mm of the stroke under DOP853; its breakpoints are now located like a table in phi's knots.)"""

from __future__ import annotations

import dataclasses
import json

import pytest
import yaml
from support import model_of, run_cli, scene, simulate_complete
from test_governor_dynamics import DIRECT

from mech_regulator.analysis import summarise
from mech_regulator.analysis.self_check import (
    ENERGY_PER_RTOL,
    FIXED_STEP_RESIDUAL,
    MODE_PER_RTOL,
    mode_log_check,
    self_checks,
)
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene

PULSED_LOAD = {
    "name": "pulsed_load",
    "machine": {
        "inertia": 2.0,
        "drive": {"type": "linear_motor", "stall_torque": 400.0, "no_load_speed": 20.0},
        "loads": [
            {
                "type": "table",
                "angle_deg": [0.0, 100.0, 100.01, 103.0, 103.01],
                "period_deg": 360.0,
                "torque": [0.0, 0.0, 300.0, 300.0, 0.0],
            }
        ],
    },
    "scenario": {"initial": {"phi": 0.0, "omega": 15.0}, "duration": 2.0},
    "solver": {"method": "LSODA", "rtol": 1e-10, "atol": 1e-12},
}


@pytest.fixture
def pulsed(tmp_path) -> str:
    path = tmp_path / "pulsed.yaml"
    path.write_text(yaml.safe_dump(PULSED_LOAD, sort_keys=False))
    return str(path)


def test_a_loose_run_is_reported_inaccurate(capsys, pulsed):
    code, out, err = run_cli(capsys, "simulate", pulsed, "--quiet", "--json")
    summary = json.loads(out)
    assert code == 0 and summary["status"] == "inaccurate", summary["status"]
    (check,) = summary["self_checks"]
    assert check["check"] == "energy residual (relative)" and check["allowed"] == ENERGY_PER_RTOL * 1e-10
    assert check["value"] == abs(summary["energy"]["relative_residual"]) > 1e-3
    assert "warning: inaccurate run: energy residual" in err and "solver.max_step" in err, err


def test_strict_makes_it_exit_3_and_the_advised_fix_makes_it_complete(capsys, pulsed):
    code, out, _ = run_cli(capsys, "simulate", pulsed, "--quiet", "--strict")
    assert code == 3 and out.startswith("scene pulsed_load: inaccurate at t = 2 s")
    code, out, err = run_cli(
        capsys, "simulate", pulsed, "--quiet", "--strict", "--json", "--set", "solver.max_step=0.0001"
    )
    summary = json.loads(out)
    assert code == 0 and summary["status"] == "complete" and summary["self_checks"] == [], err


@pytest.mark.parametrize("name", ["lathe", "startup", "press", "engine"])
def test_bundled_scenes_pass_their_own_check(capsys, name):
    code, out, _ = run_cli(
        capsys,
        "simulate",
        name,
        "--quiet",
        "--strict",
        "--json",
        *(["--set", "scenario.duration=2", "--set", "scenario.load_events=[]"] if name == "engine" else []),
    )
    assert code == 0 and json.loads(out)["self_checks"] == []


def test_the_fixed_step_methods_have_their_own_bound():
    model = build_model(load_scene("lathe", ["solver.method=RK4", "solver.step=0.001"]))
    summary = {"energy": {"relative_residual": 2 * FIXED_STEP_RESIDUAL}}
    (check,) = self_checks(model, summary)
    assert check["allowed"] == FIXED_STEP_RESIDUAL and "solver.step" in check["fix"]
    assert self_checks(model, {"energy": {"relative_residual": FIXED_STEP_RESIDUAL / 2}}) == []
    assert self_checks(model, {"energy": None}) == []


# The mode-log check: a sleeve with static > kinetic friction under a ramped load sticks and breaks away many times
# (test_hard_cases_governor.py's stick-slip base). A run's own mode log passes; the same run with one logged mode
# change taken out (its stretch merged into the one before) claims the sleeve kept a mode whose guard went below 0
# — what a missed event looks like — and is caught, naming the guard.
STICK_SLIP = scene(
    DIRECT,
    governor__friction=1.0,
    governor__static_friction=3.0,
    governor__damping=100.0,
    scenario={"duration": 3.0, "external_load": 0.0, "load_events": [{"time": 0.5, "torque": 30.0, "ramp": 2.0}]},
    solver={"method": "DOP853", "rtol": 1e-8, "atol": 1e-10},
)


def test_a_run_passes_its_own_mode_log_and_a_missed_event_is_caught():
    model = model_of(STICK_SLIP)
    trajectory = simulate_complete(model)
    assert len(trajectory.modes) >= 4, trajectory.modes
    assert mode_log_check(model, trajectory) is None
    assert self_checks(model, summarise(model, trajectory), trajectory) == []
    # the longest stretch after the first: its start taken out of the log, as if the solver had not seen it
    lengths = [
        (end - start, index)
        for index, ((start, _), (end, _)) in enumerate(zip(trajectory.modes[1:], trajectory.modes[2:]), start=1)
    ]
    _, missed = max(lengths)
    doctored = dataclasses.replace(trajectory, modes=trajectory.modes[:missed] + trajectory.modes[missed + 1 :])
    check = mode_log_check(model, doctored)
    assert check is not None and check["value"] > check["allowed"] == MODE_PER_RTOL * 1e-8
    left_mode = trajectory.modes[missed - 1][1]
    assert any(guard.name in check["check"] for guard in model.guards(left_mode)), (check, left_mode)
    (reported,) = self_checks(model, summarise(model, doctored), doctored)
    assert reported["check"].startswith("missed event") and "solver.rtol" in reported["fix"]
