"""Governed scenes through the command line: `governor` (statics and stability, text, --json, --plot),
`simulate` of a governed scene (load responses, CSV columns), `describe`, and the governor's validation
messages.

Runs go through `mech_regulator.cli.main.main([...])` in-process. The machines here have a constant
inertia (no mechanism) and run for about a second, so they simulate quickly; the bundled engine scenes
are only analysed (`governor --json`), never simulated.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest
from support import run_cli as run
from support import write_scene as write

from mech_regulator.cli.main import main
from mech_regulator.scene import load_scene

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

# A direct-action Porter governor on a constant-J machine: linear motor M_d = throttle * 200 (1 - omega/150),
# viscous load 0.3 omega, valve fully open at z = 0.02 m and closed at z = 0.08 m.
DIRECT = """\
name: small_direct
machine:
  inertia: 0.5
  drive: {type: linear_motor, stall_torque: 200.0, no_load_speed: 150.0}
  loads:
    - {type: viscous, coefficient: 0.3}
governor:
  type: direct
  ball_mass: 1.0
  arm_length: 0.2
  sleeve_mass: 5.0
  damping: 200.0
  friction: 0.0
  ratio: 0.16
  stroke: [0.02, 0.08]
  valve: {open_at: 0.02, closed_at: 0.08}
scenario:
  initial: {omega: 112.86}
  duration: 1.6
  external_load: 0.0
  load_events:
    - {time: 0.4, torque: 10.0}
    - {time: 1.0, torque: 4.0}
solver: {method: DOP853, rtol: 1.0e-9, atol: 1.0e-11, sample_rate: 200.0}
"""

GOVERNOR_TYPE_LINE = "  type: direct\n"
VALVE_LINE = "  valve: {open_at: 0.02, closed_at: 0.08}\n"
INDIRECT_PART = (
    "  pilot_neutral: 0.05\n"
    "  servo: {gain: 100.0, max_speed: 2.0}\n"
    "  feedback: {type: isodromic, gain: 0.2, time_constant: 1.0}\n"
)
SERVO_LINE = "  servo: {gain: 100.0, max_speed: 2.0}\n"
FEEDBACK_LINE = "  feedback: {type: isodromic, gain: 0.2, time_constant: 1.0}\n"

# Sensor constants of DIRECT, for the closed-form statics below.
BALL, ARM, SLEEVE_MASS, RATIO, G = 1.0, 0.2, 5.0, 0.16, 9.81
STROKE = (0.02, 0.08)


def edited(*replacements: tuple[str, str], text: str = DIRECT) -> str:
    """text with each (old, new) replaced exactly once (a typo in a test must not silently pass)."""
    for old, new in replacements:
        assert text.count(old) == 1, f"{old!r} occurs {text.count(old)} times in the scene"
        text = text.replace(old, new)
    return text


INDIRECT = edited(
    ("name: small_direct", "name: small_isodromic"),
    ("  type: direct", "  type: indirect"),
    (VALVE_LINE, INDIRECT_PART),
    ("damping: 200.0", "damping: 100.0"),
)
UNGOVERNED = edited(
    (DIRECT[DIRECT.index("governor:") : DIRECT.index("scenario:")], ""), ("name: small_direct", "name: small_plain")
)


def run_quietly(*argv: str) -> tuple[int, str, str]:
    """main() with stdout and stderr captured, for module-scoped fixtures (no capsys there)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def assert_all_in(text: str, *fragments: str) -> None:
    for fragment in fragments:
        assert fragment in text, f"{fragment!r} not in:\n{text}"


def read_csv(path: Path) -> dict[str, np.ndarray]:
    with path.open(newline="") as handle:
        rows = list(csv.reader(handle))
    values = np.array([[float(value) for value in row] for row in rows[1:]])
    assert len(rows[0]) == len(set(rows[0])), rows[0]
    return {name: values[:, i] for i, name in enumerate(rows[0])}


# Closed-form statics of the Porter sensor without spring and friction:
# z = 2 l (1 - cos a), omega_g^2 = (m + M) g / (m l cos a), crank speed = omega_g / ratio.
def equilibrium_speed(z: float) -> float:
    cos_a = 1.0 - z / (2.0 * ARM)
    return math.sqrt((BALL + SLEEVE_MASS) * G / (BALL * ARM * cos_a)) / RATIO


