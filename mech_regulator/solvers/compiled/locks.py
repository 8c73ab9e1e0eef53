"""The fast path's compile locks, files in the cache folder (mech_regulator.cache): one for the background compile of
the steppers (warm.py) and one per method held while a stepper is compiled or loaded (steppers.stepper)."""

from __future__ import annotations

import contextlib
import fcntl
from collections.abc import Iterator
from pathlib import Path

from mech_regulator.cache import folder as cache_folder

LOCK_NAME = "compiling.lock"


def lock_path() -> Path:
    """The background compile's lock file (compiling.lock in the cache folder)."""
    return cache_folder() / LOCK_NAME


@contextlib.contextmanager
def method_lock(method: str) -> Iterator[None]:
    """Hold the lock of `method`'s stepper (compiling-METHOD.lock in the cache folder) while compiling or loading it
    (steppers.stepper): one process at a time, so that two (two commands, two test workers) never compile the
    same stepper side by side; the other one waits and loads it from numba's disk cache. Another method's compile does
    not hold it up."""
    with open(lock_path().with_name(f"compiling-{method}.lock"), "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        yield
