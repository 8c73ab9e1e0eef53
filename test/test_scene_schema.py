"""The published scene schema: `mech-regulator schema`, its committed copy
config/schema/scene.schema.json and the yaml-language-server line of every bundled scene.

The schema accepts every bundled scene file as written, including those with `base:` (a partial scene whose
keys are deep-merged over the base), and rejects what the pydantic validation rejects key by key: misspelt
keys and wrong types, at the top level and nested, in complete and in partial scenes."""

import contextlib
import copy
import io
import json
from pathlib import Path

import pytest

from mech_regulator.scene import SceneError, load_scene
from mech_regulator.scene.loading import parse_yaml
from mech_regulator.scene.reference import schema_json

jsonschema = pytest.importorskip("jsonschema")

ROOT = Path(__file__).resolve().parents[1]
SCENES = sorted((ROOT / "config" / "scenes").glob("*.yaml"))
SCHEMA_FILE = ROOT / "config" / "schema" / "scene.schema.json"
MODELINE = "# yaml-language-server: $schema=../schema/scene.schema.json"


@pytest.fixture(scope="module")
def schema() -> dict:
    return json.loads(schema_json())


@pytest.fixture(scope="module", params=["2020-12", "draft 7"])
def validator(request, schema):
    """The schema's own dialect, and draft 7, which the VS Code YAML extension implements: both must agree."""
    cls = jsonschema.Draft202012Validator if request.param == "2020-12" else jsonschema.Draft7Validator
    cls.check_schema(schema)
    return cls(schema)


def file_data(path: Path) -> dict:
    """A scene file as written (its base not merged), read with the package's YAML reader."""
    return parse_yaml(path.read_text(encoding="utf-8"), str(path))


def errors(validator, data) -> list[str]:
    return [
        f"{'.'.join(map(str, error.absolute_path)) or '(top level)'}: {error.message}"
        for error in validator.iter_errors(data)
    ]


def write_scene(folder: Path, data: dict, name: str = "user_scene") -> Path:
    path = folder / f"{name}.yaml"
    path.write_text(json.dumps(data), encoding="utf-8")  # JSON is YAML
    return path


# ----------------------------------------------------------------------------------------------
# Bundled scenes


def test_bundled_scenes_are_there():
    assert len(SCENES) >= 17
    assert any("base" in file_data(path) for path in SCENES), "no bundled scene uses base: any more"


@pytest.mark.parametrize("path", SCENES, ids=lambda path: path.stem)
def test_every_bundled_scene_file_validates(validator, path):
    assert errors(validator, file_data(path)) == []


@pytest.mark.parametrize("path", SCENES, ids=lambda path: path.stem)
def test_every_bundled_scene_names_the_schema_on_its_first_line(path):
    first_line = path.read_text(encoding="utf-8").splitlines()[0]
    assert first_line == MODELINE, f"{path.name} starts with {first_line!r}"
    target = (path.parent / first_line.split("$schema=", 1)[1]).resolve()
    assert target == SCHEMA_FILE.resolve() and target.is_file()


# ----------------------------------------------------------------------------------------------
# The committed and installed file


def test_committed_schema_file_is_what_the_command_prints():
    from mech_regulator.cli.main import main

    assert SCHEMA_FILE.read_text(encoding="utf-8") == schema_json(), (
        "config/schema/scene.schema.json is out of date: regenerate it with "
        "'mech-regulator schema > config/schema/scene.schema.json'"
    )
    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        assert main(["schema"]) == 0
    assert buffer.getvalue() == schema_json()


def test_setup_installs_the_schema_under_share(monkeypatch):
    from setuptools._distutils.core import run_setup

    monkeypatch.chdir(ROOT)
    data_files = dict(run_setup(str(ROOT / "setup.py"), stop_after="init").data_files)
    assert data_files["share/mech_regulator/config/schema"] == ["config/schema/scene.schema.json"]


def test_schema_is_generated_from_the_models(schema):
    from mech_regulator.scene.machine_keys import Machine
    from mech_regulator.scene.schema import Scene

    definitions = schema["$defs"]
    assert set(schema["properties"]) == set(Scene.model_fields) | {"base"}
    assert set(definitions["Machine"]["properties"]) == set(Machine.model_fields)
    assert set(definitions["PartialMachine"]["properties"]) == set(Machine.model_fields)
    assert definitions["PartialMachine"].get("required", []) == []
    assert all(definition["additionalProperties"] is False for definition in definitions.values())


# ----------------------------------------------------------------------------------------------
# Misspelt keys and wrong types: rejected by the schema and by load_scene


def lathe() -> dict:
    return file_data(ROOT / "config" / "scenes" / "lathe.yaml")


def engine_direct() -> dict:
    return file_data(ROOT / "config" / "scenes" / "engine_direct.yaml")


def changed(data: dict, dotted: str, value) -> dict:
    data = copy.deepcopy(data)
    *parents, last = dotted.split(".")
    node = data
    for key in parents:
        node = node.setdefault(key, {})
    node[last] = value
    return data


def renamed(data: dict, dotted: str, new_name: str) -> dict:
    data = copy.deepcopy(data)
    *parents, last = dotted.split(".")
    node = data
    for key in parents:
        node = node[key]
    node[new_name] = node.pop(last)
    return data