def valve_throttle(z):
    return np.clip((STROKE[1] - np.asarray(z)) / (STROKE[1] - STROKE[0]), 0.0, 1.0)


# ----------------------------------------------------------------------------------------------
# governor SCENE


@pytest.fixture(scope="module")
def direct_analysis(tmp_path_factory) -> dict:
    path = write(tmp_path_factory.mktemp("direct_analysis"), DIRECT)
    code, out, err = run_quietly("governor", str(path), "--json")
    assert code == 0, err
    return json.loads(out)


def test_governor_json_keys(direct_analysis):
    analysis = direct_analysis
    assert {"scene", "kind", "statism", "operating_points", "linear", "floquet", "droop", "characteristic"} <= set(
        analysis
    )
    assert analysis["scene"] == "small_direct"
    assert analysis["kind"] == "direct"
    assert analysis["feedback"] is None
    assert analysis["floquet"] is None  # constant J: nothing periodic in phi
    linear = analysis["linear"]
    assert {"eigenvalues", "vyshnegradsky", "stable", "dominant", "damping_ratio", "polynomial"} <= set(linear)
    assert linear["state_names"] == ["omega", "arm_angle", "arm_rate"]
    assert len(linear["eigenvalues"]) == 3 and all(len(pair) == 2 for pair in linear["eigenvalues"])
    assert len(linear["vyshnegradsky"]) == 2
    assert [point["external_load"] for point in analysis["operating_points"]] == [0.0, 10.0, 4.0]


def test_governor_statics_match_closed_form(direct_analysis):
    """Static characteristic and statism from z = 2 l (1 - cos a), omega_g^2 = (m + M) g / (m l cos a)."""
    characteristic = direct_analysis["characteristic"]
    low, high = equilibrium_speed(STROKE[0]), equilibrium_speed(STROKE[1])
    assert characteristic["sleeve"][0] == pytest.approx(STROKE[0])
    assert characteristic["sleeve"][-1] == pytest.approx(STROKE[1])
    assert characteristic["speed"][0] == pytest.approx(low, rel=1e-9)
    assert characteristic["speed"][-1] == pytest.approx(high, rel=1e-9)
    for z, speed in zip(characteristic["sleeve"], characteristic["speed"]):
        assert speed == pytest.approx(equilibrium_speed(z), rel=1e-9)
    assert direct_analysis["statism"] == pytest.approx((high - low) / (0.5 * (high + low)), rel=1e-9)


def test_governor_operating_points_balance(direct_analysis):
    """At each operating point: speed on the static characteristic, throttle from the valve, and
    throttle * M_drive(omega) = viscous + external load."""
    for point in direct_analysis["operating_points"]:
        speed, z, throttle = point["speed"], point["sleeve"], point["throttle"]
        assert point["limited"] == ""
        assert STROKE[0] < z < STROKE[1]
        assert speed == pytest.approx(equilibrium_speed(z), rel=1e-6)
        assert throttle == pytest.approx(float(valve_throttle(z)), abs=1e-9)
        assert throttle * 200.0 * (1.0 - speed / 150.0) == pytest.approx(0.3 * speed + point["external_load"], rel=1e-6)
        assert point["mean_inertia"] == pytest.approx(0.5)
    first, loaded, _ = direct_analysis["operating_points"]
    assert first["speed"] == pytest.approx(112.86, abs=0.01)  # the scene starts at its operating point
    assert loaded["speed"] < first["speed"] and loaded["sleeve"] < first["sleeve"]  # droop of a direct governor
    droop = direct_analysis["droop"]
    assert droop["per_unit_load"] < 0
    assert droop["per_event"][0] == pytest.approx(loaded["speed"] - first["speed"], rel=1e-6)


def test_governor_linear_stability_consistent(direct_analysis):
    linear = direct_analysis["linear"]
    eigenvalues = np.array([complex(re, im) for re, im in linear["eigenvalues"]])
    roots = np.roots(linear["polynomial"])
    assert sorted(roots, key=lambda v: (v.real, v.imag)) == pytest.approx(
        sorted(eigenvalues, key=lambda v: (v.real, v.imag)), rel=1e-6
    )
    assert linear["stable"] == bool(np.all(eigenvalues.real < 0))
    A, B = linear["vyshnegradsky"]
    assert A > 0 and B > 0
    assert (A * B > 1) == linear["stable"]  # Vyshnegradsky's criterion for the third-order system
    assert linear["stable"]
    # less sleeve damping than the critical value makes the governor unstable
    assert 0 < linear["critical_damping"] < 200.0


