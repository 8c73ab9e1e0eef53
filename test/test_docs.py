"""The documentation stays in step with the code: the scene format's with the schema, and the code's citations of
docs/theory.md with its sections (no comment or docstring points outside the repository or to an issue number)."""

import ast
import io
import re
import tokenize
from pathlib import Path

import pytest

from mech_regulator.scene.reference import schema_markdown
from mech_regulator.scene.schema import Scene

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs" / "scenes.md"
THEORY = ROOT / "docs" / "theory.md"
CODE_FOLDERS = ("mech_regulator", "test")

# What a comment or docstring must not name: the physics digest and the source folder outside the repository, and
# issue numbers (the code says what the change was, or cites the docs).
OUTSIDE = re.compile(r"physics\.md|\.\./shared|/work/shared|\bissues?\s*#?\d+", re.IGNORECASE)
SECTION_HEADING = re.compile(r"^#{2,6} (\d+(?:\.\d+)*)\.? ", re.MULTILINE)
SECTION_CITATION = re.compile(r"§(\d+(?:\.\d+)*)")
ANCHOR_CITATION = re.compile(r"theory\.md#([\w-]+)")


def test_generated_reference_matches_schema():
    text = DOCS.read_text(encoding="utf-8")
    generated = re.search(r"<!-- BEGIN GENERATED -->\n(.*)<!-- END GENERATED -->", text, re.S)
    assert generated, "docs/scenes.md lost its generated-reference markers"
    assert generated.group(1) == schema_markdown(), (
        "docs/scenes.md is out of date: regenerate the part between the markers with "
        "'mech-regulator schema --format markdown'"
    )


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


# ----------------------------------------------------------------------------------------------
# docs/theory.md and the code's citations of it


def comments_and_docstrings(source: str) -> list[tuple[int, str]]:
    """(line, text) of every comment and every module, class and function docstring of a Python source."""
    found = [
        (token.start[0], token.string)
        for token in tokenize.generate_tokens(io.StringIO(source).readline)
        if token.type == tokenize.COMMENT
    ]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if (
                isinstance(first, ast.Expr)
                and isinstance(first.value, ast.Constant)
                and isinstance(first.value.value, str)
            ):
                found.append((first.lineno, first.value.value))
    return found


def outside_references(source: str) -> list[tuple[int, str]]:
    """(line, what) of each reference outside the repository or to an issue number in the comments and docstrings."""
    return [
        (line, match.group(0)) for line, text in comments_and_docstrings(source) for match in OUTSIDE.finditer(text)
    ]


def code_files() -> list[Path]:
    return sorted(path for folder in CODE_FOLDERS for path in (ROOT / folder).rglob("*.py"))


def theory_sections() -> set[str]:
    return set(SECTION_HEADING.findall(THEORY.read_text(encoding="utf-8")))


def theory_anchors() -> set[str]:
    """The markdown anchors of docs/theory.md's headings, as GitHub makes them."""
    headings = re.findall(r"^#+ (.+)$", THEORY.read_text(encoding="utf-8"), re.MULTILINE)
    return {re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-") for heading in headings}


def test_the_scan_finds_what_it_looks_for():
    source = (
        '"""Module (see ../shared/physics.md section 2)."""\n'
        "x = 'physics.md in a string is no comment'\n"
        'def f():\n    """Fixed in Issue 19."""\n    return 1  # issue #7\n'
    )
    assert outside_references(source) == [(5, "issue #7"), (1, "../shared"), (1, "physics.md"), (4, "Issue 19")]


def test_no_comment_or_docstring_points_outside_the_repository():
    found = [
        f"{path.relative_to(ROOT)}:{line}: {what}"
        for path in code_files()
        for line, what in outside_references(path.read_text(encoding="utf-8"))
    ]
    assert not found, "cite docs/theory.md or docs/ instead of:\n" + "\n".join(found)


def test_theory_has_numbered_sections():
    sections = theory_sections()
    assert {"1", "2", "2.3", "3.4", "4.2", "5.1", "6.2", "7.1", "8.2", "8.7"} <= sections


@pytest.mark.parametrize("folder", CODE_FOLDERS)
def test_every_citation_of_theory_names_a_section_it_has(folder):
    """A § in the code is a citation of docs/theory.md (the code uses the sign for nothing else)."""
    sections, anchors = theory_sections(), theory_anchors()
    missing = []
    for path in sorted((ROOT / folder).rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        missing += [
            f"{path.relative_to(ROOT)}: §{number}"
            for number in SECTION_CITATION.findall(text)
            if number not in sections
        ]
        missing += [
            f"{path.relative_to(ROOT)}: #{anchor}" for anchor in ANCHOR_CITATION.findall(text) if anchor not in anchors
        ]
    assert not missing, f"docs/theory.md has no such section: {missing}"


def test_the_docs_cite_sections_of_theory_it_has():
    sections, anchors = theory_sections(), theory_anchors()
    missing = []
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]:
        text = path.read_text(encoding="utf-8")
        cited = re.findall(r"theory\.md[^)\n]{0,3}§(\d+(?:\.\d+)*)", text)
        if path == THEORY:
            cited = SECTION_CITATION.findall(text)
        missing += [f"{path.relative_to(ROOT)}: §{number}" for number in cited if number not in sections]
        missing += [
            f"{path.relative_to(ROOT)}: #{anchor}"
            for anchor in re.findall(r"\(#([\w-]+)\)", text)
            if path == THEORY and anchor not in anchors
        ]
        missing += [
            f"{path.relative_to(ROOT)}: #{anchor}" for anchor in ANCHOR_CITATION.findall(text) if anchor not in anchors
        ]
    assert not missing, f"docs/theory.md has no such section: {missing}"
