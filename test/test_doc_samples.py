"""The sample outputs in README.md and docs/*.md are what the commands print today: every fenced block that starts
with `$ mech-regulator ...` is run (in-process, in a temporary folder) and each command's printed lines must appear in
its output, in order. A line `...` in a sample leaves out lines there; the wrapping of long lines in a sample does
not count (whitespace is compared collapsed). A scene file a sample names (`my_six_bar.yaml`) is the page's own
```yaml block of that name, so the sample runs what a reader would write from the page alone. Output files a sample
writes (`--plot`, `--out`, `--record`) go to the temporary folder, by their names alone. The suite fixes `solver.path: auto` to the
reference path (test/conftest.py), which is what a first run on a fresh machine prints as well."""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass
from pathlib import Path

import pytest
from support import SOURCE_TREE, run_cli

PAGES = [SOURCE_TREE / "README.md", *sorted((SOURCE_TREE / "docs").glob("*.md"))]
FENCE = re.compile(r"^```(\w*)\n(.*?)^```$", re.MULTILINE | re.DOTALL)
PROMPT = "$ mech-regulator "
ELISION = "..."
OUTPUT_OPTIONS = ("--plot", "--out", "--record")


@dataclass(frozen=True)
class Sample:
    """One command of a page's sample block and the lines the page shows it printing."""

    page: Path
    line: int  # [-] the command's line in the page, 1-based
    argv: tuple[str, ...]
    shown: tuple[str, ...]

    def __str__(self) -> str:
        return f"{self.page.relative_to(SOURCE_TREE)}:{self.line}"


def samples() -> list[Sample]:
    """Every `$ mech-regulator` command shown in a fenced block without a language, with the lines shown under it."""
    found = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for block in FENCE.finditer(text):
            if block.group(1) or not block.group(2).startswith(PROMPT):
                continue
            first_line = text.count("\n", 0, block.start(2)) + 1
            commands: list[tuple[int, str, list[str]]] = []
            for offset, line in enumerate(block.group(2).splitlines()):
                if line.startswith(PROMPT):
                    commands.append((first_line + offset, line[len(PROMPT) :], []))
                else:
                    commands[-1][2].append(line)
            found += [Sample(page, number, tuple(shlex.split(line)), tuple(shown)) for number, line, shown in commands]
    return found


def yaml_block_named(page: Path, name: str) -> str:
    """The page's ```yaml block whose scene is `name` (its `name:` key)."""
    for block in FENCE.finditer(page.read_text(encoding="utf-8")):
        if block.group(1) == "yaml" and re.search(rf"^name: {re.escape(name)}$", block.group(2), re.MULTILINE):
            return block.group(2)
    raise AssertionError(f"{page.name} shows a command on {name}.yaml but no ```yaml block with name: {name}")


def collapsed(text: str) -> str:
    return " ".join(text.split())


def runnable(sample: Sample) -> list[str]:
    """The sample's argv, run in a temporary folder: its output files written there (by their names alone) and its
    own scene files (`NAME.yaml`) written there from the page."""
    argv = list(sample.argv)
    for index, argument in enumerate(argv):
        if index and argv[index - 1] in OUTPUT_OPTIONS:
            argv[index] = Path(argument).name
        elif argument.endswith(".yaml"):
            argv[index] = Path(argument).name
            Path(argv[index]).write_text(yaml_block_named(sample.page, Path(argument).stem), encoding="utf-8")
    return argv


SAMPLES = samples()


def test_the_pages_show_samples():
    assert len(SAMPLES) >= 10, [str(sample) for sample in SAMPLES]


@pytest.mark.parametrize("sample", SAMPLES, ids=str)
def test_a_sample_shows_what_the_command_prints(sample, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _, out, err = run_cli(capsys, *runnable(sample))
    printed = collapsed(out + "\n" + err)
    position = 0
    pieces = "\n".join(sample.shown).split(f"\n{ELISION}\n") if sample.shown else []
    for piece in pieces:
        expected = collapsed(piece.replace(ELISION, ""))
        found = printed.find(expected, position)
        assert found >= 0, f"{sample} shows\n{piece}\nbut `mech-regulator {' '.join(sample.argv)}` printed\n{out}{err}"
        position = found + len(expected)