def test_governor_text(tmp_path, capsys, direct_analysis):
    path = write(tmp_path, DIRECT)
    code, out, err = run(capsys, "governor", str(path))
    assert code == 0, err
    linear = direct_analysis["linear"]
    A, B = linear["vyshnegradsky"]
    assert_all_in(
        out,
        "scene small_direct: direct governor",
        f"statism (degree of non-uniformity) {direct_analysis['statism']:.4g}",
        "operating points",
        "eigenvalues [1/s]: ",
        "stable",
        f"Vyshnegradsky: A = {A:.4g}, B = {B:.4g}, A B = {A * B:.4g} (> 1: stable)",
    )
    point_lines = [line for line in out.splitlines() if line.startswith("  load ")]
    assert len(point_lines) == 3, out
    for line, point in zip(point_lines, direct_analysis["operating_points"]):
        assert f"omega {point['speed']:.6g} rad/s" in line, line
    assert "Floquet" not in out
    assert "wrote" not in out


def test_governor_plot(tmp_path, capsys):
    path, picture = write(tmp_path, DIRECT), tmp_path / "x.png"
    code, out, err = run(capsys, "governor", str(path), "--plot", str(picture))
    assert code == 0, err
    data = picture.read_bytes()
    assert data[:8] == PNG_SIGNATURE
    assert len(data) > 10_000
    assert f"wrote {picture}" in out


@pytest.mark.parametrize("scene", ["ungoverned", "lathe"])
def test_governor_without_governor(tmp_path, capsys, scene):
    target = str(write(tmp_path, UNGOVERNED)) if scene == "ungoverned" else scene
    code, out, err = run(capsys, "governor", target)
    assert code == 2
    assert out == ""
    name = "small_plain" if scene == "ungoverned" else "lathe"
    assert_all_in(err, "mech-regulator: ", f"scene '{name}'", "no governor", "'governor:'")


def test_governor_bad_plot_path_refused_before_work(tmp_path, capsys, monkeypatch):
    import mech_regulator.analysis

    def must_not_run(*args, **kwargs):
        raise AssertionError("the analysis ran although the plot cannot be written")

    monkeypatch.setattr(mech_regulator.analysis, "analyse_governor", must_not_run)
    target = tmp_path / "no_such_folder" / "x.png"
    code, out, err = run(capsys, "governor", str(write(tmp_path, DIRECT)), "--plot", str(target))
    assert code == 2
    assert out == ""
    assert_all_in(err, f"cannot write '{target}'", f"the folder '{target.parent}' does not exist")
    assert not target.parent.exists()


def test_governor_json_is_strict_json(tmp_path, capsys):
    code, out, err = run(capsys, "governor", str(write(tmp_path, DIRECT)), "--json")
    assert code == 0, err

    def reject(constant):
        raise ValueError(f"{constant} is not JSON")

    json.loads(out, parse_constant=reject)


# ----------------------------------------------------------------------------------------------
# A bundled governed engine (analysed only: a full run takes about 10 s)


@pytest.fixture(scope="module")
def engine_direct_analysis() -> dict:
    code, out, err = run_quietly("governor", "engine_direct", "--json")
    assert code == 0, err
    return json.loads(out)


def test_engine_direct_floquet(engine_direct_analysis):
    floquet = engine_direct_analysis["floquet"]
    assert floquet is not None  # the engine's J and drive are periodic in phi
    assert len(floquet["multipliers"]) == len(engine_direct_analysis["linear"]["eigenvalues"]) == 3
    moduli = [math.hypot(re, im) for re, im in floquet["multipliers"]]
    assert floquet["stable"] == (max(moduli) < 1)
    assert floquet["cycle_time"] > 0
    assert floquet["residual"] < 1e-6
    # the averaged model's exp(lambda T) is close to the true multipliers
    averaged = sorted(math.hypot(re, im) for re, im in floquet["averaged_multipliers"])
    assert averaged == pytest.approx(sorted(moduli), abs=0.02)


