"""Reading scene files: YAML, `--set` overrides, bundled scenes, and clear validation messages.

Every mistake in a scene becomes a SceneError whose message names the key (as a dotted path), the
value given and what is expected, with the closest valid key for a misspelt one.
"""

from __future__ import annotations

import difflib
import re
import sys
import types
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pydantic
import yaml

from mech_regulator.errors import SceneError
from mech_regulator.scene.limits import (
    MAX_BASE_CHAIN,
    MAX_SCENE_BYTES,
    MAX_YAML_CHARACTERS,
    MAX_YAML_DEPTH,
    MAX_YAML_NODES,
    number_refusals,
    run_refusals,
    shown,
)
from mech_regulator.scene.schema import Scene

SCENE_KEYS = frozenset(Scene.model_fields) | {"base"}  # the top-level keys a scene file may have


class _Refused(yaml.YAMLError):
    """A YAML document beyond a limit of limits.py (problem: which, and the limit; problem_mark: where)."""

    def __init__(self, problem: str, problem_mark):
        super().__init__(problem)
        self.problem, self.problem_mark = problem, problem_mark


class _Duplicate(yaml.YAMLError):
    """A key given twice in one mapping of a YAML document (problem: which key, at which lines)."""

    def __init__(self, problem: str):
        super().__init__(problem)
        self.problem = problem


class _Loader(yaml.SafeLoader):
    """SafeLoader that also reads YAML 1.2 floats such as 1e-3 (PyYAML alone reads them as strings), refuses a key
    given twice in one mapping (PyYAML alone keeps the last value silently; a merge `<<:` may still bring keys that
    the mapping then sets itself), and refuses a
    document nested deeper than MAX_YAML_DEPTH or larger, with its aliases expanded, than MAX_YAML_NODES values or
    MAX_YAML_CHARACTERS characters of scalars (an alias bomb, "billion laughs"): each node's expanded size (values,
    characters, depth; an alias counts as the whole node it repeats) is worked out from its children's as it is
    composed, so a bomb is refused at the first node beyond the limit, before anything is expanded."""

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            first: dict[Any, Any] = {}  # key -> the mark where it was first given
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    earlier = first.setdefault(key, key_node.start_mark)
                except TypeError:  # an unhashable key: SafeLoader's own message follows
                    continue
                if earlier is not key_node.start_mark:
                    raise _Duplicate(
                        f"the key {shown(key)} is given twice in one mapping, at {_place(earlier)} and "
                        f"at {_place(key_node.start_mark)}; expected it once (YAML would keep only the "
                        "last)"
                    )
        return super().construct_mapping(node, deep)

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0
        self._sizes: dict[int, tuple[int, int, int]] = {}  # id(node) -> (values, characters, depth) expanded

    def compose_node(self, parent, index):
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent):
            node = self.anchors.get(event.anchor)
            if node is not None and id(node) not in self._sizes:
                raise _Refused(
                    f"the alias *{event.anchor[:40]} repeats a node that contains it: a recursive "
                    "structure, which a scene never needs",
                    event.start_mark,
                )
            return super().compose_node(parent, index)
        if self._depth >= MAX_YAML_DEPTH:
            raise _Refused(
                f"mappings and lists nested deeper than {MAX_YAML_DEPTH} levels (the limit; a scene needs "
                "fewer than 10)",
                event.start_mark,
            )
        self._depth += 1
        try:
            node = super().compose_node(parent, index)
        finally:
            self._depth -= 1
        if isinstance(node, yaml.ScalarNode):
            size = (1, len(node.value), 1)
        else:
            children = (
                [part for pair in node.value for part in pair] if isinstance(node, yaml.MappingNode) else node.value
            )
            sizes = [self._sizes[id(child)] for child in children]
            size = (1 + sum(s[0] for s in sizes), sum(s[1] for s in sizes), 1 + max((s[2] for s in sizes), default=0))
        self._sizes[id(node)] = size
        values, characters, depth = size
        if values > MAX_YAML_NODES:
            raise _Refused(
                f"with its aliases expanded the document holds more than {MAX_YAML_NODES} values (the "
                f"limit; this node alone {values:.3g}): an alias bomb?",
                event.start_mark,
            )
        if characters > MAX_YAML_CHARACTERS:
            raise _Refused(
                f"with its aliases expanded the document's values hold more than {MAX_YAML_CHARACTERS} "
                f"characters (the limit; this node alone {characters:.3g})",
                event.start_mark,
            )
        if depth > MAX_YAML_DEPTH:
            raise _Refused(
                f"with its aliases expanded, mappings and lists nest deeper than {MAX_YAML_DEPTH} levels (the limit)",
                event.start_mark,
            )
        return node