MISSPELT = [
    ("top level", lambda: renamed(lathe(), "scenario", "scenaro"), "scenaro"),
    ("machine.inertai", lambda: renamed(lathe(), "machine.inertia", "inertai"), "inertai"),
    ("nested section", lambda: renamed(lathe(), "machine.flywheel.ratio", "ration"), "ration"),
    ("governor.dampin", lambda: renamed(engine_direct(), "governor.damping", "dampin"), "dampin"),
    ("partial top level", lambda: {"base": "engine", "solvr": {"method": "RK45"}}, "solvr"),
    ("partial machine.inertai", lambda: {"base": "engine", "machine": {"inertai": 1}}, "inertai"),
    ("partial governor.dampin", lambda: {"base": "engine_direct", "governor": {"dampin": 100.0}}, "dampin"),
    ("partial mechanism", lambda: {"base": "engine", "machine": {"mechanism": {"rodd": 0.2}}}, "rodd"),
]

WRONG_TYPES = [
    ("text for a number", lambda: changed(lathe(), "machine.inertia", "heavy")),
    ("true for a number", lambda: changed(lathe(), "machine.inertia", True)),
    ("negative inertia", lambda: changed(lathe(), "machine.inertia", -1.0)),
    ("unknown method", lambda: changed(lathe(), "solver.method", "Euler")),
    ("unknown load type", lambda: changed(lathe(), "machine.loads", [{"type": "drag", "coefficient": 1.0}])),
    ("section for a list", lambda: changed(lathe(), "machine.loads", {"type": "fan", "coefficient": 1.0})),
    ("partial: text for a number", lambda: {"base": "engine", "machine": {"inertia": "heavy"}}),
    ("partial: unknown governor type", lambda: {"base": "engine_direct", "governor": {"type": "hydraulic"}}),
    ("partial: incomplete list item", lambda: {"base": "engine", "machine": {"loads": [{"type": "fan"}]}}),
    ("partial: removing a required key", lambda: {"base": "engine", "scenario": {"duration": None}}),
    ("partial: base not a name", lambda: {"base": 3, "scenario": {"duration": 1.0}}),
    ("complete scene without machine", lambda: {"scenario": {"duration": 1.0}}),
]


@pytest.mark.parametrize("data, key", [(make, key) for _, make, key in MISSPELT], ids=[case for case, _, _ in MISSPELT])
def test_misspelt_key_is_rejected_by_schema_and_loader(validator, tmp_path, data, key):
    data = data()
    found = errors(validator, data)
    assert found, f"the schema accepts the misspelt key '{key}'"
    assert any(key in message or "not valid under any" in message for message in found), found
    with pytest.raises(SceneError, match=rf"{key}: unknown key"):
        load_scene(str(write_scene(tmp_path, data)))


@pytest.mark.parametrize("data", [make for _, make in WRONG_TYPES], ids=[case for case, _ in WRONG_TYPES])
def test_wrong_value_is_rejected_by_schema_and_loader(validator, tmp_path, data):
    data = data()
    assert errors(validator, data), "the schema accepts it"
    with pytest.raises(SceneError):
        load_scene(str(write_scene(tmp_path, data)))


def test_the_misspelt_key_is_named_where_it_is(validator):
    assert "machine: Additional properties are not allowed ('inertai' was unexpected)" in errors(
        validator, renamed(lathe(), "machine.inertia", "inertai")
    )  # and machine.inertia is missing
    assert errors(validator, {"base": "engine", "machine": {"inertai": 1}}) == [
        "machine: Additional properties are not allowed ('inertai' was unexpected)"
    ]


# ----------------------------------------------------------------------------------------------
# Partial scenes (base:)


PARTIAL = [
    ("one nested key", {"base": "engine_indirect_none", "governor": {"feedback": {"type": "rigid", "gain": 0.1}}}),
    (
        "several sections",
        {
            "base": "engine",
            "name": "mine",
            "machine": {"flywheel": {"inertia": 0.2}},
            "scenario": {"duration": 5.0},
            "solver": {"rtol": 1e-6},
        },
    ),
    ("a key removed", {"base": "engine_direct", "governor": {"damping": None}, "scenario": {"load_events": None}}),
    ("a section removed", {"base": "engine_direct", "governor": None, "scenario": {"initial": {"sleeve": None}}}),
    (
        "a type changed",
        {
            "base": "engine_direct",
            "governor": {"type": "indirect", "pilot_neutral": 0.05, "servo": {"gain": 100.0}, "valve": None},
        },
    ),
    ("a list replaced", {"base": "engine", "machine": {"loads": [{"type": "viscous", "coefficient": 0.01}]}}),
    ("only the base", {"base": "lathe"}),
]


@pytest.mark.parametrize("data", [data for _, data in PARTIAL], ids=[case for case, _ in PARTIAL])
def test_scene_with_base_and_a_partial_override_validates(validator, tmp_path, data):
    assert errors(validator, data) == []
    load_scene(str(write_scene(tmp_path, data)))  # and it is a valid scene once merged


def test_partial_scene_with_a_base_file_next_to_it(validator, tmp_path):
    write_scene(tmp_path, file_data(ROOT / "config" / "scenes" / "lathe.yaml"), name="my_lathe")
    derived = {"base": "my_lathe.yaml", "machine": {"flywheel": {"inertia": 0.5}}}
    assert errors(validator, derived) == []
    assert load_scene(str(write_scene(tmp_path, derived))).machine.flywheel.inertia == 0.5


def test_base_makes_keys_optional_only_for_a_partial_scene(validator):
    partial = {"base": "engine", "machine": {"flywheel": {"inertia": 0.2}}}
    assert errors(validator, partial) == []
    complete = {key: value for key, value in partial.items() if key != "base"}
    assert errors(validator, complete)  # the same keys without base: machine.inertia and scenario missing
