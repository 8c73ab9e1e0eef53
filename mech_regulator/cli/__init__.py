"""The command line: a thin layer over the physics core."""

import sys
import time

EXIT_INTERRUPTED = 130
STARTED = time.monotonic()  # [s] when the command line began (its first import): `run`'s start-up counts from it


def entry() -> int:
    """Entry point of `mech-regulator`: the command line (cli.main.main), imported here so that a Ctrl-C while its
    modules load ends quietly with exit code 130, as a Ctrl-C later does."""
    try:
        from mech_regulator.cli.main import main

        return main()
    except KeyboardInterrupt:
        print("mech-regulator: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
