"""`mech-regulator ARGV` in a process forked from one that has imported what `run` imports (multiprocessing's
forkserver, preloaded with PRELOADED): what a new Python and those imports cost is paid once, not for each command
(some 1.5 s of CPU of a `run`'s 2.5-4 s on the 2-core machine). The command itself runs as
`python -m mech_regulator ARGV` does (cli.entry; the suite sets no command server), in its folder, its output to
files read back as a subprocess.CompletedProcess; its exit code is the process's.

The forkserver starts with the environment of the test process at its first use and keeps it: a command that needs
another environment is started with subprocess."""

from __future__ import annotations

import multiprocessing
import os
import subprocess
import sys
from pathlib import Path

PRELOADED = ["mech_regulator.cli.command", "mech_regulator.nodes.common", "mech_regulator.viz.recording"]
CONTEXT = multiprocessing.get_context("forkserver")
CONTEXT.set_forkserver_preload(PRELOADED)


def _command(argv: list[str], folder: str) -> None:
    """In the forked process: `mech-regulator ARGV` in `folder`, its standard output and error to folder/stdout.txt
    and folder/stderr.txt; ends with its exit code."""
    from mech_regulator.cli import entry

    os.chdir(folder)
    for name, stream in (("stdout.txt", sys.stdout), ("stderr.txt", sys.stderr)):
        with open(name, "w") as target:
            os.dup2(target.fileno(), stream.fileno())
    sys.argv = ["mech-regulator", *argv]
    sys.exit(entry())


def preloaded_command(argv: list[str], folder: Path, timeout: float) -> subprocess.CompletedProcess:
    """Run `mech-regulator ARGV` in `folder` (module docstring); subprocess.TimeoutExpired (the process killed) should
    it not end within `timeout` [s]."""
    process = CONTEXT.Process(target=_command, args=(argv, str(folder)))
    process.start()
    process.join(timeout)
    if process.exitcode is None:
        process.kill()
        process.join()
        raise subprocess.TimeoutExpired(argv, timeout)
    return subprocess.CompletedProcess(
        argv, process.exitcode, (folder / "stdout.txt").read_text(), (folder / "stderr.txt").read_text()
    )
