"""Reference of the scene format generated from the schema: the JSON Schema and the key tables of
docs/scenes.md (a test keeps the document in step with the schema)."""

from __future__ import annotations

import inspect
import json
import types
import typing

import pydantic

from mech_regulator.scene.schema import Scene


def schema_json() -> str:
    """The JSON Schema (draft 2020-12) of scene files, for editors' completion and checking."""
    schema = Scene.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "mech_regulator scene"
    return json.dumps(schema, indent=2) + "\n"


def schema_markdown() -> str:
    """One markdown table per section of the format: key, type, default, meaning and unit."""
    sections: list[str] = []
    seen: set[type] = set()

    def visit(model: type[pydantic.BaseModel], path: str) -> None:
        if model in seen:
            return
        seen.add(model)
        rows = ["| key | type | default | meaning [unit] |", "| --- | --- | --- | --- |"]
        nested: list[tuple[type, str]] = []
        for name, field in model.model_fields.items():
            default = "required" if field.is_required() else _format_default(field)
            rows.append(f"| `{name}` | {_type_name(field.annotation)} | {default} | "
                        f"{(field.description or '').replace('|', chr(92) + '|')} |")
            for child in _models_in(field.annotation):
                suffix = "[]" if typing.get_origin(_strip(field.annotation)) is list else ""
                nested.append((child, f"{path}.{name}{suffix}" if path else name + suffix))
        title = f"`{path}`" if path else "top level"
        kind = model.model_fields.get("type")
        if kind is not None:
            title += f" — type `{'` / `'.join(typing.get_args(kind.annotation))}`"
        doc = " ".join(inspect.cleandoc(model.__doc__ or "").split("\n\n")[0].split())
        header = f"### {title}\n\n" + (f"{doc}\n\n" if doc and model.__module__.endswith("schema") else "")
        sections.append(header + "\n".join(rows) + "\n")
        for child, child_path in nested:
            visit(child, child_path)

    visit(Scene, "")
    return "\n".join(sections)


def _strip(annotation):
    while typing.get_origin(annotation) in (typing.Annotated,):
        annotation = typing.get_args(annotation)[0]
    return annotation


def _models_in(annotation) -> list[type[pydantic.BaseModel]]:
    """The pydantic models an annotation can hold (through Optional, lists, unions)."""
    if isinstance(annotation, type) and issubclass(annotation, pydantic.BaseModel):
        return [annotation]
    found = []
    for argument in typing.get_args(annotation):
        for model in _models_in(argument):
            if model not in found:
                found.append(model)
    return found


def _type_name(annotation) -> str:
    annotation = _strip(annotation)
    origin = typing.get_origin(annotation)
    if origin is typing.Literal:
        return " / ".join(f"`{value}`" for value in typing.get_args(annotation))
    if origin is list:
        return f"list of {_type_name(typing.get_args(annotation)[0])}"
    if origin in (typing.Union, types.UnionType):
        members = [a for a in typing.get_args(annotation) if a is not type(None)]
        optional = " (optional)" if type(None) in typing.get_args(annotation) else ""
        if len(members) > 1 and all(_models_in(_strip(m)) == [_strip(m)] for m in members):
            return "section, chosen by `type`" + optional
        return " or ".join(_type_name(m) for m in members) + optional
    if isinstance(annotation, type) and issubclass(annotation, pydantic.BaseModel):
        return "section"
    return {float: "number", str: "text", int: "integer", bool: "true/false"}.get(annotation, str(annotation))


def _format_default(field) -> str:
    if field.default_factory is not None:
        value = field.default_factory()
        return "[]" if value == [] else "(section defaults)"
    return "none" if field.default is None else f"`{field.default}`"
