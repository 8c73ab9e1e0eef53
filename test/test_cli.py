"""The `mech-regulator` command line: simulate (CSV, PNG, summary, --json, --set), describe, schema, scenes.

Runs go through `mech_regulator.cli.main.main([...])` in-process with short durations.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest
from support import run_cli as run

from mech_regulator.cli.main import main
from mech_regulator.scene.loading import read_scene_data

SCENES_DIR = Path(__file__).resolve().parents[1] / "config" / "scenes"
BUNDLED = sorted(path.stem for path in SCENES_DIR.glob("*.yaml"))
REQUIRED_COLUMNS = ["t", "phi", "omega", "epsilon", "J", "M_drive", "M_load"]
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def simulate_json(capsys, scene: str, *overrides: str) -> dict:
    argv = ["simulate", scene, "--quiet", "--json"]
    for assignment in overrides:
        argv += ["--set", assignment]
    code, out, err = run(capsys, *argv)
    assert code == 0, err
    return json.loads(out)


def read_csv(path: Path) -> tuple[list[str], list[list[float]]]:
    with path.open(newline="") as handle:
        rows = list(csv.reader(handle))
    return rows[0], [[float(value) for value in row] for row in rows[1:]]


def bundled_data(name: str) -> dict:
    """A bundled scene as plain data, read with the package's YAML reader (1e-3 is a number) and with
    its `base:` scene merged in."""
    return read_scene_data(SCENES_DIR / f"{name}.yaml")


def test_bundled_scenes_present():
    assert BUNDLED == [
        "clutch_start",
        "compressor",
        "compressor_friction",
        "crank_slider_bench",
        "engine",
        "engine_direct",
        "engine_hartnell",
        "engine_indirect_isodromic",
        "engine_indirect_none",
        "engine_indirect_rigid",
        "engine_inline4",
        "engine_pi",
        "four_bar_rocker",
        "geared_shaker",
        "lathe",
        "press",
        "press_coupling",
        "shaper",
        "sieve_shaker",
        "six_bar_press",
        "six_bar_press_friction",
        "startup",
        "two_mass",
        "valve_gear",
        "walking_beam",
        "walking_beam_linkage",
    ]


# ----------------------------------------------------------------------------------------------
# simulate


@pytest.fixture(scope="module")
def lathe_run(tmp_path_factory):
    """One short lathe run writing CSV and PNG; shared by the checks below."""
    folder = tmp_path_factory.mktemp("lathe_run")
    csv_path, png_path = folder / "run.csv", folder / "run.png"
    duration = 0.5
    code = main(
        [
            "simulate",
            "lathe",
            "--quiet",
            "--set",
            f"scenario.duration={duration}",
            "--out",
            str(csv_path),
            "--plot",
            str(png_path),
        ]
    )
    return {
        "code": code,
        "csv": csv_path,
        "png": png_path,
        "duration": duration,
        "sample_rate": bundled_data("lathe")["solver"]["sample_rate"],
    }


def test_simulate_exit_code(lathe_run):
    assert lathe_run["code"] == 0


def test_simulate_csv_columns_and_values(lathe_run):
    header, rows = read_csv(lathe_run["csv"])
    assert set(REQUIRED_COLUMNS) <= set(header), header
    assert len(header) == len(set(header))
    assert rows and all(len(row) == len(header) for row in rows)
    assert all(math.isfinite(value) for row in rows for value in row)
    column = {name: [row[i] for row in rows] for i, name in enumerate(header)}
    t = column["t"]
    duration, rate = lathe_run["duration"], lathe_run["sample_rate"]
    assert t[0] == 0.0
    assert t[-1] == pytest.approx(duration, abs=1e-9)
    assert len(t) == round(duration * rate) + 1
    steps = [b - a for a, b in zip(t, t[1:])]
    assert max(abs(step - 1.0 / rate) for step in steps) < 1e-9
    # the lathe: constant inertia J = 2 + 15.45..., constant drive, cutting load 0 or -100 N m
    assert all(j == pytest.approx(2.0 + 15.453292519943295) for j in column["J"])
    assert all(m == pytest.approx(83.33333333333333) for m in column["M_drive"])
    assert {round(m, 6) for m in column["M_load"]} <= {0.0, -100.0}
    assert column["omega"][0] == pytest.approx(15.15)
    assert all(14.8 < w < 15.2 for w in column["omega"])
    # epsilon = (M_drive + M_load) / J for a constant inertia
    for eps, md, ml, j in zip(column["epsilon"], column["M_drive"], column["M_load"], column["J"]):
        assert eps == pytest.approx((md + ml) / j)


def test_simulate_png(lathe_run):
    data = lathe_run["png"].read_bytes()
    assert data[:8] == PNG_SIGNATURE
    assert len(data) > 10_000
    width, height = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")  # IHDR
    assert width > 200 and height > 200


def test_plot_path_without_suffix_is_reported_correctly(tmp_path, capsys):
    code, out, err = run(
        capsys,
        "simulate",
        "lathe",
        "--quiet",
        "--json",
        "--set",
        "scenario.duration=0.2",
        "--plot",
        str(tmp_path / "picture"),
    )
    assert code == 0, err
    summary = json.loads(out)
    assert Path(summary["plot"]).is_file(), sorted(p.name for p in tmp_path.iterdir())


def test_simulate_prints_summary(tmp_path, capsys):
    code, out, err = run(
        capsys, "simulate", "lathe", "--quiet", "--set", "scenario.duration=0.5", "--out", str(tmp_path / "a.csv")
    )
    assert code == 0, err
    for fragment in (
        "scene lathe",
        "omega_m =",
        "delta =",
        "energy:",
        "residual",
        "solver DOP853",
        "steps",
        "rhs evaluations",
        f"wrote {tmp_path / 'a.csv'}",
    ):
        assert fragment in out, (fragment, out)


def test_simulate_json_summary(capsys):
    summary = simulate_json(capsys, "lathe", "scenario.duration=0.5")
    assert summary["scene"] == "lathe"
    assert summary["status"] == "complete"
    assert summary["t_end"] == pytest.approx(0.5)
    last = summary["steady"]["last_period"]
    for key in ("omega_m", "omega_max", "omega_min", "delta"):
        assert math.isfinite(last[key])
    # the lathe's flywheel was sized for omega_m = 15 rad/s and delta = 1/50
    assert last["omega_m"] == pytest.approx(15.0, rel=1e-3)
    assert last["delta"] == pytest.approx(0.02, rel=1e-2)
    energy = summary["energy"]
    assert {"works", "delta_kinetic", "residual", "relative_residual"} <= set(energy)
    assert abs(energy["relative_residual"]) < 1e-5
    solver = summary["solver"]
    assert solver["method"] == "DOP853"
    assert solver["steps"] > 0 and solver["nfev"] > 0


@pytest.mark.parametrize("scene", ["compressor", "engine", "four_bar_rocker"])
def test_simulate_other_scenes_briefly(tmp_path, capsys, scene):
    csv_path = tmp_path / f"{scene}.csv"
    # load events later than the short duration are rejected, so they go too (the engine has one)
    code, out, err = run(
        capsys,
        "simulate",
        scene,
        "--quiet",
        "--json",
        "--set",
        "scenario.duration=0.1",
        "--set",
        "scenario.load_events=[]",
        "--set",
        "solver.sample_rate=500",
        "--out",
        str(csv_path),
    )
    assert code == 0, err
    summary = json.loads(out)
    assert summary["status"] == "complete"
    assert summary["csv"] == str(csv_path)
    header, rows = read_csv(csv_path)
    assert set(REQUIRED_COLUMNS) <= set(header)
    assert len(rows) == round(0.1 * 500) + 1
    assert all(math.isfinite(value) for row in rows for value in row)
    # a mechanism: the reduced inertia varies with the crank angle
    j = [row[header.index("J")] for row in rows]
    assert max(j) > min(j)


def test_set_bigger_flywheel_gives_smaller_delta(capsys):
    base = simulate_json(capsys, "lathe", "scenario.duration=0.5")
    bigger = simulate_json(capsys, "lathe", "scenario.duration=0.5", "machine.flywheel.inertia=40")
    delta, delta_big = base["steady"]["last_period"]["delta"], bigger["steady"]["last_period"]["delta"]
    assert delta_big < delta
    # constant inertia: delta is about inversely proportional to J
    assert delta_big / delta == pytest.approx((2 + 15.453292519943295) / (2 + 40), rel=0.05)


def test_set_initial_omega_changes_result(capsys):
    base = simulate_json(capsys, "lathe", "scenario.duration=0.3")
    faster = simulate_json(capsys, "lathe", "scenario.duration=0.3", "scenario.initial.omega=20")
    assert faster["omega_end"] > base["omega_end"] + 4.0
    assert faster["phi_end"] > base["phi_end"]


def test_set_list_item(capsys):
    base = simulate_json(capsys, "lathe", "scenario.duration=0.3")
    lighter = simulate_json(capsys, "lathe", "scenario.duration=0.3", "machine.loads.0.torque=50")
    assert lighter["omega_end"] > base["omega_end"]


# ----------------------------------------------------------------------------------------------
# describe

EFFECT_WORDS = {  # what `describe` calls each effect type
    "constant": "constant",
    "linear_motor": "linear motor",
    "engine": "engine",
    "viscous": "viscous",
    "fan": "fan",
    "cutting": "cutting",
    "table": "table",
    "slider_viscous": "viscous on the slider",
    "slider_spring": "spring on the slider",
    "slider_table": "slider force table",
    "rocker_viscous": "viscous on the rocker",
    "rocker_spring": "spring on the rocker",
    "shuttle_viscous": "viscous on the shuttle bar",
    "slider_constant": "constant on the slider",
}


@pytest.mark.parametrize("scene", BUNDLED)
def test_describe_lists_effects_state_and_solver(capsys, scene):
    data = bundled_data(scene)
    code, out, err = run(capsys, "describe", scene)
    assert code == 0, err
    machine = data["machine"]
    effect_lines = [line for line in out.splitlines() if line.startswith("  - ")]
    expected = [machine["drive"]["type"]] + [load["type"] for load in machine.get("loads", [])]
    drive_lines = [line for line in effect_lines if line.startswith("  - drive")]
    assert len(drive_lines) == 1 and EFFECT_WORDS[machine["drive"]["type"]] in drive_lines[0]
    load_lines = [line for line in effect_lines if line.startswith("  - load")]
    for load in machine.get("loads", []):
        assert any(EFFECT_WORDS[load["type"]] in line for line in load_lines), (load, out)
    extra = ("gravity" in machine and "mechanism" in machine) + bool(data["scenario"].get("load_events"))
    assert len(effect_lines) == len(expected) + extra, out
    if "gravity" in machine:
        assert any("weight" in line for line in load_lines)
    if data["scenario"].get("load_events"):
        assert any("external load" in line for line in load_lines)
    assert "state vector: phi [rad], omega [rad/s]" in out
    solver = data["solver"]
    assert f"solver: {solver['method']}" in out
    assert f"output at {solver['sample_rate']:g} Hz" in out
    if "mechanism" in machine:
        assert machine["mechanism"]["type"] in out


def test_describe_follows_set(capsys):
    code, out, err = run(
        capsys,
        "describe",
        "lathe",
        "--set",
        "solver.method=RK4",
        "--set",
        "solver.step=2e-4",
        "--set",
        "scenario.duration=0.5",
    )
    assert code == 0, err
    assert "solver: RK4 (fixed step 0.0002 s)" in out
    assert "scenario: 0.5 s" in out


# ----------------------------------------------------------------------------------------------
# schema and scenes


@pytest.fixture(scope="module")
def schema_text():
    import contextlib
    import io

    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        code = main(["schema"])
    assert code == 0
    return buffer.getvalue()


def test_schema_is_json_schema(schema_text):
    schema = json.loads(schema_text)
    assert "json-schema.org" in schema["$schema"]
    assert schema["type"] == "object"
    assert {"machine", "scenario", "solver"} <= set(schema["properties"])
    assert {"machine", "scenario"} <= set(schema["else"]["required"])  # required unless the scene has a base
    assert schema.get("additionalProperties") is False


def test_schema_validates_bundled_scenes(schema_text):
    jsonschema = pytest.importorskip("jsonschema")
    schema = json.loads(schema_text)
    jsonschema.Draft202012Validator.check_schema(schema)
    validator = jsonschema.Draft202012Validator(schema)
    for name in BUNDLED:
        errors = list(validator.iter_errors(bundled_data(name)))
        assert not errors, (name, [error.message for error in errors])
    broken = bundled_data("lathe")
    broken["machine"]["inertai"] = 1.0
    assert list(validator.iter_errors(broken))


def test_schema_markdown(capsys):
    code, out, err = run(capsys, "schema", "--format", "markdown")
    assert code == 0
    assert "| key | type | default | meaning [unit] |" in out
    assert "`machine.mechanism`" in out


def test_scenes_lists_all_bundled(capsys):
    code, out, err = run(capsys, "scenes")
    assert code == 0, err
    listed = [line.split()[0] for line in out.splitlines() if line.strip()]
    assert listed == BUNDLED
    for line, name in zip(out.splitlines(), BUNDLED):
        first_words = " ".join(bundled_data(name)["description"].split()[:3])
        assert first_words in line
