"""Warming the fast path: its compiled steppers (one per method, solvers/compiled/steppers.py) take some 40 to
50 s of CPU to compile on a fresh machine, the first of them (the integration loop all four share), and some 7 s each
further one (docs/speed.md, "The test suite") (compile_estimate; DOP853's on the 2-core machine: 44 s at a load of
about 2.5, 49.6 s idle in an earlier measurement; 147 s of wall time under a load of about 10, 305 s with a pip
install beside it: `NUMBA_CACHE_DIR=$(mktemp -d) MECH_REGULATOR_CACHE=$(mktemp -d) mech-regulator compile --method
DOP853`) — once per machine and numba version, then numba loads them from its disk cache in a fraction of a second
— while a scene's own module (codegen.py) compiles in a few seconds. So only the steppers are warmed ahead:

- `mech-regulator compile` compiles every method's stepper, a line per method (and the linkage solver, which the
  reference path runs compiled too: mechanisms/linkage/flat.py);
- the main job (`run`) compiles the stepper of its scene's method before its nodes start (`compile_before_the_run`):
  its nodes exchange some hundreds of times a second, which the reference path's per-exchange work holds to a tenth
  of the fast path's pace or less, and a compile beside them would take one of a small machine's cores; a compile that
  another process has under way is waited for, not run twice;
- any other command whose scene asks for the fast path while its method's stepper is not compiled yet is served by
  the reference path, and the stepper is compiled by a background process for the next run
  (`compile_in_background`; a lock in the cache folder keeps it to one such process at a time).

Run as a module (`python -m mech_regulator.solvers.compiled.warm METHOD ...`) it compiles the methods named (all
when none) under that lock: what the background process does. The processes started here run this module's main
with the starting process's sys.path (processes.python_child), so that they compile the package that process runs:
`python -m` imported the copy in the working folder when there was one (a checkout, the command's own package
installed elsewhere), and the main job then compiled its own stepper a second time, silently, after the announced
compile (docs/speed.md, "A fresh clone's first run, step by step").
"""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys
import time
from collections.abc import Callable, Iterable

from mech_regulator.processes import python_child
from mech_regulator.solvers.compiled import FAST_METHODS
from mech_regulator.solvers.compiled.locks import lock_path

LOCK_VARIABLE = "MECH_REGULATOR_COMPILE_LOCK_FD"  # the lock's descriptor handed to the background process
FIRST_COMPILE_ESTIMATE = "about 50 s on an idle 2-core machine, several times that on a busy one"  # (docstring)
FURTHER_COMPILE_ESTIMATE = (
    "about 10 s on an idle 2-core machine, the integration loop it shares with the compiled "
    "methods being compiled already; several times that on a busy one"
)
CHILD_PROGRAM = "from mech_regulator.solvers.compiled.warm import main; sys.exit(main(sys.argv[2:]))"
"""What a compiling process runs (processes.python_child), its methods as its arguments."""


def compile_estimate(method: str) -> str:
    """What compiling `method`'s stepper takes here, for the line that announces it (module docstring): the first
    stepper compiles the integration loop the methods share (FIRST_COMPILE_ESTIMATE), a further one does not
    (FURTHER_COMPILE_ESTIMATE), as another method's stepper in numba's disk cache shows."""
    from mech_regulator.solvers.compiled.steppers import _STEPPERS

    further = any(stepper_cached(other) for other in _STEPPERS if other != method)
    return FURTHER_COMPILE_ESTIMATE if further else FIRST_COMPILE_ESTIMATE


def stepper_cached(method: str) -> bool:
    """Whether numba's disk cache holds the compiled stepper of `method` for the current source of steppers.py and
    of every module compiled code can reach (mech_regulator/numba_cache.py; the index is empty when one changed)."""
    from numba.core.caching import FunctionCache

    from mech_regulator.solvers.compiled.steppers import _STEPPERS

    function, _ = _STEPPERS[method]
    return bool(FunctionCache(function)._cache_file._load_index())


def compile_steppers(methods: Iterable[str], report: Callable[[str], object] = lambda line: None) -> None:
    """Compile (or load from the disk cache) the steppers of `methods`, reporting a line before and after each."""
    from mech_regulator.solvers.compiled.steppers import stepper

    for method in methods:
        cached = stepper_cached(method)
        report(
            f"{'loading' if cached else 'compiling'} the fast path's {method} stepper"
            f"{'' if cached else f' (once, {compile_estimate(method)})'} ..."
        )
        started = time.perf_counter()
        stepper(method)
        report(f"  {method} ready in {time.perf_counter() - started:.1f} s")


def compile_before_the_run(method: str, report: Callable[[str], object]) -> None:
    """Compile the stepper of `method` before a run, saying so with its estimate and then how long it took: in a
    child process (this module's main, under the lock: a compile another process has under way is waited for, said
    too, and then loaded), so that the compile's memory stays out of this process — the main job's nodes are forked
    from it — and the run that follows is a warm run. Should this process still not find the stepper in numba's disk
    cache then (the package's sources changed since this process read them), it compiles it here, saying so.
    Raises RuntimeError with the child's output if the child fails."""
    with open(lock_path(), "a") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            busy = False
        except BlockingIOError:
            busy = True
    report(
        f"waiting for the fast path's {method} stepper that another process is compiling (once, "
        f"{compile_estimate(method)} in all) ..."
        if busy
        else f"compiling the fast path's {method} stepper (once, {compile_estimate(method)}) ..."
    )
    started = time.perf_counter()
    done = subprocess.run(python_child(CHILD_PROGRAM, method), stdin=subprocess.DEVNULL, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"compiling the fast path's {method} stepper failed:\n{done.stdout}{done.stderr}")
    report(f"{method} ready in {time.perf_counter() - started:.1f} s")
    if not stepper_cached(method):
        report(
            f"the {method} stepper compiled in a child process is not in numba's disk cache as this process reads it "
            "(the package's sources changed since this process read them): compiling it here"
        )
        compile_steppers([method], report)


def compile_in_background(methods: Iterable[str]) -> bool:
    """Start a detached process compiling the steppers of `methods` unless one is compiling already; returns whether
    one was started. The lock is taken here and handed to the process (an inherited descriptor), so that a second
    command right after this one sees it held. Its output goes to compiling.log in the cache folder."""
    lock = lock_path()
    with open(lock, "a") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return False  # another process is compiling
        with open(lock.with_name("compiling.log"), "a") as log:
            subprocess.Popen(
                python_child(CHILD_PROGRAM, *methods),
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
                pass_fds=(handle.fileno(),),
                env=dict(os.environ, **{LOCK_VARIABLE: str(handle.fileno())}),
            )
    return True  # the process holds the lock on its copy of the descriptor until it ends


def main(argv: list[str]) -> int:
    """Compile the steppers of the methods in argv (all fast methods when none), holding the lock meanwhile (handed
    over by compile_in_background, or taken here)."""
    methods = argv or list(FAST_METHODS)
    unknown = [method for method in methods if method not in FAST_METHODS]
    if unknown:
        print(f"unknown fast-path method(s) {unknown}; expected some of {', '.join(FAST_METHODS)}", file=sys.stderr)
        return 2
    inherited = os.environ.pop(LOCK_VARIABLE, None)
    with os.fdopen(int(inherited), "a") if inherited else open(lock_path(), "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        compile_steppers(methods, lambda line: print(line, flush=True))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
