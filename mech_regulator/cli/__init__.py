"""The command line: a thin layer over the physics core. `entry` is the `mech-regulator` command."""

import sys

from mech_regulator.cli.command import run_command
from mech_regulator.cli.start import SERVED_COMMANDS
from mech_regulator.errors import EXIT_INTERRUPTED


def entry() -> int:
    """Entry point of `mech-regulator`: a served command through the command server when one serves it
    (cli/server_client.py: no heavy import there), else the command in this process (run_command)."""
    argv = sys.argv[1:]
    code = None
    if argv and argv[0] in SERVED_COMMANDS:
        try:
            from mech_regulator.cli.server_client import through_server

            code = through_server(argv)
        except KeyboardInterrupt:
            print("mech-regulator: interrupted", file=sys.stderr)
            return EXIT_INTERRUPTED
    return run_command(argv) if code is None else code
