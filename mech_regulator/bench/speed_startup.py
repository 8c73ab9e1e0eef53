"""The speed benchmark's start-up measurements (bench/speed.py): time to the first result in a fresh Python process,
cold (empty compile caches) and warm, and the package's import time."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable

from mech_regulator.bench.speed_runs import BENCH_SCENE, FAST, REFERENCE, Row

STARTUP_PROGRAM = """
import time
start = time.perf_counter()
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene
from mech_regulator.solvers import simulate
imported = time.perf_counter()
trajectory = simulate(build_model(load_scene({scene!r}, {overrides!r})))
print(imported - start, time.perf_counter() - start, trajectory.status)
"""


def _python_wall(program: str, env: dict[str, str]) -> tuple[list[str], float]:
    """Run a Python program in a fresh interpreter: (its printed words, wall time [s] of the whole process)."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, env=env, check=False)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"start-up measurement failed: {done.stderr.strip().splitlines()[-1:]}")
    return done.stdout.split(), wall


def measure_startup(quick: bool, report: Callable[[Row], None]) -> list[Row]:
    """Time to the first result of crank_slider_bench (import + build + first run, wall time inside a fresh
    Python process) and the package's import time: reference path, and fast path cold (empty compile caches
    MECH_REGULATOR_CACHE and NUMBA_CACHE_DIR) then warm (the caches the cold run filled). quick: the fast path warm
    only, on this process's caches (where measure_durations compiled its DOP853 stepper), not the cold compile
    of some 50 s (solvers/compiled/warm.py)."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="mech-regulator-cache-") as cache:
        env = dict(os.environ) if quick else dict(os.environ, MECH_REGULATOR_CACHE=cache, NUMBA_CACHE_DIR=cache)
        cold = [] if quick else [(FAST, "cold", ["solver.path=fast"])]
        runs = [(REFERENCE, "warm", []), *cold, (FAST, "warm", ["solver.path=fast"])]
        for path, phase, overrides in runs:
            (imported, first, status), wall = _python_wall(
                STARTUP_PROGRAM.format(scene=BENCH_SCENE, overrides=overrides), env
            )
            rows.append(
                Row(
                    "startup",
                    BENCH_SCENE,
                    path,
                    "DOP853",
                    phase,
                    float(imported),
                    2.0,
                    float(first),
                    note=f"import {float(imported):.3g} s, process {wall:.3g} s, run {status}",
                )
            )
            report(rows[-1])
    return rows
