"""Commands that only read or list compile nothing (cache.py): `scenes`, `schema`, `describe`, every subcommand's
`--help` and `server status`, run in a fresh Python with empty caches (numba reads NUMBA_CACHE_DIR when it is imported),
leave both caches empty, import neither numba nor sympy, and say nothing of compiling."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from mech_regulator.cli.parser import build_parser

# a preset mechanism, general linkages (the scene checks solve their poses), joint friction (its kinetostatics)
DESCRIBED = ("engine_direct", "walking_beam_linkage", "six_bar_press_friction", "lathe")

RUN_COMMANDS = """
import contextlib, io, json, sys
from mech_regulator.cli.main import main

codes = []
for argv in json.loads(sys.argv[1]):
    with contextlib.redirect_stdout(io.StringIO()):
        try:
            codes.append(main(argv))
        except SystemExit as end:   # --help
            codes.append(end.code)
print(json.dumps({"codes": codes, "numba": "numba" in sys.modules, "sympy": "sympy" in sys.modules}))
"""


def subcommands() -> list[str]:
    """Every subcommand of the parser (and the bench's)."""
    parser = build_parser()
    choices = next(action for action in parser._subparsers._group_actions).choices
    names = list(choices)
    bench = next(action for action in choices["bench"]._subparsers._group_actions).choices
    return names + [f"bench {name}" for name in bench]


def test_reading_and_listing_commands_compile_nothing(tmp_path):
    caches = {name: tmp_path / name for name in ("numba", "compiled", "runtime")}
    for folder in caches.values():
        folder.mkdir()
    environment = dict(
        os.environ,
        NUMBA_CACHE_DIR=str(caches["numba"]),
        MECH_REGULATOR_CACHE=str(caches["compiled"]),
        XDG_RUNTIME_DIR=str(caches["runtime"]),
    )
    commands = (
        [["scenes"], ["schema"], ["schema", "--format", "markdown"], ["server", "status"]]
        + [["describe", scene] for scene in DESCRIBED]
        + [[*name.split(), "--help"] for name in subcommands()]
    )
    assert len(commands) > 20, commands  # every subcommand found
    result = subprocess.run(
        [sys.executable, "-c", RUN_COMMANDS, json.dumps(commands)],
        capture_output=True,
        text=True,
        timeout=300,
        env=environment,
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr
    ran = json.loads(result.stdout)
    assert ran["codes"] == [0] * len(commands), list(zip(commands, ran["codes"]))
    assert not ran["numba"] and not ran["sympy"], ran
    assert "compiling" not in result.stderr, result.stderr
    assert list(caches["numba"].iterdir()) == [] and list(caches["compiled"].iterdir()) == []