def _place(mark) -> str:
    """'line L, column C' of a YAML mark (both from 1)."""
    return f"line {mark.line + 1}, column {mark.column + 1}"


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                   |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
                   |[-+]?\.[0-9_]+(?:[eE][-+]?[0-9]+)?
                   |[-+]?\.(?:inf|Inf|INF)
                   |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


def parse_yaml(text: str, source: str) -> Any:
    """Parse YAML text; a syntax error becomes a SceneError naming the line and column."""
    try:
        return yaml.load(text, Loader=_Loader)
    except _Refused as error:
        mark = error.problem_mark
        raise SceneError(
            f"{source}: refused at line {mark.line + 1}, column {mark.column + 1}: {error.problem}"
        ) from None
    except _Duplicate as error:
        raise SceneError(f"{source}: {error.problem}") from None
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(error, "problem", None) or str(error)
        raise SceneError(f"{source}: not valid YAML{where}: {problem}") from None


# ---------------------------------------------------------------------------------------------
# Bundled configuration


def config_dir() -> Path:
    """The bundled `config/` folder: next to the package in a source tree or editable install, else
    `share/mech_regulator/config` under an install prefix (pip, colcon), else from ament_index."""
    here = Path(__file__).resolve()
    candidates = [here.parents[2] / "config"]
    # The install prefix this very package sits in comes before the interpreter's own prefix.
    candidates += [parent / "share" / "mech_regulator" / "config" for parent in (*here.parents, Path(sys.prefix))]
    for candidate in candidates:
        if (candidate / "scenes").is_dir():
            return candidate
    try:
        from ament_index_python.packages import get_package_share_directory

        candidates.append(Path(get_package_share_directory("mech_regulator")) / "config")
    except (ImportError, LookupError, OSError):  # no ROS index (plain pip), or AMENT_PREFIX_PATH unset
        pass
    if (candidates[-1] / "scenes").is_dir():
        return candidates[-1]
    raise SceneError("the bundled config/ folder was not found; looked in: " + ", ".join(map(str, candidates)))


def bundled_scenes() -> dict[str, Path]:
    """Bundled scene names (file stems) and their paths."""
    return {path.stem: path for path in sorted((config_dir() / "scenes").glob("*.yaml"))}


def resolve_scene_path(name_or_path: str) -> Path:
    """A scene file given as a path, or as the name of a bundled scene (with or without .yaml)."""
    path = Path(name_or_path)
    if path.is_file():
        return path
    bundled = bundled_scenes()
    stem = path.name[:-5] if path.name.endswith(".yaml") else path.name
    if stem in bundled and len(path.parts) == 1:
        return bundled[stem]
    close = difflib.get_close_matches(stem, bundled, n=1)
    hint = f"; did you mean the bundled scene '{close[0]}'?" if close else ""
    raise SceneError(f"scene '{name_or_path}': no such file, nor a bundled scene (bundled: {', '.join(bundled)}){hint}")


# ---------------------------------------------------------------------------------------------
# Overrides


def apply_override(data: dict, assignment: str, option: str = "--set") -> None:
    """Apply one `dotted.key=value` override in place; the value is read as YAML (numbers, lists...).

    List entries are addressed by index: `machine.loads.0.coefficient=0.02`. option: the command-line option
    the messages name (--set, or --grid for a sweep).
    """
    if "=" not in assignment:
        raise SceneError(f"{option} '{assignment}': expected dotted.key=value, e.g. machine.inertia=0.1")
    dotted, raw = assignment.split("=", 1)
    keys = dotted.strip().split(".")
    if not all(keys):
        raise SceneError(f"{option} '{assignment}': the key '{dotted}' has an empty part")
    value = parse_yaml(raw, f"{option} {dotted}")
    node: Any = data
    for depth, key in enumerate(keys[:-1]):
        node = _child(node, key, keys[: depth + 1], assignment, create=True, option=option)
    last = keys[-1]
    if isinstance(node, list):
        node[_index(node, last, keys, assignment, option)] = value
    elif isinstance(node, dict):
        node[last] = value
    else:
        raise SceneError(f"{option} '{assignment}': '{'.'.join(keys[:-1])}' holds {shown(node)}, not a section")


def _index(node: list, key: str, path: list[str], assignment: str, option: str) -> int:
    if not key.isdigit() or int(key) >= len(node):
        raise SceneError(
            f"{option} '{assignment}': '{'.'.join(path)}' must index the list (0 to {len(node) - 1}), got '{key}'"
        )
    return int(key)


