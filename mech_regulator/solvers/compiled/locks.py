"""The fast path's compile locks, files in the cache folder (mech_regulator.cache): one for the background compile of
the steppers (warm.py) and one per method held while a stepper is compiled or loaded (steppers.stepper). Each is named
with the stamp of the compiled code's sources (numba_cache.reach_source_hash), so two versions of the package sharing a
cache folder (two checkouts, a `git pull` while a compile runs) never wait on each other's compile of other code: a
process would otherwise sit behind a compile it cannot use, saying nothing."""

from __future__ import annotations

import contextlib
import fcntl
import sys
import time
from collections.abc import Iterator
from pathlib import Path

from mech_regulator.cache import folder as cache_folder
from mech_regulator.numba_cache import reach_source_hash

STAMP_DIGITS = 16  # [-] hex digits of the sources' SHA-256 in a lock's name


def lock_path() -> Path:
    """The background compile's lock file: compiling-STAMP.lock in the cache folder."""
    return cache_folder() / f"compiling-{reach_source_hash()[:STAMP_DIGITS]}.lock"


def method_lock_path(method: str) -> Path:
    """The lock file of `method`'s stepper: compiling-STAMP-METHOD.lock in the cache folder."""
    return lock_path().with_name(f"{lock_path().stem}-{method}.lock")


@contextlib.contextmanager
def method_lock(method: str) -> Iterator[None]:
    """Hold the lock of `method`'s stepper (method_lock_path) while compiling or loading it
    (steppers.stepper): one process at a time, so that two (two commands, two test workers) never compile the
    same stepper side by side; the other one waits and loads it from numba's disk cache. Another method's compile does
    not hold it up. A wait is said on stderr when it starts and when it ends: another process's compile can take
    minutes on a busy machine, and a command that waits for it must not sit there saying nothing."""
    path = method_lock_path(method)
    with open(path, "a") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            start = time.monotonic()
            print(
                f"mech-regulator: waiting for another process's compile of the fast path's {method} stepper "
                f"(it holds {path}; a first compile takes some 50 s on an idle 2-core machine) ...",
                file=sys.stderr,
                flush=True,
            )
            fcntl.flock(handle, fcntl.LOCK_EX)
            print(f"  {method} stepper free after {time.monotonic() - start:.1f} s", file=sys.stderr, flush=True)
        yield
