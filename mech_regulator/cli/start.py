"""What the command line knows from its first import (the package imports this module): when it began, and
which commands the command server runs."""

import time

STARTED = time.monotonic()  # [s] when the command line began (its first import): `run`'s start-up counts from it
SERVED_COMMANDS = frozenset(
    {
        "simulate",
        "describe",
        "governor",
        "coupling",
        "kinematics",
        "engine",
        "structure",
        "flywheel",
        "scenes",
        "schema",
    }
)
"""Commands the command server (cli/server.py) runs: the physics core in one thread (not run: ROS; sweep: worker
processes or Dask; bench: processes of its own; compile: numba compiling for tens of seconds; server)."""