def _child(node: Any, key: str, path: list[str], assignment: str, create: bool, option: str) -> Any:
    if isinstance(node, list):
        return node[_index(node, key, path, assignment, option)]
    if isinstance(node, dict):
        if node.get(key) is None and create:
            node[key] = {}
        return node[key]
    raise SceneError(f"{option} '{assignment}': '{'.'.join(path[:-1])}' holds {shown(node)}, not a section")


# ---------------------------------------------------------------------------------------------
# Validation and messages


def load_scene(name_or_path: str, overrides: Sequence[str] = ()) -> Scene:
    """Read, override and validate a scene; any problem raises SceneError with a clear message."""
    data, path = overridden_scene_data(name_or_path, overrides)
    return validate_scene(data, str(path))


def overridden_scene_data(name_or_path: str, overrides: Sequence[str] = ()) -> tuple[dict, Path]:
    """The mapping of a scene (a file or a bundled name) with the --set overrides applied and its name defaulting
    to the file's stem, not yet validated, and the file it came from."""
    path = resolve_scene_path(name_or_path)
    data = read_scene_data(path)
    for assignment in overrides:
        apply_override(data, assignment)
    data.setdefault("name", path.stem)
    return data, path


def read_scene_data(path: Path, derived_from: tuple[Path, ...] = (), referrer: str = "") -> dict:
    """The mapping of a scene file; a file with `base: SCENE` starts from that scene (a bundled name, or a .yaml
    file inside the file's own folder, see base_path) and changes it: mappings merge key by key, null removes a key,
    anything else is replaced. referrer: for a base, "<the file naming it>: base = '<base>'", which its messages
    start with; a base is taken only for a scene (its top-level keys a scene's) and, not being one, its content is
    never shown."""
    text = _scene_text(path, referrer)
    if referrer:
        try:
            data = parse_yaml(text, str(path))
        except SceneError:
            raise SceneError(
                f"{referrer}: {path} is not a valid YAML scene file; check it with `mech-regulator describe {path}`"
            ) from None
    else:
        data = parse_yaml(text, str(path))
    if data is None:
        data = {}
    if not isinstance(data, dict):
        what = f"{referrer}: {path}" if referrer else str(path)
        raise SceneError(
            f"{what}: expected a mapping of sections (machine, scenario, solver), got {type(data).__name__}"
        )
    if referrer and not set(data) <= SCENE_KEYS:
        raise SceneError(
            f"{referrer}: {path} is not a scene file: its top level has keys that a scene does not have "
            f"(a scene's: {', '.join(sorted(SCENE_KEYS))})"
        )
    base = data.pop("base", None)
    if base is None:
        return data
    if not isinstance(base, str):
        raise SceneError(
            f"{path}: base = {shown(base)}; expected the name of a bundled scene or a path to a scene file"
        )
    if len(derived_from) >= MAX_BASE_CHAIN:
        raise SceneError(
            f"{path}: base = '{base}': a chain of more than {MAX_BASE_CHAIN} bases (the "
            "limit); expected a short chain of scenes that ends in a scene without base"
        )
    base_file = base_path(path, base)
    if base_file.resolve() in derived_from + (path.resolve(),):
        raise SceneError(
            f"{path}: base = '{base}' closes a loop of bases; expected a chain of scenes that ends "
            "in a scene without base"
        )
    merged = read_scene_data(base_file, derived_from + (path.resolve(),), f"{path}: base = '{base}'")
    merged.pop("name", None)
    merged.pop("description", None)
    return _merge(merged, data)


def _scene_text(path: Path, referrer: str = "") -> str:
    """The text of a scene file, at most MAX_SCENE_BYTES long (read no further, whatever the file is)."""
    what = f"{referrer}: {path}" if referrer else f"scene '{path}'"
    try:
        with open(path, "rb") as file:
            raw = file.read(MAX_SCENE_BYTES + 1)
    except OSError as error:
        raise SceneError(f"{what}: cannot be read: {error.strerror}") from None
    if len(raw) > MAX_SCENE_BYTES:
        raise SceneError(
            f"{what}: larger than {MAX_SCENE_BYTES} bytes, the limit for a scene file (a scene is a few "
            "kB; long tables belong in fewer points)"
        )
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as error:
        raise SceneError(
            f"{what}: not UTF-8 text (byte {error.start}: {error.reason}); save the file as UTF-8"
        ) from None


