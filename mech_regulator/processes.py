"""Processes seen from Linux: whether one still runs, a child that ends with its parent, and the command line of a
child Python that imports what this one imports. The launcher's nodes, the command server, the fast path's compile
and the benchmarks all start or watch processes."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys


def process_alive(pid: int) -> bool:
    """Whether the process runs (a zombie waiting for its parent's reaping counts as ended)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False
    except OSError:  # no /proc: ask the kernel
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:  # another user's
            return True
        return True


def die_with_parent() -> None:
    """In a child process before it starts (Linux): receive SIGINT when its parent dies, however it dies (even
    SIGKILL), so that the child (a node; `bench soak`'s run) closes what it has and ends, and none is left behind."""
    import ctypes

    PR_SET_PDEATHSIG = 1
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGINT)


def python_child(program: str, *arguments: str) -> list[str]:
    """The command line of a child Python that runs `program` (source, as `python -c` runs it; `arguments` are its
    sys.argv[2:]) with this interpreter, its flags (-O, -X ..., as multiprocessing starts its processes) and this
    process's sys.path, so that it imports the very modules this one imports. `python -m` or a bare `python -c` put
    the child's working folder first on sys.path, where another copy of a package is imported when there is one (a
    command run from a checkout while the package it runs is installed elsewhere): the main job's compile child
    then compiled that copy's code, and the main job, finding nothing compiled for its own, compiled it again,
    unannounced (docs/speed.md, "A fresh clone's first run, step by step")."""
    flags = subprocess._args_from_interpreter_flags()  # type: ignore[attr-defined]
    bootstrap = f"import json, sys; sys.path[:] = json.loads(sys.argv[1]); {program}"
    return [sys.executable, *flags, "-c", bootstrap, json.dumps(sys.path), *arguments]


COMMAND_LINE_PROGRAM = (
    "from mech_regulator.cli import entry; sys.argv[:] = ['mech-regulator', *sys.argv[2:]]; sys.exit(entry())"
)
"""What a command-line child runs (python_child): `mech-regulator` with the child's arguments."""


def command_line_child(*arguments: str) -> list[str]:
    """The command line of a child `mech-regulator ARGUMENTS` run by this interpreter with this process's sys.path
    (python_child), not `python -m mech_regulator`, which would import a copy of the package in the working folder."""
    return python_child(COMMAND_LINE_PROGRAM, *arguments)
