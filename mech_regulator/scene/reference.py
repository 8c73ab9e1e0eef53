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
    """The JSON Schema (draft 2020-12, using only what draft 7 editors understand too) of scene files, for
    editors' completion and checking; `config/schema/scene.schema.json` is this text (a test keeps it so)."""
    return json.dumps(scene_json_schema(), indent=2) + "\n"


def scene_json_schema() -> dict:
    """The JSON Schema of a scene file, generated from the pydantic models (`Scene.model_json_schema()`).

    A file without `base:` is a complete scene (the `else` branch: the models' schema). A file with `base:`
    holds only its changes to the base scene (loading.read_scene_data deep-merges them over it), so the
    `then` branch checks it against the "partial" form of every section: the same keys and types, with
    `additionalProperties: false` still (a misspelt key is an error), but no key required, `null` allowed
    for a key that may be left out (it removes the base's key), the type of a section chosen by `type` free
    (the base may give it) and null allowed for the keys of the other types (they remove the base's keys
    when the type changes). Lists are replaced whole, so list items are complete. A partial scene's merged
    result is checked when it is loaded (`load_scene`)."""
    full = Scene.model_json_schema()
    defs = full.pop("$defs")
    partial = _PartialSchemas(defs)
    required = set(full["required"])
    partial_keys = {
        key: partial.value(value, nullable=key not in required) for key, value in full["properties"].items()
    }
    descriptions = {key: _annotations(value) for key, value in full["properties"].items()}
    base = {
        "type": "string",
        "title": "Base",
        "description": "the scene this one changes (a bundled scene's name, or the relative path of a .yaml scene "
        "file inside this file's folder, no '..'); "
        "with base, every key is optional: mappings merge key by key, lists and plain values "
        "replace, and null removes a key of the base",
    }
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "mech_regulator scene",
        "description": " ".join(inspect.cleandoc(Scene.__doc__ or "").split()) + " A scene with `base:` holds only "
        "its changes to another scene.",
        "type": "object",
        "properties": {
            "name": descriptions["name"],
            "description": descriptions["description"],
            "base": base,
            **{key: value for key, value in descriptions.items() if key not in ("name", "description")},
        },
        "additionalProperties": False,
        "if": {"required": ["base"]},
        "then": {"properties": partial_keys},
        "else": {"properties": full["properties"], "required": full["required"]},
        "$defs": dict(sorted({**defs, **partial.defs}.items())),
    }


def _annotations(schema: dict) -> dict:
    """The keywords of a schema that describe rather than validate it."""
    return {key: schema[key] for key in ("title", "description") if key in schema}


class _PartialSchemas:
    """The partial form of the models' schemas (see scene_json_schema), as `Partial<Model>` definitions."""

    def __init__(self, defs: dict):
        self.full = defs
        self.defs: dict[str, dict] = {}

    def value(self, schema: dict, nullable: bool) -> dict:
        """The partial form of the value of a key; nullable: the key may be removed (it is not required)."""
        notes = _annotations(schema)
        partial = {key: item for key, item in self.partial(schema).items() if key not in notes}
        if nullable and not _accepts_null(partial):
            partial = {"anyOf": [partial, {"type": "null"}]}
        return {**partial, **notes}

    def partial(self, schema: dict) -> dict:
        """The partial form of a schema: sections (model definitions) become their partial definitions, unions
        of sections are any of their partial members; lists and plain values stay (they are replaced whole)."""
        if "$ref" in schema:
            name = self.model(schema["$ref"])
            return {**schema, "$ref": f"#/$defs/{self.define(name)}"} if name else dict(schema)
        for union in ("anyOf", "oneOf"):
            if union in schema:
                members: list[dict] = []
                for member in schema[union]:
                    member = self.partial(member)
                    members += member["anyOf"] if set(member) == {"anyOf"} else [member]
                self.remove_other_types(schema[union])
                return {"anyOf": members, **_annotations(schema)}
        return {key: item for key, item in schema.items() if key != "default"}

    def model(self, ref: str) -> str | None:
        """The name of the model definition a $ref points to, or None."""
        name = ref.removeprefix("#/$defs/")
        return name if self.full.get(name, {}).get("type") == "object" else None

    def define(self, name: str) -> str:
        partial_name = f"Partial{name}"
        if partial_name not in self.defs:
            model = self.full[name]
            required = set(model.get("required", ()))
            self.defs[partial_name] = definition = {
                key: item for key, item in model.items() if key not in ("properties", "required")
            }
            definition["description"] = (
                f"{model.get('description', name)}\n\nPartial form (a scene with base): "
                "every key optional; null removes a key of the base."
            )
            definition["properties"] = {}
            for key, item in model["properties"].items():
                definition["properties"][key] = self.value(item, nullable=key not in required)
        return partial_name

    def remove_other_types(self, members: list[dict]) -> None:
        """The members of a union of sections chosen by `type` accept null for the other members' keys: a
        scene with base that changes the type removes the keys the new type does not have."""
        names = [self.model(member.get("$ref", "")) for member in members]
        if not all(names):
            return
        for name in names:
            properties = self.defs[f"Partial{name}"]["properties"]
            for other in names:
                for key in self.full[other]["properties"]:
                    properties.setdefault(
                        key,
                        {
                            "type": "null",
                            "description": f"null removes this key of the base scene (a key of {other}, not of {name})",
                        },
                    )


def _accepts_null(schema: dict) -> bool:
    return schema.get("type") == "null" or any(_accepts_null(member) for member in schema.get("anyOf", ()))


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
            rows.append(
                f"| `{name}` | {_type_name(field.annotation)} | {default} | "
                f"{(field.description or '').replace('|', chr(92) + '|')} |"
            )
            for child in _models_in(field.annotation):
                suffix = {list: "[]", dict: ".<name>"}.get(typing.get_origin(_strip(field.annotation)), "")
                nested.append((child, f"{path}.{name}{suffix}" if path else name + suffix))
        title = f"`{path}`" if path else "top level"
        kind = model.model_fields.get("type")
        if kind is not None:
            title += f" — type `{'` / `'.join(typing.get_args(kind.annotation))}`"
        doc = " ".join(inspect.cleandoc(model.__doc__ or "").split("\n\n")[0].split())
        header = f"### {title}\n\n" + (f"{doc}\n\n" if doc and model.__module__.startswith(f"{__package__}.") else "")
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
    if origin is dict:
        return f"mapping of names to {_type_name(typing.get_args(annotation)[1])}"
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
        return "[]" if value == [] else "{}" if value == {} else "(section defaults)"
    return "none" if field.default is None else f"`{field.default}`"