def base_path(path: Path, base: str) -> Path:
    """The file a scene at `path` names with `base: BASE`: a .yaml file inside the scene's own folder (a relative
    path, subfolders allowed, no '..', not through a link that leads out of the folder), else a bundled scene's
    name. Anything else is refused with a SceneError that names the rule: a scene shared with you cannot make this
    program read a file elsewhere."""
    bundled = bundled_scenes()
    folder = path.parent
    relative = Path(base)
    expected = (
        f"expected the name of a bundled scene ({', '.join(bundled)}) or the relative path of a .yaml scene "
        f"file inside this scene's folder ({folder})"
    )
    if relative.is_absolute():
        raise SceneError(f"{path}: base = '{base}': not a relative path; {expected}")
    if ".." in relative.parts:
        raise SceneError(f"{path}: base = '{base}': '..' leaves this scene's folder; {expected}")
    candidate = folder / relative
    if candidate.suffix == ".yaml" and candidate.is_file():
        if not candidate.resolve().is_relative_to(folder.resolve()):
            raise SceneError(f"{path}: base = '{base}': a link that leads outside this scene's folder; {expected}")
        return candidate
    if base.removesuffix(".yaml") in bundled and len(relative.parts) == 1:
        return bundled[base.removesuffix(".yaml")]
    if relative.suffix != ".yaml":
        raise SceneError(
            f"{path}: base = '{base}': no such file: not a bundled scene's name, and a base file is a "
            f".yaml file; {expected}"
        )
    raise SceneError(
        f"{path}: base = '{base}': no such file next to this scene ({candidate}), nor a bundled "
        f"scene (bundled: {', '.join(bundled)})"
    )


def _merge(base: dict, changes: dict) -> dict:
    """base changed by changes: nested mappings merge key by key, null removes a key, other values replace."""
    merged = dict(base)
    for key, value in changes.items():
        if value is None:
            merged.pop(key, None)
        elif isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = _merge(merged[key], value)
        else:
            merged[key] = value
    return merged


def validate_scene(data: dict, source: str = "scene") -> Scene:
    """Validate a scene mapping; SceneError lists every problem, one per line (at most MAX_PROBLEMS_SHOWN). Numbers
    beyond the limits of limits.py are refused first (before the schema's checks multiply them), then settings that
    would make the run impossible (limits.run_refusals)."""
    problems = number_refusals(data)
    if problems:
        raise SceneError(problems_message(source, problems))
    try:
        scene = Scene.model_validate(data)
    except pydantic.ValidationError as error:
        lines = [describe_error(item, data) for item in error.errors(include_url=False)]
        raise SceneError(problems_message(source, list(dict.fromkeys(lines)))) from None
    except (ArithmeticError, RecursionError) as error:  # a check of the schema computing with extreme numbers
        raise SceneError(
            f"{source}: its numbers cannot be computed with ({type(error).__name__}: {error}); expected "
            "values of a real machine"
        ) from None
    problems = run_refusals(scene)
    if problems:
        raise SceneError(problems_message(source, problems))
    return scene


MAX_PROBLEMS_SHOWN = 40  # lines of a validation message; the rest are counted


def problems_message(source: str, lines: list[str]) -> str:
    """The message listing a scene's problems, one per line (also the mechanisms' checks', mechanisms/checks.py)."""
    shown_lines = lines[:MAX_PROBLEMS_SHOWN]
    if len(lines) > MAX_PROBLEMS_SHOWN:
        shown_lines.append(f"... and {len(lines) - MAX_PROBLEMS_SHOWN} more")
    return f"{source}: {len(lines)} problem{'s' if len(lines) > 1 else ''}:\n  " + "\n  ".join(shown_lines)


def describe_error(item: Mapping[str, Any], data: Any) -> str:
    """One line for one pydantic error: dotted key, the value given, and what is expected."""
    loc = _data_path(item["loc"], data)
    key = ".".join(str(part) for part in loc) or "(top level)"
    kind, message = item["type"], item["msg"]
    if kind == "extra_forbidden":
        valid = _valid_keys(loc[:-1], data)
        close = difflib.get_close_matches(str(loc[-1]), valid, n=1, cutoff=0.5)
        hint = f"; did you mean '{close[0]}'?" if close else ""
        return f"{key}: unknown key{hint} (valid keys here: {', '.join(valid)})"
    if kind == "missing":
        return f"{key}: missing; {_field_description(loc, data) or 'this key is required'}"
    if kind in ("union_tag_invalid", "union_tag_not_found"):
        expected = ", ".join(f"'{tag}'" for tag in _type_tags(loc, data))
        if kind == "union_tag_not_found":
            return f"{key}: missing 'type'; expected one of {expected}"
        return f"{key}.type = {shown(item['input'].get('type'))}: unknown type; expected one of {expected}"
    if message.startswith("Value error, "):
        return f"{key}: {message[len('Value error, ') :]}"
    if kind == "finite_number":
        message = "expected a finite number (not NaN or infinity)"
    description = _field_description(loc, data)
    unit = f" ({description})" if description else ""
    return f"{key} = {shown(item['input'])}: {message[0].lower() + message[1:]}{unit}"


