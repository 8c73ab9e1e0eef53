"""The documentation of the scene format stays in step with the schema."""

import re
from pathlib import Path

from mech_regulator.scene.reference import schema_markdown
from mech_regulator.scene.schema import Scene

DOCS = Path(__file__).resolve().parents[1] / "docs" / "scenes.md"


def test_generated_reference_matches_schema():
    text = DOCS.read_text(encoding="utf-8")
    generated = re.search(r"<!-- BEGIN GENERATED -->\n(.*)<!-- END GENERATED -->", text, re.S)
    assert generated, "docs/scenes.md lost its generated-reference markers"
    assert generated.group(1) == schema_markdown(), (
        "docs/scenes.md is out of date: regenerate the part between the markers with "
        "'mech-regulator schema --format markdown'")


def test_every_key_has_a_description_with_its_meaning():
    def walk(model, path):
        for name, field in model.model_fields.items():
            if name != "type":
                assert field.description, f"{path}{name} has no description"
            for child in _models(field.annotation):
                walk(child, f"{path}{name}.")

    walk(Scene, "")


def test_every_physical_quantity_states_its_unit():
    """Numbers in the schema carry a unit in brackets, except pure ratios marked [-]."""
    missing = []

    def walk(model, path):
        for name, field in model.model_fields.items():
            if field.annotation in (float, float | None) and "[" not in (field.description or ""):
                missing.append(f"{path}{name}")
            for child in _models(field.annotation):
                walk(child, f"{path}{name}.")

    walk(Scene, "")
    assert not missing, f"no unit in the description of: {missing}"


def _models(annotation):
    import typing

    import pydantic

    if isinstance(annotation, type) and issubclass(annotation, pydantic.BaseModel):
        return [annotation]
    return [m for a in typing.get_args(annotation) for m in _models(a)]
