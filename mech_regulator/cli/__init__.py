"""The command line: a thin layer over the physics core."""

import sys
import time

EXIT_INTERRUPTED = 130
EXIT_RUN_FAILED = 1  # a run that failed, or an output that could not be written after the work
EXIT_INACCURATE = 3  # simulate --strict: the run failed a self-check (analysis/self_check.py)
STARTED = time.monotonic()  # [s] when the command line began (its first import): `run`'s start-up counts from it
SERVED_COMMANDS = frozenset({"simulate", "describe", "governor", "coupling", "kinematics", "engine", "structure",
                             "flywheel", "scenes", "schema"})
"""Commands the command server (cli/server.py) runs: the physics core in one thread (not run: ROS; sweep: worker
processes or Dask; bench: processes of its own; compile: numba compiling for tens of seconds; server)."""


def entry() -> int:
    """Entry point of `mech-regulator`: a served command through the command server when one serves it
    (cli/server.py: no heavy import there), else the command in this process (run_command)."""
    argv = sys.argv[1:]
    code = None
    if argv and argv[0] in SERVED_COMMANDS:
        try:
            from mech_regulator.cli.server import through_server

            code = through_server(argv)
        except KeyboardInterrupt:
            print("mech-regulator: interrupted", file=sys.stderr)
            return EXIT_INTERRUPTED
    return run_command(argv) if code is None else code


def run_command(argv: list[str]) -> int:
    """The command line (cli.main.main) run on argv in this process, imported here so that a Ctrl-C while its
    modules load ends quietly with exit code 130, as a Ctrl-C later does; `run` then still leaves its summary
    (nodes.launch.summary_before_start: nothing simulated)."""
    try:
        from mech_regulator.cli.main import main

        return main(argv)
    except KeyboardInterrupt:
        print("mech-regulator: interrupted", file=sys.stderr)
        if argv[:1] == ["run"]:
            from mech_regulator.nodes.launch import summary_before_start

            written = summary_before_start(argv)
            if written is not None:
                print(f"mech-regulator: nothing was simulated; wrote {written}", file=sys.stderr)
        return EXIT_INTERRUPTED
