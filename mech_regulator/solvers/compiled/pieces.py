"""The governor's speed pieces as the compiled stepper's rows (solvers/compiled/run.py, integrators' `pieces`): a
co-simulated governor follows the machine's speed in some 17 quadratic pieces an exchange (solvers/cosim.py), whose
load pieces and p values built in Python one by one (cosim.speed_pieces, CompiledScene.piece_values) cost about half
as much as the compiled call that steps them (docs/speed.md, "A seventh sitting"); and the machine's speed samples
and its prediction one cycle back (quadratics' functions compiled as they are: some 25 and 30 us an exchange in
Python, docs/speed.md, "An eighth sitting"). Compiled or loaded with a stepper (steppers.stepper), for the argument
types their calls have (SIGNATURE, SAMPLED_SPEEDS_SIGNATURE, CYCLE_BACK_SIGNATURE), as dense.steps_dense."""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import register_jitable

from mech_regulator import numba_cache
from mech_regulator.solvers.compiled.dense import SIGNATURE as DENSE_SIGNATURE
from mech_regulator.solvers.compiled.dense import steps_dense
from mech_regulator.solvers.quadratics import (
    quadratic_through,
    speed_load_line,
    speed_samples_times,
    speeds_one_cycle_back,
)

numba_cache.install()  # before the first njit(cache=True): keyed on the package's source

SIGNATURE = (types.float64[::1], types.float64[::1], types.float64[:, ::1])
"""speed_rows' argument types: the speed samples' times and speeds, and the rows it writes."""

CYCLE_BACK_SIGNATURE = (
    types.float64[:, ::1],
    types.float64,
    types.float64,
    types.float64,
    types.float64,
    types.float64,
)
"""speeds_one_cycle_back's argument types: the kept samples and five floats."""

SAMPLED_SPEEDS_SIGNATURE = DENSE_SIGNATURE[:5] + (types.float64, types.float64, types.float64)
"""sampled_speeds' argument types: a compiled call's arrays (results.StepsDense's), then three floats."""

_quadratic_through = njit(cache=True)(quadratic_through)
_speed_load_line = njit(cache=True)(speed_load_line)
for _plain in (
    quadratic_through,
    speed_samples_times,
):  # the plain functions, called from compiled code: compiled there
    register_jitable(_plain)
compiled_speeds_one_cycle_back = njit(cache=True)(speeds_one_cycle_back)


@njit(cache=True)
def speed_rows(times, speeds, rows):
    """Write into rows (one per piece) the pieces of the speed samples (times [s], omega [rad/s]; 2 rows.shape[0] + 1 of
    them, the quadratic through three on each piece) as the stepper goes on into them: [the piece's end [s], omega at
    its start [rad/s], then p[PIECE_SLOTS] as CompiledScene.piece_values gives them for cosim.speed_waveform's
    LoadPiece: its offset [N m] and slope [N m/s] (quadratics' functions, the same operations), throttle 1 held,
    the throttle's rates 0, its start [s], no sensitivity to the speed, stops 0 and 1, and the sign of omega at the
    start (codegen.sign_of)]."""
    for i in range(rows.shape[0]):
        t_start, t_end, first = times[2 * i], times[2 * i + 2], speeds[2 * i]
        a, b = _quadratic_through(t_end - t_start, first, speeds[2 * i + 1], speeds[2 * i + 2])
        offset, slope = _speed_load_line(a, b, t_start)
        sign = 1.0 if first > 0.0 else -1.0 if first < 0.0 else 0.0 if first == 0.0 else first
        row = rows[i]
        row[0], row[1] = t_end, first
        row[2], row[3], row[4], row[5], row[6] = offset, slope, 1.0, 0.0, 0.0
        row[7], row[8], row[9], row[10], row[11] = t_start, 0.0, 0.0, 1.0, sign


@njit(cache=True)
def sampled_speeds(times, y_old, coefficients, step_offsets, restarted, t_start, t_end, longest):
    """cosim.speed_samples of one compiled call's dense output (results.StepsDense: its arrays) over [t_start, t_end]
    [s] within it, the pieces no longer than `longest` [s]: the times (quadratics.speed_samples_times) and the
    crank's speed [rad/s] there (dense.steps_dense's), the rows of one array, in one call."""
    at = speed_samples_times(t_start, t_end, longest)
    samples = np.empty((2, at.size))
    samples[0] = at
    samples[1] = steps_dense(times, y_old, coefficients, step_offsets, restarted, at)[1]
    return samples
