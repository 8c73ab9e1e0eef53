"""The compiled evaluation of a compiled call's dense output (results.StepsDense): the co-simulation reads it at
every exchange (the machine's speed samples, the governor's throttle samples: solvers/cosim.py), where the same
evaluation in numpy took some 60 us a call in some 30 array operations, more than the numbers themselves cost. It is
compiled (about 1 s of CPU on a fresh machine) or loaded with a stepper (steppers.stepper), for the argument types
its calls have (SIGNATURE), so that the compile announced for a stepper covers it: compiled at its first call, it took
the main job's launcher a second or more after that compile, unannounced."""

from __future__ import annotations

import numpy as np
from numba import njit, types

from mech_regulator import numba_cache

numba_cache.install()  # before the first njit(cache=True): keyed on the package's source

SIGNATURE = (
    types.float64[::1],
    types.float64[:, ::1],
    types.float64[:, :, ::1],
    types.float64[::1],
    types.boolean[::1],
    types.float64[::1],
)
"""steps_dense's argument types as results.StepsDense passes them: a compiled call's arrays and the times asked for."""


@njit(cache=True)
def steps_dense(times, y_old, coefficients, step_offsets, restarted, at):
    """The states (n_states x m) at the m times `at` [s] of the dense output of the steps ending at times[1:]
    (results.StepsDense, in the same operations in the same order, so the same numbers to the bit): on step k (the last that
    starts at or before the time, the first and the last step continued beyond the ends; at the start of a step with
    restarted[k] the step before it), y = y_old[k] + h_k (((c_J theta + ...) theta + c_1) theta), theta = (t -
    times[k]) / h_k, and phi plus step_offsets[k] [rad] (an empty step_offsets: none)."""
    n_steps, n_states, order = coefficients.shape
    states = np.empty((n_states, at.size))
    for i in range(at.size):
        t = at[i]
        k = min(max(np.searchsorted(times, t, side="right") - 1, 0), n_steps - 1)
        if restarted[k] and times[k] == t:
            k -= 1
        h = times[k + 1] - times[k]
        theta = (t - times[k]) / h
        for state in range(n_states):
            total = 0.0
            for j in range(order - 1, -1, -1):
                total += coefficients[k, state, j]
                total *= theta
            states[state, i] = y_old[k, state] + h * total
        if step_offsets.size:
            states[0, i] += step_offsets[k]
    return states
