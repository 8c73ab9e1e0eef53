"""Scenes that start from another scene: `base: SCENE` (a bundled name or a path relative to the file)
and change keys -- mappings merge key by key, `key: null` removes a key, anything else (lists too)
replaces. Loops, missing bases and a base that is not a string give a SceneError (exit code 2 on the
command line) with a clear message. Nothing here runs a simulation.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from support import run_cli as run
from support import write_scene

from mech_regulator.scene import SceneError, load_scene

LATHE_FLYWHEEL = 15.453292519943295

# A small complete scene used as a base by relative path.
PARENT = """\
name: parent
description: the parent scene
machine:
  inertia: 0.5
  flywheel: {inertia: 0.2, ratio: 2.0}
  drive: {type: constant, torque: 3.0}
  loads:
    - {type: viscous, coefficient: 0.01}
    - {type: fan, coefficient: 1.0e-4}
scenario:
  initial: {phi: 0.0, omega: 10.0}
  duration: 0.5
solver: {method: RK45, rtol: 1.0e-6, sample_rate: 100.0}
"""


def write(folder: Path, name: str, text: str) -> Path:
    return write_scene(folder, text, name)


def scene_error(path: Path) -> str:
    with pytest.raises(SceneError) as caught:
        load_scene(str(path))
    return str(caught.value)


def assert_cli_refuses(capsys, path: Path, *fragments: str) -> str:
    code, out, err = run(capsys, "describe", str(path))
    assert code == 2, err
    assert out == ""
    assert err.startswith("mech-regulator: "), err
    for fragment in fragments:
        assert fragment in err, (fragment, err)
    return err


def without(dump: dict, *paths: str) -> dict:
    """A model_dump with the dotted paths taken out (to compare the rest)."""
    dump = {key: dict(value) if isinstance(value, dict) else value for key, value in dump.items()}
    for dotted in paths:
        *parents, last = dotted.split(".")
        node = dump
        for key in parents:
            node[key] = dict(node[key])
            node = node[key]
        node.pop(last)
    return dump


# ----------------------------------------------------------------------------------------------
# A bundled base


def test_bundled_base_with_a_change(tmp_path, capsys):
    path = write(tmp_path, "heavy_lathe.yaml", "base: lathe\nmachine:\n  flywheel: {inertia: 40.0}\n")
    scene = load_scene(str(path))
    lathe = load_scene("lathe")
    assert scene.machine.flywheel.inertia == 40.0
    assert scene.machine.flywheel.ratio == 1.0  # the rest of machine.flywheel stays
    assert scene.name == "heavy_lathe"  # the derived file's stem, not 'lathe'
    assert lathe.name == "lathe"
    # everything else is the lathe's
    assert without(scene.model_dump(), "name", "description", "machine.flywheel") == without(
        lathe.model_dump(), "name", "description", "machine.flywheel"
    )
    assert scene.machine.drive == lathe.machine.drive and scene.machine.loads == lathe.machine.loads
    code, out, err = run(capsys, "describe", str(path))
    assert code == 0, err
    assert "scene: heavy_lathe" in out
    assert f"constant J = {2.0 + 40.0:g} kg m^2" in out


def test_derived_file_may_name_itself(tmp_path):
    path = write(tmp_path, "x.yaml", "base: lathe\nname: my lathe\nscenario: {duration: 1.0}\n")
    scene = load_scene(str(path))
    assert scene.name == "my lathe"
    assert scene.scenario.duration == 1.0
    assert scene.scenario.initial.omega == 15.15  # scenario.initial kept


def test_set_applies_after_the_base(tmp_path):
    path = write(tmp_path, "x.yaml", "base: lathe\nmachine:\n  flywheel: {inertia: 40.0}\n")
    scene = load_scene(str(path), ["machine.flywheel.ratio=2", "machine.inertia=3"])
    assert (scene.machine.flywheel.inertia, scene.machine.flywheel.ratio, scene.machine.inertia) == (40.0, 2.0, 3.0)


def test_changes_are_validated(tmp_path, capsys):
    path = write(tmp_path, "x.yaml", "base: lathe\nmachine:\n  flywheel: {inertai: 40.0}\n")
    assert_cli_refuses(capsys, path, "machine.flywheel.inertai", "did you mean 'inertia'?")


# ----------------------------------------------------------------------------------------------
# Merging


def test_nested_mapping_merges(tmp_path):
    write(tmp_path, "parent.yaml", PARENT)
    scene = load_scene(
        str(
            write(
                tmp_path,
                "child.yaml",
                "base: parent.yaml\nmachine:\n  flywheel: {ratio: 3.0}\nsolver: {rtol: 1.0e-9}\n",
            )
        )
    )
    assert (scene.machine.flywheel.inertia, scene.machine.flywheel.ratio) == (0.2, 3.0)
    assert scene.machine.inertia == 0.5 and scene.machine.drive.torque == 3.0
    assert (scene.solver.method, scene.solver.rtol, scene.solver.sample_rate) == ("RK45", 1e-9, 100.0)


def test_lists_replace(tmp_path):
    write(tmp_path, "parent.yaml", PARENT)
    scene = load_scene(
        str(
            write(
                tmp_path,
                "child.yaml",
                "base: parent.yaml\nmachine:\n  loads:\n    - {type: viscous, coefficient: 0.5}\n",
            )
        )
    )
    assert len(scene.machine.loads) == 1
    assert (scene.machine.loads[0].type, scene.machine.loads[0].coefficient) == ("viscous", 0.5)
    lathe = load_scene(str(write(tmp_path, "lathe2.yaml", "base: lathe\nmachine:\n  loads: []\n")))
    assert lathe.machine.loads == []


def test_null_removes_a_key(tmp_path, capsys):
    write(tmp_path, "parent.yaml", PARENT)
    path = write(tmp_path, "child.yaml", "base: parent.yaml\nmachine:\n  flywheel: null\n")
    scene = load_scene(str(path))
    assert scene.machine.flywheel is None
    assert scene.machine.inertia == 0.5 and len(scene.machine.loads) == 2
    code, out, err = run(capsys, "describe", str(path))
    assert code == 0, err
    assert "constant J = 0.5 kg m^2" in out
    # from the bundled lathe too: no flywheel leaves J = 2
    code, out, err = run(
        capsys, "describe", str(write(tmp_path, "bare.yaml", "base: lathe\nmachine: {flywheel: null}\n"))
    )
    assert code == 0, err
    assert "constant J = 2 kg m^2" in out


def test_null_removes_a_key_inside_a_section_and_defaults_return(tmp_path):
    write(tmp_path, "parent.yaml", PARENT)
    scene = load_scene(str(write(tmp_path, "child.yaml", "base: parent.yaml\nsolver: {method: null, rtol: null}\n")))
    assert scene.solver.method == "DOP853" and scene.solver.rtol == 1e-8  # the schema's defaults
    assert scene.solver.sample_rate == 100.0


def test_null_for_a_key_the_base_lacks_is_harmless(tmp_path):
    write(tmp_path, "parent.yaml", PARENT)
    scene = load_scene(str(write(tmp_path, "child.yaml", "base: parent.yaml\nmachine: {mechanism: null}\n")))
    assert scene.machine.mechanism is None and scene.machine.flywheel.inertia == 0.2


def test_a_section_replaced_by_a_scalar_is_reported(tmp_path, capsys):
    write(tmp_path, "parent.yaml", PARENT)
    path = write(tmp_path, "child.yaml", "base: parent.yaml\nmachine: {flywheel: 0.3}\n")
    assert_cli_refuses(capsys, path, "machine.flywheel", "0.3")


# ----------------------------------------------------------------------------------------------
# Relative paths and chains


def test_base_relative_to_the_file_not_the_working_folder(tmp_path, monkeypatch):
    # (a base stays inside the scene's own folder, subfolders allowed: test_hostile_input.py refuses '..')
    write(tmp_path, "scenes/variants/parents/parent.yaml", PARENT)
    child = write(tmp_path, "scenes/variants/child.yaml", "base: parents/parent.yaml\nmachine: {inertia: 0.7}\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    scene = load_scene(str(child))
    assert scene.machine.inertia == 0.7
    assert scene.machine.flywheel.inertia == 0.2
    assert scene.name == "child"
    assert scene.description is None  # the base's description is not inherited


def test_relative_base_next_to_the_file(tmp_path, capsys):
    write(tmp_path, "parent.yaml", PARENT)
    child = write(tmp_path, "child.yaml", "base: parent.yaml\nscenario: {duration: 0.25}\n")
    code, out, err = run(capsys, "describe", str(child))
    assert code == 0, err
    assert "scene: child" in out and "scenario: 0.25 s" in out


def test_chain_of_two_bases(tmp_path):
    write(tmp_path, "grand.yaml", PARENT)
    write(
        tmp_path,
        "mid.yaml",
        "base: grand.yaml\nname: middle\nmachine:\n  flywheel: {inertia: 0.4}\nscenario: {duration: 0.3}\n",
    )
    child = write(
        tmp_path, "child.yaml", "base: mid.yaml\nmachine:\n  flywheel: {ratio: 1.5}\n  drive: {torque: 4.0}\n"
    )
    scene = load_scene(str(child))
    assert (scene.machine.flywheel.inertia, scene.machine.flywheel.ratio) == (0.4, 1.5)
    assert scene.machine.drive.type == "constant" and scene.machine.drive.torque == 4.0
    assert scene.scenario.duration == 0.3  # from mid
    assert scene.solver.method == "RK45"  # from grand
    assert scene.name == "child"  # neither 'middle' nor 'parent'
    assert load_scene(str(tmp_path / "mid.yaml")).name == "middle"


def test_chain_through_a_bundled_scene(tmp_path):
    write(tmp_path, "mid.yaml", "base: lathe\nmachine:\n  flywheel: {inertia: 30.0}\n")
    scene = load_scene(str(write(tmp_path, "child.yaml", "base: mid.yaml\nscenario: {duration: 2.0}\n")))
    assert scene.machine.flywheel.inertia == 30.0 and scene.scenario.duration == 2.0
    assert scene.machine.drive.torque == pytest.approx(83.33333333333333)


# ----------------------------------------------------------------------------------------------
# Mistakes


def test_loop_of_two(tmp_path, capsys):
    a = write(tmp_path, "a.yaml", "base: b.yaml\n")
    write(tmp_path, "b.yaml", "base: a.yaml\n")
    message = scene_error(a)
    for fragment in ("base = 'a.yaml'", "loop"):
        assert fragment in message, message
    assert_cli_refuses(capsys, a, "base", "loop")


def test_loop_to_itself(tmp_path, capsys):
    path = write(tmp_path, "self.yaml", "base: self.yaml\nmachine: {inertia: 1.0}\n")
    assert_cli_refuses(capsys, path, str(path), "base = 'self.yaml'", "loop")


def test_loop_of_three_through_subfolders(tmp_path):
    a = write(tmp_path, "a.yaml", "base: sub/b.yaml\n")
    write(tmp_path, "sub/b.yaml", "base: deeper/c.yaml\n")
    write(tmp_path, "sub/deeper/c.yaml", "base: d.yaml\n")
    write(tmp_path, "sub/deeper/d.yaml", "base: c.yaml\n")
    assert "loop" in scene_error(a)


@pytest.mark.parametrize("base", ["nothere", "nothere.yaml", "sub/nothere.yaml"])
def test_missing_base(tmp_path, capsys, base):
    path = write(tmp_path, "child.yaml", f"base: {base}\n")
    message = scene_error(path)
    assert f"'{base}'" in message and "no such file" in message, message
    assert_cli_refuses(capsys, path, base, "no such file")


def test_missing_base_names_the_file_that_refers_to_it(tmp_path):
    write(tmp_path, "mid.yaml", "base: nothere.yaml\n")
    child = write(tmp_path, "child.yaml", "base: mid.yaml\n")
    message = scene_error(child)
    assert "mid.yaml" in message and "base" in message, message


def test_base_is_not_looked_up_in_the_working_folder(tmp_path, monkeypatch):
    write(tmp_path, "parent.yaml", PARENT)  # in the working folder, not next to child.yaml
    child = write(tmp_path, "sub/child.yaml", "base: parent.yaml\n")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SceneError):
        load_scene(str(child))


@pytest.mark.parametrize(
    "written, shown", [("3", "3"), ("[lathe]", "['lathe']"), ("{name: lathe}", "{'name': 'lathe'}"), ("true", "True")]
)
def test_base_not_a_string(tmp_path, capsys, written, shown):
    path = write(tmp_path, "child.yaml", f"base: {written}\nmachine: {{inertia: 1.0}}\n")
    message = scene_error(path)
    for fragment in (str(path), f"base = {shown}", "expected the name of a bundled scene or a path"):
        assert fragment in message, message
    assert_cli_refuses(capsys, path, f"base = {shown}")


def test_base_null_means_no_base(tmp_path):
    path = write(tmp_path, "plain.yaml", "base: null\n" + PARENT)
    assert load_scene(str(path)).machine.inertia == 0.5


# ----------------------------------------------------------------------------------------------
# The bundled governed scenes


@pytest.mark.parametrize(
    "name, kind, feedback",
    [
        ("engine_direct", "direct", None),
        ("engine_indirect_none", "indirect", "none"),
        ("engine_indirect_rigid", "indirect", "rigid"),
        ("engine_indirect_isodromic", "indirect", "isodromic"),
    ],
)
def test_bundled_governed_scenes(name, kind, feedback):
    scene = load_scene(name)
    engine = load_scene("engine")
    assert scene.name == name
    governor = scene.governor
    assert governor is not None and governor.type == kind
    if kind == "direct":
        assert governor.valve.type == "linear"
    else:
        assert governor.feedback.type == feedback
        assert not hasattr(governor, "valve")  # 'valve: null' removed engine_direct's valve
        assert governor.stroke[0] < governor.pilot_neutral < governor.stroke[1]
        if feedback != "none":
            assert governor.feedback.gain > 0
        if feedback == "isodromic":
            assert governor.feedback.time_constant > 0
    # from engine_direct all the way down: the sensor, the lighter flywheel, the loads, the load levels
    direct = load_scene("engine_direct")
    for key in ("ball_mass", "arm_length", "sleeve_mass", "ratio", "stroke"):
        assert getattr(governor, key) == getattr(direct.governor, key), key
    assert scene.machine.flywheel == direct.machine.flywheel != engine.machine.flywheel
    assert scene.scenario.external_load == 6.0
    assert scene.scenario.load_events[0].torque == 8.0
    # from engine: the mechanism and the engine drive
    assert scene.machine.mechanism == engine.machine.mechanism
    assert scene.machine.drive == engine.machine.drive
    assert scene.machine.inertia == engine.machine.inertia
    assert scene.description and scene.description != engine.description


def test_indirect_scenes_differ_only_in_feedback():
    """... and in run's exchange step: the hunting engine without feedback exchanges every 10 ms (docs/ros.md)."""
    none, rigid, isodromic = (load_scene(f"engine_indirect_{kind}") for kind in ("none", "rigid", "isodromic"))
    differing = ("name", "description", "governor.feedback", "solver.exchange_step")
    for scene in (rigid, isodromic):
        assert without(scene.model_dump(), *differing) == without(none.model_dump(), *differing)
        assert scene.solver.exchange_step == 0.02
    assert none.solver.exchange_step == 0.01
