"""Every run checks itself (analysis/self_check.py): a run whose energy residual exceeds what its tolerance allows is
reported `inaccurate` with the check, its value, the allowed value and the fix, in the summary and the JSON;
`--strict` makes it exit 3. The deliberately loose run: a load switched on and off within 0.5 deg, which DOP853's
steps stride over (the speed runs up to the motor's no-load speed as if the load were not there)."""

from __future__ import annotations

import json

import pytest
import yaml

from mech_regulator.analysis.self_check import ENERGY_PER_RTOL, FIXED_STEP_RESIDUAL, self_checks
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene
from support import run_cli

PULSED_LOAD = {
    "name": "pulsed_load",
    "machine": {"inertia": 2.0, "drive": {"type": "linear_motor", "stall_torque": 400.0, "no_load_speed": 20.0},
                "loads": [{"type": "table", "angle_deg": [0.0, 100.0, 100.01, 100.5, 100.51, 359.99],
                           "torque": [0.0, 0.0, 150.0, 150.0, 0.0, 0.0], "period_deg": 360.0}]},
    "scenario": {"initial": {"phi": 0.0, "omega": 15.0}, "duration": 2.0},
    "solver": {"method": "DOP853", "rtol": 1e-10, "atol": 1e-12},
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
    code, out, err = run_cli(capsys, "simulate", pulsed, "--quiet", "--strict", "--json", "--set",
                             "solver.max_step=0.0002")
    summary = json.loads(out)
    assert code == 0 and summary["status"] == "complete" and summary["self_checks"] == [], err


@pytest.mark.parametrize("name", ["lathe", "startup", "press", "engine"])
def test_bundled_scenes_pass_their_own_check(capsys, name):
    code, out, _ = run_cli(capsys, "simulate", name, "--quiet", "--strict", "--json",
                           *(["--set", "scenario.duration=2", "--set", "scenario.load_events=[]"]
                             if name == "engine" else []))
    assert code == 0 and json.loads(out)["self_checks"] == []


def test_the_fixed_step_methods_have_their_own_bound():
    model = build_model(load_scene("lathe", ["solver.method=RK4", "solver.step=0.001"]))
    summary = {"energy": {"relative_residual": 2 * FIXED_STEP_RESIDUAL}}
    (check,) = self_checks(model, summary)
    assert check["allowed"] == FIXED_STEP_RESIDUAL and "solver.step" in check["fix"]
    assert self_checks(model, {"energy": {"relative_residual": FIXED_STEP_RESIDUAL / 2}}) == []
    assert self_checks(model, {"energy": None}) == []