def _data_path(loc: tuple, data: Any) -> list:
    """Drop the union tags pydantic inserts into locations (machine.loads.0.viscous.coefficient
    -> machine.loads.0.coefficient), keeping the path as the user wrote it."""
    path, node, tag_skipped = [], data, False
    for index, part in enumerate(loc):
        # a tag: the node's own type, or the default type of a node that gives none (a valve)
        default_tag = (
            isinstance(node, dict)
            and "type" not in node
            and isinstance(part, str)
            and part not in node
            and index < len(loc) - 1
        )
        if isinstance(node, dict) and (node.get("type") == part or default_tag) and not tag_skipped:
            tag_skipped = True
            continue
        tag_skipped = False
        if isinstance(node, dict) and part in node:
            node = node[part]
        elif isinstance(node, list) and isinstance(part, int) and part < len(node):
            node = node[part]
        else:
            node = None
        path.append(part)
    return path


def _annotation_at(loc: list, data: Any) -> Any:
    """The type annotation that validates the value at loc (following list items and type tags)."""
    annotation: Any = Scene
    node = data
    for part in loc:
        annotation = _resolve(annotation, node)
        if isinstance(part, int):
            if typing.get_origin(annotation) is not list:
                return None
            annotation = typing.get_args(annotation)[0]
            node = node[part] if isinstance(node, list) and part < len(node) else None
        else:
            if not (isinstance(annotation, type) and issubclass(annotation, pydantic.BaseModel)):
                return None
            field = annotation.model_fields.get(part)
            if field is None:
                return None
            annotation = field.annotation
            node = node.get(part) if isinstance(node, dict) else None
    return annotation


def _model_at(loc: list, data: Any) -> type[pydantic.BaseModel] | None:
    """The pydantic model class that validates the section at loc."""
    node: Any = data
    for part in loc:
        node = (
            node.get(part)
            if isinstance(node, dict)
            else (node[part] if isinstance(node, list) and isinstance(part, int) and part < len(node) else None)
        )
    annotation = _resolve(_annotation_at(loc, data), node)
    return annotation if isinstance(annotation, type) and issubclass(annotation, pydantic.BaseModel) else None


def _type_tags(loc: list, data: Any) -> list[str]:
    """The values 'type' may take for the section at loc."""
    tags: list[str] = []
    annotation = _annotation_at(loc, data)
    pending = [annotation]
    while pending:
        current = pending.pop()
        if isinstance(current, type) and issubclass(current, pydantic.BaseModel):
            literal = current.model_fields.get("type")
            tags += list(typing.get_args(literal.annotation)) if literal is not None else []
        else:
            pending += list(reversed(typing.get_args(current)))
    return tags


def _resolve(annotation: Any, node: Any) -> Any:
    """Strip Optional and Annotated from an annotation; pick a union member by the node's 'type' tag."""
    origin = typing.get_origin(annotation)
    if origin is typing.Annotated:
        return _resolve(typing.get_args(annotation)[0], node)
    if origin in (typing.Union, types.UnionType):
        members = [m for m in typing.get_args(annotation) if m is not type(None)]
        if len(members) == 1:
            return _resolve(members[0], node)
        tag = node.get("type") if isinstance(node, dict) else None
        for member in members:
            model = _resolve(member, None) if typing.get_origin(member) is typing.Annotated else member
            literal = getattr(model, "model_fields", {}).get("type")
            if literal is None:
                continue
            if tag in typing.get_args(literal.annotation) or (tag is None and not literal.is_required()):
                return model
        return None
    return annotation


def _valid_keys(loc: list, data: Any) -> list[str]:
    model = _model_at(loc, data)
    return list(model.model_fields) if model is not None else []


def _field_description(loc: list, data: Any) -> str:
    if not loc or not isinstance(loc[-1], str):
        return ""
    model = _model_at(loc[:-1], data)
    field = model.model_fields.get(loc[-1]) if model is not None else None
    return (field.description or "") if field is not None else ""


def key_description(key: str, data: dict) -> str:
    """The schema's description of a dotted scene key (list items by index, as in --set) for the scene mapping
    data, with its unit in brackets at the end; '' for a key the schema does not know."""
    return _field_description([int(part) if part.isdigit() else part for part in key.split(".")], data)
