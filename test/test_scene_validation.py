"""Scene validation through the command line: every mistake gives exit code 2 and a clear message
naming the key (dotted path), the value and what is expected -- never a traceback.

Each test starts from a small valid scene, breaks one thing, and runs
`mech_regulator.cli.main.main([...])` in-process (one test also runs `python -m mech_regulator`).
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
from support import run_cli as run
from support import write_scene as write

import mech_regulator
from mech_regulator.scene.loading import bundled_scenes, load_scene

# A valid scene: a crank-slider with a flywheel, a constant drive and a viscous load.
BASE = """\
name: mini
machine:
  inertia: 0.1
  flywheel: {inertia: 0.2, ratio: 1.0}
  mechanism: {type: crank_slider, crank: 0.05, rod: 0.2, offset: 0.0, rod_mass: 0.3, rod_inertia: 0.001, slider_mass: 1.0}
  drive: {type: constant, torque: 1.0}
  loads:
    - {type: viscous, coefficient: 0.01}
scenario:
  initial: {phi: 0.0, omega: 10.0}
  duration: 0.2
solver: {method: DOP853, sample_rate: 100.0}
"""

MECHANISM_LINE = (
    "  mechanism: {type: crank_slider, crank: 0.05, rod: 0.2, offset: 0.0, rod_mass: 0.3, "
    "rod_inertia: 0.001, slider_mass: 1.0}"
)
assert MECHANISM_LINE in BASE


def edited(*replacements: tuple[str, str], text: str = BASE) -> str:
    """BASE with each (old, new) replaced exactly once (a typo in a test must not silently pass)."""
    for old, new in replacements:
        assert text.count(old) == 1, f"{old!r} occurs {text.count(old)} times in the base scene"
        text = text.replace(old, new)
    return text


def four_bar_line(crank, coupler, rocker, frame, extra="") -> str:
    return (
        f"  mechanism: {{type: four_bar, crank: {crank}, coupler: {coupler}, rocker: {rocker}, frame: {frame}{extra}}}"
    )


def run_bad(capsys, tmp_path: Path, text: str, *options: str, command: str = "simulate") -> str:
    """Run a broken scene; check exit code 2 and no traceback; return stderr."""
    path = write(tmp_path, text)
    quiet = ["--quiet"] if command == "simulate" else []
    code, out, err = run(capsys, command, str(path), *quiet, *options)
    assert code == 2, f"exit code {code}; stderr:\n{err}"
    assert "Traceback" not in out + err
    assert err.startswith("mech-regulator: "), err
    return err


def assert_all_in(err: str, *fragments: str) -> None:
    for fragment in fragments:
        assert fragment in err, f"{fragment!r} missing from:\n{err}"


# ----------------------------------------------------------------------------------------------
# The base scene itself is valid (otherwise every test below would pass for the wrong reason)


def test_base_scene_is_valid(tmp_path, capsys):
    code, out, err = run(capsys, "describe", str(write(tmp_path, BASE)))
    assert code == 0, err
    assert "crank_slider" in out
    four_bar = edited((MECHANISM_LINE, four_bar_line(0.04, 0.12, 0.08, 0.10)))
    code, out, err = run(capsys, "describe", str(write(tmp_path, four_bar)))
    assert code == 0, err


# ----------------------------------------------------------------------------------------------
# Unknown keys, with the closest valid one


@pytest.mark.parametrize("command", ["simulate", "describe"])
def test_unknown_key_in_mechanism_suggests_closest(tmp_path, capsys, command):
    err = run_bad(capsys, tmp_path, edited(("rod: 0.2", "rodd: 0.2")), command=command)
    assert_all_in(err, "machine.mechanism.rodd", "unknown key", "did you mean 'rod'?", "valid keys here")


def test_unknown_key_at_top_level(tmp_path, capsys):
    err = run_bad(capsys, tmp_path, edited(("name: mini", "name: mini\ndescripton: a small machine")))
    assert_all_in(err, "descripton", "unknown key", "did you mean 'description'?")
    assert "1 problem" in err


def test_unknown_key_inside_list_item(tmp_path, capsys):
    err = run_bad(capsys, tmp_path, edited(("coefficient: 0.01", "coeficient: 0.01")))
    assert_all_in(err, "machine.loads.0.coeficient", "did you mean 'coefficient'?")


def test_unknown_key_spelt_like_the_type_tag(tmp_path, capsys):
    err = run_bad(capsys, tmp_path, edited(("{type: viscous, coefficient: 0.01}", "{type: fan, fan: 0.01}")))
    assert_all_in(
        err, "machine.loads.0.fan:", "machine.loads.0.coefficient: missing", "valid keys here: type, coefficient"
    )
    assert "machine.loads.0.fan.fan" not in err


@pytest.mark.parametrize(
    "old, new, path, bad, valid",
    [
        (
            "type: viscous",
            "type: viscus",
            "machine.loads.0.type",
            "'viscus'",
            ["'viscous'", "'fan'", "'cutting'", "'slider_table'", "'rocker_spring'"],
        ),
        (
            "type: constant",
            "type: konstant",
            "machine.drive.type",
            "'konstant'",
            ["'constant'", "'linear_motor'", "'table'", "'engine'"],
        ),
        (
            "type: crank_slider",
            "type: crank_slder",
            "machine.mechanism.type",
            "'crank_slder'",
            ["'crank_slider'", "'four_bar'"],
        ),
    ],
)
def test_unknown_type_lists_valid_types(tmp_path, capsys, old, new, path, bad, valid):
    err = run_bad(capsys, tmp_path, edited((old, new)))
    assert_all_in(err, path, bad, "unknown type", "expected one of", *valid)


def test_missing_type_lists_valid_types(tmp_path, capsys):
    err = run_bad(capsys, tmp_path, edited(("{type: viscous, coefficient: 0.01}", "{coefficient: 0.01}")))
    assert_all_in(err, "machine.loads.0", "type", "'viscous'", "'fan'")


# ----------------------------------------------------------------------------------------------
# Wrong types


@pytest.mark.parametrize(
    "old, new, path, shown",
    [
        ("inertia: 0.1", "inertia: heavy", "machine.inertia", "'heavy'"),
        ("duration: 0.2", 'duration: "0.2"', "scenario.duration", "'0.2'"),
        ("slider_mass: 1.0", "slider_mass: true", "machine.mechanism.slider_mass", "True"),
        ("coefficient: 0.01", "coefficient: [0.01]", "machine.loads.0.coefficient", "[0.01]"),
        ("inertia: 0.1", "inertia: 0.1\n  gravity: [0.0, down]", "machine.gravity.1", "'down'"),
    ],
)
def test_wrong_type(tmp_path, capsys, old, new, path, shown):
    err = run_bad(capsys, tmp_path, edited((old, new)))
    assert_all_in(err, f"{path} = {shown}", "valid number")


def test_section_given_as_a_scalar(tmp_path, capsys):
    err = run_bad(capsys, tmp_path, edited((MECHANISM_LINE, "  mechanism: crank_slider")))
    assert_all_in(err, "machine.mechanism = 'crank_slider'", "dictionary")


# ----------------------------------------------------------------------------------------------
# Non-physical values


@pytest.mark.parametrize(
    "old, new, path, value",
    [
        ("slider_mass: 1.0", "slider_mass: -1.0", "machine.mechanism.slider_mass", "-1.0"),
        ("rod_mass: 0.3", "rod_mass: -0.3", "machine.mechanism.rod_mass", "-0.3"),
    ],
)
def test_negative_mass(tmp_path, capsys, old, new, path, value):
    err = run_bad(capsys, tmp_path, edited((old, new)))
    assert_all_in(err, f"{path} = {value}", "greater than or equal to 0", "[kg]")


@pytest.mark.parametrize(
    "old, new, path, value",
    [
        ("inertia: 0.1", "inertia: -0.1", "machine.inertia", "-0.1"),
        ("{inertia: 0.2, ratio", "{inertia: -0.2, ratio", "machine.flywheel.inertia", "-0.2"),
        ("rod_inertia: 0.001", "rod_inertia: -0.001", "machine.mechanism.rod_inertia", "-0.001"),
    ],
)
def test_negative_inertia(tmp_path, capsys, old, new, path, value):
    err = run_bad(capsys, tmp_path, edited((old, new)))
    assert_all_in(err, f"{path} = {value}", "greater than or equal to 0", "[kg m^2]")


@pytest.mark.parametrize(
    "old, new, path, value",
    [
        ("crank: 0.05", "crank: 0", "machine.mechanism.crank", "0"),
        ("crank: 0.05", "crank: -0.05", "machine.mechanism.crank", "-0.05"),
        ("rod: 0.2", "rod: 0.0", "machine.mechanism.rod", "0.0"),
        ("rod: 0.2", "rod: -0.2", "machine.mechanism.rod", "-0.2"),
        ("duration: 0.2", "duration: 0", "scenario.duration", "0"),
    ],
)
def test_zero_or_negative_length(tmp_path, capsys, old, new, path, value):
    err = run_bad(capsys, tmp_path, edited((old, new)))
    assert_all_in(err, f"{path} = {value}", "greater than 0")


@pytest.mark.parametrize("link", ["crank", "coupler", "rocker", "frame"])
def test_four_bar_non_positive_link(tmp_path, capsys, link):
    lengths = {"crank": 0.04, "coupler": 0.12, "rocker": 0.08, "frame": 0.10}
    lengths[link] = -lengths[link]
    text = edited((MECHANISM_LINE, four_bar_line(*lengths.values())))
    err = run_bad(capsys, tmp_path, text)
    assert_all_in(err, f"machine.mechanism.{link} = {lengths[link]}", "greater than 0")


@pytest.mark.parametrize("crank, rod, offset", [(0.05, 0.07, 0.03), (0.05, 0.07, -0.03), (0.05, 0.05, 0.0)])
def test_rod_shorter_than_crank_plus_offset(tmp_path, capsys, crank, rod, offset):
    text = edited(("crank: 0.05", f"crank: {crank}"), ("rod: 0.2", f"rod: {rod}"), ("offset: 0.0", f"offset: {offset}"))
    err = run_bad(capsys, tmp_path, text)
    limit = crank + abs(offset)
    assert_all_in(err, "machine.mechanism", f"rod = {rod}", "crank + |offset|", f"{limit:g}")


def _unassemblable_range_deg(a: float, b: float, c: float, d: float) -> tuple[float, float]:
    """Crank angles (frame along +x) where |B - D| >= b + c: by the law of cosines in triangle A B D,
    |B - D|^2 = a^2 + d^2 - 2 a d cos(phi), so the loop breaks for cos(phi) <= (a^2 + d^2 - (b + c)^2) / (2 a d)."""
    limit = math.degrees(math.acos((a * a + d * d - (b + c) ** 2) / (2 * a * d)))
    return limit, 360.0 - limit


def test_non_grashof_four_bar_states_crank_angle_range(tmp_path, capsys):
    a, b, c, d = 0.05, 0.08, 0.06, 0.10  # a + d = 0.15 > b + c = 0.14: cannot pass phi = 180 deg
    err = run_bad(capsys, tmp_path, edited((MECHANISM_LINE, four_bar_line(a, b, c, d))))
    lo, hi = _unassemblable_range_deg(a, b, c, d)
    assert 90 < lo < 180 < hi < 270
    assert_all_in(
        err,
        "machine.mechanism",
        "cannot be assembled",
        f"{lo:.2f} to {hi:.2f} deg",
        "Grashof",
        f"crank {a}",
        f"coupler {b}",
        f"rocker {c}",
        f"frame {d}",
    )
    # the breaking point itself: |B - D| = b + c exactly at the ends of the range
    for angle in (lo, hi):
        phi = math.radians(angle)
        assert math.hypot(a * math.cos(phi) - d, a * math.sin(phi)) == pytest.approx(b + c)


def test_non_grashof_four_bar_range_follows_frame_angle(tmp_path, capsys):
    a, b, c, d = 0.05, 0.08, 0.06, 0.10
    err = run_bad(capsys, tmp_path, edited((MECHANISM_LINE, four_bar_line(a, b, c, d, ", frame_angle_deg: 30.0"))))
    lo, hi = _unassemblable_range_deg(a, b, c, d)
    assert f"{lo + 30:.2f} to {hi + 30:.2f} deg" in err, err


# ----------------------------------------------------------------------------------------------
# NaN and infinity


@pytest.mark.parametrize(
    "old, new, path, shown",
    [
        ("inertia: 0.1", "inertia: .nan", "machine.inertia", "nan"),
        ("torque: 1.0", "torque: .inf", "machine.drive.torque", "inf"),
        ("torque: 1.0", "torque: -.inf", "machine.drive.torque", "-inf"),
        ("omega: 10.0", "omega: .NaN", "scenario.initial.omega", "nan"),
        ("sample_rate: 100.0", "sample_rate: .Inf", "solver.sample_rate", "inf"),
        ("inertia: 0.1", "inertia: 0.1\n  gravity: [0.0, .nan]", "machine.gravity.1", "nan"),
    ],
)
def test_nan_and_infinity(tmp_path, capsys, old, new, path, shown):
    err = run_bad(capsys, tmp_path, edited((old, new)))
    assert_all_in(err, f"{path} = {shown}", "finite number")


# ----------------------------------------------------------------------------------------------
# YAML reading


@pytest.mark.parametrize(
    "written, value", [("1e-3", 1e-3), ("1E-3", 1e-3), ("2e2", 200.0), ("+5e-3", 5e-3), ("1.5e-2", 0.015)]
)
def test_exponent_without_dot_is_a_number(tmp_path, capsys, written, value):
    """PyYAML (YAML 1.1) reads 1e-3 as a string; the scene loader reads it as a number."""
    path = write(tmp_path, edited(("coefficient: 0.01", f"coefficient: {written}")))
    scene = load_scene(str(path))
    assert scene.machine.loads[0].coefficient == pytest.approx(value)
    assert isinstance(scene.machine.loads[0].coefficient, float)
    code, out, err = run(capsys, "describe", str(path))
    assert code == 0, err


@pytest.mark.parametrize("written, value", [("-.01", -0.01), ("+.01", 0.01)])
def test_signed_float_without_leading_digit_is_a_number(tmp_path, written, value):
    path = write(tmp_path, edited(("offset: 0.0", f"offset: {written}")))
    assert load_scene(str(path)).machine.mechanism.offset == pytest.approx(value)


def test_yaml_syntax_error_names_line(tmp_path, capsys):
    text = edited(("  duration: 0.2", "\tduration: 0.2"))
    line = text.splitlines().index("\tduration: 0.2") + 1
    err = run_bad(capsys, tmp_path, text)
    assert_all_in(err, "not valid YAML", f"line {line}", "scene.yaml")


def test_yaml_unclosed_bracket_names_line(tmp_path, capsys):
    text = edited(
        (
            "solver: {method: DOP853, sample_rate: 100.0}",
            "solver: {method: DOP853, sample_rate: 100.0\nanalysis: {steady_tolerance: 1.0e-4}",
        )
    )
    err = run_bad(capsys, tmp_path, text)
    assert_all_in(err, "not valid YAML", "line ")


def test_python_tag_is_rejected(tmp_path, capsys):
    err = run_bad(capsys, tmp_path, edited(("inertia: 0.1", "inertia: !!python/object/apply:os.getcwd []")))
    assert_all_in(err, "not valid YAML", "line 3")


def test_top_level_must_be_a_mapping(tmp_path, capsys):
    err = run_bad(capsys, tmp_path, "- 1\n- 2\n")
    assert_all_in(err, "expected a mapping", "list")


def test_empty_file_reports_missing_sections(tmp_path, capsys):
    err = run_bad(capsys, tmp_path, "")
    assert_all_in(err, "machine: missing", "scenario: missing")


def test_file_not_utf8(tmp_path, capsys):
    path = tmp_path / "scene.yaml"
    path.write_bytes(BASE.replace("name: mini", "name: mini\ndescription: caf\xe9").encode("latin-1"))
    code, out, err = run(capsys, "simulate", str(path), "--quiet")
    assert code == 2
    assert "UTF-8" in err or "utf-8" in err


# ----------------------------------------------------------------------------------------------
# Missing keys and cross-checks


def test_missing_required_key(tmp_path, capsys):
    err = run_bad(capsys, tmp_path, edited(("  duration: 0.2\n", "")))
    assert_all_in(err, "scenario.duration", "missing", "simulated time [s]")


def test_missing_required_key_in_mechanism(tmp_path, capsys):
    err = run_bad(capsys, tmp_path, edited(("crank: 0.05, ", "")))
    assert_all_in(err, "machine.mechanism.crank", "missing", "crank radius")


@pytest.mark.parametrize(
    "mechanism, load, needs, has",
    [
        (four_bar_line(0.04, 0.12, 0.08, 0.10), "slider_viscous", "crank_slider", "four_bar"),
        (MECHANISM_LINE, "rocker_viscous", "four_bar", "crank_slider"),
        ("", "slider_viscous", "crank_slider", "no mechanism"),
    ],
)
def test_output_load_on_wrong_mechanism(tmp_path, capsys, mechanism, load, needs, has):
    text = edited((MECHANISM_LINE + "\n", mechanism + "\n" if mechanism else ""), ("type: viscous", f"type: {load}"))
    err = run_bad(capsys, tmp_path, text)
    assert_all_in(err, "machine", "loads[0]", f"'{load}'", f"needs mechanism.type: {needs}", has)


def test_engine_drive_needs_crank_slider(tmp_path, capsys):
    engine = "  drive: {type: engine, bore: 0.08, angle_deg: [0, 360], pressure: [0, 1.0e5]}"
    text = edited(
        (MECHANISM_LINE, four_bar_line(0.04, 0.12, 0.08, 0.10)), ("  drive: {type: constant, torque: 1.0}", engine)
    )
    err = run_bad(capsys, tmp_path, text)
    assert_all_in(err, "engine", "needs mechanism.type: crank_slider", "four_bar")


def test_load_events_out_of_order(tmp_path, capsys):
    events = "  load_events:\n    - {time: 0.1, torque: 1.0}\n    - {time: 0.05, torque: 2.0}\n"
    err = run_bad(capsys, tmp_path, edited(("  duration: 0.2\n", "  duration: 0.2\n" + events)))
    assert_all_in(err, "scenario", "load_events[1].time = 0.05", "0.1 s", "time order")


def test_load_event_ramp_overlaps_next(tmp_path, capsys):
    events = "  load_events:\n    - {time: 0.05, torque: 1.0, ramp: 0.1}\n    - {time: 0.1, torque: 2.0}\n"
    err = run_bad(capsys, tmp_path, edited(("  duration: 0.2\n", "  duration: 0.2\n" + events)))
    assert_all_in(err, "load_events[1].time = 0.1", "time order")


@pytest.mark.parametrize("event", ["{time: 0.3, torque: 1.0}", "{time: 0.15, torque: 1.0, ramp: 0.1}"])
def test_load_event_beyond_duration(tmp_path, capsys, event):
    err = run_bad(capsys, tmp_path, edited(("  duration: 0.2\n", f"  duration: 0.2\n  load_events: [{event}]\n")))
    assert_all_in(err, "scenario", "load_events[0] ends at", "duration 0.2 s")


def test_load_event_negative_time(tmp_path, capsys):
    err = run_bad(
        capsys, tmp_path, edited(("  duration: 0.2\n", "  duration: 0.2\n  load_events: [{time: -0.1, torque: 1.0}]\n"))
    )
    assert_all_in(err, "scenario.load_events.0.time = -0.1", "greater than or equal to 0")


@pytest.mark.parametrize(
    "old, new, path, fragments",
    [
        (
            "  drive: {type: constant, torque: 1.0}",
            "  drive: {type: table, angle_deg: [0, 90, 180], torque: [1, 2]}",
            "machine.drive",
            ["angle_deg has 3 entries", "values have 2"],
        ),
        (
            "{type: viscous, coefficient: 0.01}",
            "{type: table, angle_deg: [0, 90], torque: [1, 2, 3]}",
            "machine.loads.0",
            ["angle_deg has 2 entries", "values have 3"],
        ),
        (
            "{type: viscous, coefficient: 0.01}",
            "{type: slider_table, position: [0.1, 0.2, 0.3], force: [1, 2]}",
            "machine.loads.0",
            ["3 positions", "2 forces"],
        ),
        (
            "  drive: {type: constant, torque: 1.0}",
            "  drive: {type: engine, bore: 0.08, angle_deg: [0, 180, 360], pressure: [0, 1.0e5]}",
            "machine.drive",
            ["engine pressure", "angle_deg has 3 entries", "values have 2"],
        ),
    ],
)
def test_table_length_mismatch(tmp_path, capsys, old, new, path, fragments):
    err = run_bad(capsys, tmp_path, edited((old, new)))
    assert_all_in(err, path, "expected one", *fragments)


def test_table_angles_not_increasing(tmp_path, capsys):
    err = run_bad(
        capsys,
        tmp_path,
        edited(
            (
                "  drive: {type: constant, torque: 1.0}",
                "  drive: {type: table, angle_deg: [0, 180, 90], torque: [1, 2, 3]}",
            )
        ),
    )
    assert_all_in(err, "machine.drive", "[0.0, 180.0, 90.0]", "strictly increasing")


# ----------------------------------------------------------------------------------------------
# Several problems at once


def test_several_problems_reported_one_per_line(tmp_path, capsys):
    text = edited(
        ("inertia: 0.1", "inertia: -1"),
        ("torque: 1.0", "torque: .nan"),
        ("coefficient: 0.01", "coeficient: 0.01"),
        ("duration: 0.2", "duration: soon"),
    )
    err = run_bad(capsys, tmp_path, text)
    lines = err.rstrip("\n").splitlines()
    assert "problems:" in lines[0]
    problems = lines[1:]
    expected = [
        "machine.inertia = -1",
        "machine.drive.torque = nan",
        "machine.loads.0.coeficient",
        "scenario.duration = 'soon'",
    ]
    for fragment in expected:
        assert sum(fragment in line for line in problems) == 1, (fragment, err)
    assert f"{len(problems)} problems" in lines[0]
    assert len(problems) >= len(expected)
    assert all(line.startswith("  ") for line in problems)


# ----------------------------------------------------------------------------------------------
# --set overrides


@pytest.mark.parametrize(
    "assignment, fragments",
    [
        ("machine.inertia", ["--set 'machine.inertia'", "expected dotted.key=value"]),
        ("machine.loads.5.coefficient=1", ["machine.loads.5", "0 to 0", "'5'"]),
        ("machine.loads.first.coefficient=1", ["machine.loads.first", "must index the list", "'first'"]),
        ("machine.loads.-1.coefficient=1", ["machine.loads.-1", "must index the list"]),
        ("machine.inertia.value=1", ["'machine.inertia' holds 0.1", "not a section"]),
        ("scenario.duration.x.y=1", ["'scenario.duration' holds 0.2", "not a section"]),
        ("machine..inertia=1", ["empty part"]),
        ("machine.inertia=[1", ["--set machine.inertia", "not valid YAML"]),
    ],
)
def test_set_errors(tmp_path, capsys, assignment, fragments):
    err = run_bad(capsys, tmp_path, BASE, "--set", assignment)
    assert_all_in(err, *fragments)


def test_set_errors_on_describe(tmp_path, capsys):
    err = run_bad(capsys, tmp_path, BASE, "--set", "machine.loads.2=1", command="describe")
    assert_all_in(err, "machine.loads.2", "must index the list")


def test_set_value_is_validated(tmp_path, capsys):
    err = run_bad(capsys, tmp_path, BASE, "--set", "machine.inertia=-1")
    assert_all_in(err, "machine.inertia = -1", "greater than or equal to 0")
    err = run_bad(capsys, tmp_path, BASE, "--set", "machine.inertai=1")
    assert_all_in(err, "machine.inertai", "did you mean 'inertia'?")


def test_set_can_fix_a_broken_scene(tmp_path, capsys):
    path = write(tmp_path, edited(("inertia: 0.1", "inertia: -0.1")))
    code, out, err = run(capsys, "describe", str(path), "--set", "machine.inertia=1e-1")
    assert code == 0, err
    assert "0.1 kg m^2" in out or "0.3 kg m^2" in out


# ----------------------------------------------------------------------------------------------
# Scene files and output paths


@pytest.mark.parametrize(
    "name, suggestion", [("lathee", "lathe"), ("four_bar", "four_bar_rocker"), ("compresor.yaml", "compressor")]
)
def test_missing_scene_suggests_bundled(capsys, name, suggestion):
    code, out, err = run(capsys, "simulate", name)
    assert code == 2
    assert "Traceback" not in out + err
    assert_all_in(
        err,
        f"scene '{name}'",
        "no such file",
        f"did you mean the bundled scene '{suggestion}'?",
        "bundled: " + ", ".join(bundled_scenes()) + ")",
    )


def test_missing_scene_path(tmp_path, capsys):
    missing = tmp_path / "nowhere" / "my_scene.yaml"
    code, out, err = run(capsys, "describe", str(missing))
    assert code == 2
    assert_all_in(err, str(missing), "no such file")


@pytest.mark.parametrize("option", ["--out", "--plot"])
def test_output_folder_missing(tmp_path, capsys, option):
    target = tmp_path / "no_such_folder" / ("run.csv" if option == "--out" else "run.png")
    err = run_bad(capsys, tmp_path, BASE, option, str(target))
    assert_all_in(err, f"cannot write '{target}'", f"the folder '{target.parent}' does not exist")
    assert not target.parent.exists()


def test_output_folder_is_a_file(tmp_path, capsys):
    blocker = tmp_path / "blocker"
    blocker.write_text("not a folder")
    err = run_bad(capsys, tmp_path, BASE, "--out", str(blocker / "run.csv"))
    assert_all_in(err, "cannot write", str(blocker))


def test_output_path_is_a_folder(tmp_path, capsys):
    folder = tmp_path / "results"
    folder.mkdir()
    err = run_bad(capsys, tmp_path, BASE, "--out", str(folder))
    assert_all_in(err, "cannot write", str(folder))


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root can write to read-only folders")
def test_output_folder_not_writable(tmp_path, capsys):
    folder = tmp_path / "locked"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        err = run_bad(capsys, tmp_path, BASE, "--out", str(folder / "run.csv"))
    finally:
        folder.chmod(0o755)
    assert_all_in(err, "cannot write", str(folder))


# ----------------------------------------------------------------------------------------------
# The real command line


def test_python_m_exits_2_without_traceback(tmp_path):
    path = write(tmp_path, edited(("rod: 0.2", "rodd: 0.2"), ("inertia: 0.1", "inertia: .nan")))
    source_root = str(Path(mech_regulator.__file__).resolve().parents[1])  # works without an install too
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [source_root, os.environ.get("PYTHONPATH")]))}
    result = subprocess.run(
        [sys.executable, "-m", "mech_regulator", "simulate", str(path), "--quiet"],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
        env=env,
    )
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    assert_all_in(result.stderr, "machine.mechanism.rodd", "did you mean 'rod'?", "machine.inertia = nan")
    assert result.stdout == ""