def test_engine_direct_load_levels(engine_direct_analysis):
    points = engine_direct_analysis["operating_points"]
    assert [point["external_load"] for point in points] == [6.0, 8.0, 0.0]
    assert points[1]["speed"] < points[0]["speed"] < points[2]["speed"]  # direct action: droop
    # the averaged model's operating point is the mean speed of the true periodic orbit
    floquet = engine_direct_analysis["floquet"]
    assert points[0]["speed"] == pytest.approx(floquet["mean_speed"], rel=1e-3)
    # the scene starts on that orbit: at phi = 0 with the orbit's speed and the operating point's sleeve
    initial = load_scene("engine_direct").scenario.initial
    assert initial.phi == 0.0
    assert floquet["orbit"][0] == pytest.approx(initial.omega, abs=0.01)
    assert points[0]["sleeve"] == pytest.approx(initial.sleeve, abs=1e-5)


# ----------------------------------------------------------------------------------------------
# simulate a governed scene


@pytest.fixture(scope="module")
def direct_run(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("direct_run")
    path, csv_path = write(folder, DIRECT), folder / "run.csv"
    code, out, err = run_quietly("simulate", str(path), "--quiet", "--json", "--out", str(csv_path))
    assert code == 0, err
    return {"summary": json.loads(out), "csv": csv_path, "scene": path}


def test_simulate_governed_text(tmp_path, capsys):
    code, out, err = run(capsys, "simulate", str(write(tmp_path, DIRECT)), "--quiet")
    assert code == 0, err
    assert "governor: predicted operating point" in out
    response_lines = [line for line in out.splitlines() if line.startswith("  load ")]
    assert len(response_lines) == 2, out
    assert "load 0 -> 10 N m at 0.4 s" in response_lines[0]
    assert "load 10 -> 4 N m at 1 s" in response_lines[1]
    for line in response_lines:
        assert_all_in(line, "peak deviation", "static error", "new speed", "overshoot")


def test_simulate_governed_json_load_responses(direct_run, direct_analysis):
    summary = direct_run["summary"]
    assert summary["status"] == "complete"
    governed = summary["governor"]
    responses = governed["load_responses"]
    assert len(responses) == 2
    fields = {
        "time",
        "load_before",
        "load_after",
        "speed_before",
        "peak_deviation",
        "peak_time",
        "speed_after",
        "static_error",
        "predicted_static_error",
        "settling_time",
        "overshoot",
        "limits",
    }
    for response in responses:
        assert fields <= set(response), set(response)
        assert response["static_error"] == pytest.approx(response["speed_after"] - response["speed_before"])
        assert response["limits"] == []
    first, second = responses
    assert (first["time"], first["load_before"], first["load_after"]) == (0.4, 0.0, 10.0)
    assert (second["time"], second["load_before"], second["load_after"]) == (1.0, 10.0, 4.0)
    # more load: the speed dips and settles lower; less load: it rises
    assert first["peak_deviation"] < first["static_error"] < 0
    assert second["peak_deviation"] > 0
    # the statics' prediction is the difference of the operating points of `governor`
    speeds = [point["speed"] for point in direct_analysis["operating_points"]]
    assert first["predicted_static_error"] == pytest.approx(speeds[1] - speeds[0], rel=1e-6)
    assert second["predicted_static_error"] == pytest.approx(speeds[2] - speeds[1], rel=1e-6)
    point = governed["operating_point"]
    assert point["speed"] == pytest.approx(speeds[0])
    assert point["external_load"] == 0.0


def test_simulate_governed_csv_columns(direct_run):
    columns = read_csv(direct_run["csv"])
    assert {"throttle", "sleeve", "sleeve_velocity", "arm_angle"} <= set(columns)
    assert "servo" not in columns and "feedback_shift" not in columns  # direct action
    assert all(np.all(np.isfinite(values)) for values in columns.values())
    assert len(columns["t"]) == round(1.6 * 200) + 1
    sleeve = columns["sleeve"]
    assert np.all((sleeve >= STROKE[0] - 1e-12) & (sleeve <= STROKE[1] + 1e-12))
    # geometry and valve: z = 2 l (1 - cos a), throttle = valve(z)
    assert sleeve == pytest.approx(2 * ARM * (1 - np.cos(columns["arm_angle"])), abs=1e-12)
    assert columns["throttle"] == pytest.approx(valve_throttle(sleeve), abs=1e-9)
    # the sleeve starts at rest at its equilibrium for the initial speed, and drops when the load rises
    assert columns["sleeve_velocity"][0] == 0.0
    assert equilibrium_speed(sleeve[0]) == pytest.approx(112.86, rel=1e-6)
    before = columns["t"] <= 0.4
    assert sleeve[before] == pytest.approx(sleeve[0], abs=1e-5)
    assert sleeve[np.isclose(columns["t"], 1.0)][0] < sleeve[0] - 1e-3


def test_simulate_indirect_csv_has_servo(tmp_path, capsys):
    csv_path = tmp_path / "run.csv"
    text = edited(("duration: 1.6", "duration: 0.8"), ("    - {time: 1.0, torque: 4.0}\n", ""), text=INDIRECT)
    code, out, err = run(capsys, "simulate", str(write(tmp_path, text)), "--quiet", "--json", "--out", str(csv_path))
    assert code == 0, err
    assert len(json.loads(out)["governor"]["load_responses"]) == 1
    columns = read_csv(csv_path)
    assert {"throttle", "sleeve", "sleeve_velocity", "arm_angle", "servo", "feedback_shift"} <= set(columns)
    assert columns["throttle"] == pytest.approx(columns["servo"])  # the servo position is the throttle
    assert np.all((columns["servo"] >= 0.0) & (columns["servo"] <= 1.0))
    assert columns["feedback_shift"][0] == 0.0
    # the servo opens the throttle after the load rises at 0.4 s
    assert columns["servo"][-1] > columns["servo"][columns["t"] <= 0.4][-1]


# ----------------------------------------------------------------------------------------------
# describe


def test_describe_indirect_isodromic(tmp_path, capsys):
    code, out, err = run(capsys, "describe", str(write(tmp_path, INDIRECT)))
    assert code == 0, err
    assert (
        "state vector: phi [rad], omega [rad/s], arm_angle [rad], arm_rate [rad/s], servo [-], feedback_shift [m]"
    ) in out
    assert_all_in(out, "indirect governor", "isodromic feedback", "pilot neutral at z = 0.05 m", "s' = -100 * opening")


def test_describe_direct_has_no_servo_state(tmp_path, capsys):
    code, out, err = run(capsys, "describe", str(write(tmp_path, DIRECT)))
    assert code == 0, err
    assert "state vector: phi [rad], omega [rad/s], arm_angle [rad], arm_rate [rad/s]\n" in out
    assert "direct governor" in out


# ----------------------------------------------------------------------------------------------
# Validation: exit code 2 and a message naming the key and the value


def run_bad(capsys, tmp_path: Path, text: str) -> str:
    code, out, err = run(capsys, "describe", str(write(tmp_path, text)))
    assert code == 2, f"exit code {code}; stderr:\n{err}"
    assert out == ""
    assert err.startswith("mech-regulator: "), err
    return err


DRIVE_LINE = "  drive: {type: linear_motor, stall_torque: 200.0, no_load_speed: 150.0}\n"
TABLE_VALVE = "  valve: {type: table, sleeve: [0.02, 0.05, 0.08], throttle: [1.0, 1.5, 0.0]}\n"


@pytest.mark.parametrize(
    "base, old, new, fragments",
    [
        (
            "direct",
            "stroke: [0.02, 0.08]",
            "stroke: [0.0, 0.08]",
            ["governor", "stroke = [0.0, 0.08] m", "expected 0 < z_low < z_high"],
        ),
        (
            "direct",
            "stroke: [0.02, 0.08]",
            "stroke: [0.02, 0.5]",
            ["governor", "stroke = [0.02, 0.5] m", "2 arm_length = 0.4 m"],
        ),
        (
            "direct",
            "  friction: 0.0\n",
            "  friction: 5.0\n  static_friction: 2.0\n",
            ["governor", "static_friction = 2.0 N", "friction = 5.0 N", "expected static_friction >= friction"],
        ),
        (
            "indirect",
            "pilot_neutral: 0.05",
            "pilot_neutral: 0.09",
            ["governor", "pilot_neutral = 0.09 m", "outside the stroke [0.02, 0.08] m"],
        ),
        (
            "indirect",
            FEEDBACK_LINE,
            "  feedback: {type: rigid, gain: 0.0}\n",
            ["governor.feedback", "'rigid'", "gain > 0", "got 0.0"],
        ),
        (
            "indirect",
            FEEDBACK_LINE,
            "  feedback: {type: isodromic, gain: 0.2}\n",
            ["governor.feedback", "'isodromic'", "needs time_constant"],
        ),
        (
            "direct",
            "method: DOP853",
            "method: energy",
            ["solver.method 'energy'", "governed scene needs a method in time"],
        ),
        (
            "direct",
            "initial: {omega: 112.86}",
            "initial: {omega: 112.86, servo: 0.5}",
            ["scenario.initial.servo", "'direct'", "no servo-motor"],
        ),
        (
            "indirect",
            "initial: {omega: 112.86}",
            "initial: {omega: 112.86, servo: 1.5}",
            ["scenario.initial.servo = 1.5", "outside the servo travel [0.0, 1.0]"],
        ),
        (
            "direct",
            "initial: {omega: 112.86}",
            "initial: {omega: 112.86, sleeve: 0.1}",
            ["scenario.initial.sleeve = 0.1 m", "outside the governor's stroke [0.02, 0.08] m"],
        ),
        ("direct", DRIVE_LINE, "", ["machine.drive is missing", "governor"]),
        (
            "direct",
            VALVE_LINE,
            "  valve: {open_at: 0.05, closed_at: 0.05}\n",
            ["governor.valve", "open_at = closed_at = 0.05 m", "two different sleeve positions"],
        ),
        (
            "direct",
            VALVE_LINE,
            "  valve: {type: linear, open_at: 0.05, closed_at: 0.05}\n",
            ["governor.valve: open_at = closed_at = 0.05 m"],
        ),
        ("direct", VALVE_LINE, TABLE_VALVE, ["governor.valve", "throttle = [1.0, 1.5, 0.0]", "between 0 and 1"]),
        (
            "indirect",
            SERVO_LINE,
            "  servo: {gain: 100.0, max_sped: 2.0}\n",
            ["governor.servo.max_sped: unknown key", "did you mean 'max_speed'?", "gain, max_speed, dead_band, travel"],
        ),
        (
            "direct",
            "  type: direct",
            "  type: indirec",
            ["governor.type = 'indirec'", "unknown type", "'direct', 'indirect'"],
        ),
    ],
    ids=[
        "stroke_z_low_0",
        "stroke_beyond_arms",
        "static_below_kinetic_friction",
        "pilot_outside_stroke",
        "rigid_gain_0",
        "isodromic_without_time_constant",
        "energy_solver",
        "initial_servo_direct",
        "initial_servo_outside_travel",
        "initial_sleeve_outside_stroke",
        "no_drive",
        "valve_open_eq_closed",
        "linear_valve_open_eq_closed",
        "table_valve_throttle_range",
        "servo_unknown_key",
        "unknown_governor_type",
    ],
)
def test_governor_validation(tmp_path, capsys, base, old, new, fragments):
    text = edited((old, new), text=DIRECT if base == "direct" else INDIRECT)
    err = run_bad(capsys, tmp_path, text)
    assert_all_in(err, "1 problem:", *fragments)


def test_initial_sleeve_without_governor(tmp_path, capsys):
    err = run_bad(
        capsys,
        tmp_path,
        edited(("initial: {omega: 112.86}", "initial: {omega: 112.86, sleeve: 0.05}"), text=UNGOVERNED),
    )
    assert_all_in(err, "scenario.initial.sleeve is set", "no governor")


def test_scene_level_checks_run_after_section_checks(tmp_path, capsys):
    """A broken governor section is reported as such, not hidden behind (or crashing) the scene's cross-checks."""
    err = run_bad(
        capsys, tmp_path, edited(("stroke: [0.02, 0.08]", "stroke: [0.0, 0.08]"), ("method: DOP853", "method: energy"))
    )
    assert "stroke = [0.0, 0.08]" in err


def test_linear_valve_misspelt_key(tmp_path, capsys):
    err = run_bad(capsys, tmp_path, edited((VALVE_LINE, "  valve: {open_at: 0.02, closed_att: 0.08}\n")))
    assert ".linear" not in err
    assert_all_in(
        err,
        "governor.valve.closed_att: unknown key",
        "did you mean 'closed_at'?",
        "governor.valve.closed_at: missing; sleeve position with the valve closed",
    )


def test_table_valve_misspelt_key(tmp_path, capsys):
    err = run_bad(
        capsys,
        tmp_path,
        edited((VALVE_LINE, "  valve: {type: table, sleeve: [0.02, 0.08], throttle: [1.0, 0.0], throtle: 1}\n")),
    )
    assert_all_in(err, "governor.valve.throtle: unknown key", "did you mean 'throttle'?", "sleeve, throttle")
