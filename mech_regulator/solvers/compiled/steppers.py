"""The four compiled steppers, RK45, DOP853, Rosenbrock23 and RK4: each the integration loop of integrators.py run
with one method, compiled by numba with its explicit signature when a run first asks for it (stepper(method)) and
cached on disk. integrators.py's docstring says how to call them and what they return."""

from __future__ import annotations

import functools

import numpy as np
from numba import njit, types

from mech_regulator import numba_cache
from mech_regulator.solvers.compiled.dense import SIGNATURE as DENSE_SIGNATURE
from mech_regulator.solvers.compiled.dense import steps_dense
from mech_regulator.solvers.compiled.events import SWITCH_WINDOW_SIGNATURE, _switch_window
from mech_regulator.solvers.compiled.integrators import _integrate
from mech_regulator.solvers.compiled.locks import method_lock
from mech_regulator.solvers.compiled.pieces import (
    CYCLE_BACK_SIGNATURE,
    SAMPLED_SPEEDS_SIGNATURE,
    compiled_speeds_one_cycle_back,
    sampled_speeds,
    speed_rows,
)
from mech_regulator.solvers.compiled.pieces import SIGNATURE as PIECES_SIGNATURE
from mech_regulator.solvers.compiled.signatures import GUARDS_TYPE, REACTIONS_TYPE, RHS_TYPE
from mech_regulator.solvers.compiled.steps import _DOP853, _RK4, _RK45, _ROSENBROCK23

numba_cache.install()  # before the first njit(cache=True): keyed on the package's source

_RESTART_ARGS = (
    types.float64[::1],
    types.float64,
    types.float64,
    types.int64[::1],
    types.int64[::1],
    types.float64[:, ::1],
    types.int64[::1],
    types.int64,
)
_ADAPTIVE_ARGS = (
    RHS_TYPE,
    GUARDS_TYPE,
    types.int64,
    types.float64[:, ::1],
    types.float64[::1],
    REACTIONS_TYPE,
    types.int64,
    types.float64,
    types.float64[::1],
    types.float64,
    types.float64[::1],
    types.float64,
    types.float64[::1],
    types.float64,
    types.float64,
    types.float64,
    types.float64,
    types.int64,
    types.int64,
) + _RESTART_ARGS
_FIXED_ARGS = (
    RHS_TYPE,
    GUARDS_TYPE,
    types.int64,
    types.float64[:, ::1],
    types.float64[::1],
    types.float64,
    types.float64[::1],
    types.float64,
    types.float64[::1],
    types.float64,
    types.float64,
    types.float64,
    types.int64,
    types.int64,
) + _RESTART_ARGS
# the restart arguments of a call that returns at every switch window's edge and at t_end (no restart inside)
NO_RESTARTS = (
    np.zeros(0),
    0.0,
    0.0,
    np.zeros(0, dtype=np.int64),
    np.zeros(0, dtype=np.int64),
    np.zeros((0, 2)),
    np.zeros(0, dtype=np.int64),
    0,
)


# the four steppers; stepper(method) compiles the one a run needs. Each hands _integrate its method (and RK4 its
# n_journals) as a run-time np.int64, not as a constant, which numba would type as a literal and compile _integrate
# and its steps for once per method: so _integrate is compiled, and cached, once for all four, and a further
# method's stepper compiles in some 6 s of CPU rather than 21 s (docs/speed.md, "The test suite").
def _rk45(
    rhs,
    guards,
    n_guards,
    linear,
    thresholds,
    reactions,
    n_journals,
    t0,
    y0,
    t_end,
    p,
    rtol,
    atol,
    max_step,
    first_step,
    wrap_limit,
    wrap_period,
    max_steps,
    run_steps,
    kink_grid,
    kink_period,
    kink_offset,
    kink_slots,
    speed_indices,
    pieces,
    piece_slots,
    max_restarts,
):
    """Dormand–Prince 5(4) exactly as scipy's RK45 (tableau, RMS error norm, controller, initial step, FSAL):
    the same steps up to round-off. Returns the result tuple of the module docstring."""
    return _integrate(
        np.int64(_RK45),
        rhs,
        guards,
        n_guards,
        linear,
        thresholds,
        reactions,
        n_journals,
        t0,
        y0,
        t_end,
        p,
        rtol,
        atol,
        max_step,
        first_step,
        0.0,
        wrap_limit,
        wrap_period,
        max_steps,
        run_steps,
        kink_grid,
        kink_period,
        kink_offset,
        kink_slots,
        speed_indices,
        pieces,
        piece_slots,
        max_restarts,
    )


def _dop853(
    rhs,
    guards,
    n_guards,
    linear,
    thresholds,
    reactions,
    n_journals,
    t0,
    y0,
    t_end,
    p,
    rtol,
    atol,
    max_step,
    first_step,
    wrap_limit,
    wrap_period,
    max_steps,
    run_steps,
    kink_grid,
    kink_period,
    kink_offset,
    kink_slots,
    speed_indices,
    pieces,
    piece_slots,
    max_restarts,
):
    """Dormand–Prince 8(5,3) exactly as scipy's DOP853 (its combined E5/E3 error norm, error exponent -1/8,
    the 7th-degree dense output from 3 extra stages). Returns the result tuple of the module docstring."""
    return _integrate(
        np.int64(_DOP853),
        rhs,
        guards,
        n_guards,
        linear,
        thresholds,
        reactions,
        n_journals,
        t0,
        y0,
        t_end,
        p,
        rtol,
        atol,
        max_step,
        first_step,
        0.0,
        wrap_limit,
        wrap_period,
        max_steps,
        run_steps,
        kink_grid,
        kink_period,
        kink_offset,
        kink_slots,
        speed_indices,
        pieces,
        piece_slots,
        max_restarts,
    )


def _rosenbrock23(
    rhs,
    guards,
    n_guards,
    linear,
    thresholds,
    reactions,
    n_journals,
    t0,
    y0,
    t_end,
    p,
    rtol,
    atol,
    max_step,
    first_step,
    wrap_limit,
    wrap_period,
    max_steps,
    run_steps,
    kink_grid,
    kink_period,
    kink_offset,
    kink_slots,
    speed_indices,
    pieces,
    piece_slots,
    max_restarts,
):
    """Shampine & Reichelt's modified Rosenbrock (2, 3) pair (MATLAB's ode23s), L-stable, for stiff scenes:
    with d = 1/(2 + sqrt 2), e32 = 6 + sqrt 2, W = I - h d J,
        k1 = W^-1 (F0 + h d T),  F1 = f(t + h/2, y + h k1/2),  k2 = W^-1 (F1 - k1) + k1,
        y_new = y + h k2,  F2 = f(t + h, y_new),  k3 = W^-1 (F2 - e32 (k2 - F1) - 2 (k1 - F0) + h d T),
        error = h/6 (k1 - 2 k2 + k3),
    J = df/dy and T = df/dt by forward differences at each step's start; scipy's error norm and controller
    with exponent -1/3. Returns the result tuple of the module docstring."""
    return _integrate(
        np.int64(_ROSENBROCK23),
        rhs,
        guards,
        n_guards,
        linear,
        thresholds,
        reactions,
        n_journals,
        t0,
        y0,
        t_end,
        p,
        rtol,
        atol,
        max_step,
        first_step,
        0.0,
        wrap_limit,
        wrap_period,
        max_steps,
        run_steps,
        kink_grid,
        kink_period,
        kink_offset,
        kink_slots,
        speed_indices,
        pieces,
        piece_slots,
        max_restarts,
    )


def _rk4(
    rhs,
    guards,
    n_guards,
    linear,
    thresholds,
    t0,
    y0,
    t_end,
    p,
    step,
    wrap_limit,
    wrap_period,
    max_steps,
    run_steps,
    kink_grid,
    kink_period,
    kink_offset,
    kink_slots,
    speed_indices,
    pieces,
    piece_slots,
    max_restarts,
):
    """Classic RK4, y_{n+1} = y_n + h/6 (k1 + 2 k2 + 2 k3 + k4), with step [s] shortened to divide
    [t0, t_end] evenly and the Hermite cubic dense output, as solvers/rk4.py. Returns the result tuple of
    the module docstring. Its step is kept: no journals' reach (guards stands in for reactions)."""
    return _integrate(
        np.int64(_RK4),
        rhs,
        guards,
        n_guards,
        linear,
        thresholds,
        guards,
        np.int64(0),
        t0,
        y0,
        t_end,
        p,
        0.0,
        np.zeros(0),
        0.0,
        0.0,
        step,
        wrap_limit,
        wrap_period,
        max_steps,
        run_steps,
        kink_grid,
        kink_period,
        kink_offset,
        kink_slots,
        speed_indices,
        pieces,
        piece_slots,
        max_restarts,
    )


_STEPPERS = {
    "RK45": (_rk45, _ADAPTIVE_ARGS),
    "DOP853": (_dop853, _ADAPTIVE_ARGS),
    "Rosenbrock23": (_rosenbrock23, _ADAPTIVE_ARGS),
    "RK4": (_rk4, _FIXED_ARGS),
}


@functools.cache
def stepper(method: str):
    """The compiled stepper of a method ('RK45', 'DOP853', 'Rosenbrock23', 'RK4'; call it as the module docstring
    says): compiled with its one explicit signature when first asked for, or loaded from numba's disk cache, so a
    process compiles or loads only the methods it runs (on a fresh machine some 50 s of CPU for the first to
    compile, some 7 s each further one: warm.py). Under the method's lock (locks.method_lock): a process that finds
    another compiling the same stepper waits and then loads it, rather than compiling it a second time beside it. The
    evaluation of the steppers' dense output (dense.steps_dense), the co-simulated governor's speed pieces
    (pieces.speed_rows), the machine's speed samples (pieces.sampled_speeds), its prediction one cycle back
    (pieces.compiled_speeds_one_cycle_back) and the switch window a call starts in (events._switch_window, which
    solvers/compiled/run.py calls from Python) are compiled or loaded with it (_KERNELS, entry_point)."""
    function, signature = _STEPPERS[method]
    for kernel in _KERNELS:
        entry_point(kernel)
    with method_lock(method):
        return njit(signature, cache=True)(function)


_KERNELS = {
    steps_dense: DENSE_SIGNATURE,
    speed_rows: PIECES_SIGNATURE,
    sampled_speeds: SAMPLED_SPEEDS_SIGNATURE,
    compiled_speeds_one_cycle_back: CYCLE_BACK_SIGNATURE,
    _switch_window: SWITCH_WINDOW_SIGNATURE,
}
"""The kernels compiled or loaded with every stepper, each for the one signature its calls have."""


@functools.cache
def entry_point(kernel):
    """The machine-code entry of one of the kernels compiled with the steppers (_KERNELS) for its signature, compiled
    or loaded here when first asked for (stepper asks for all): calling it skips numba's type dispatch of the
    arguments (some 0.5 us a call, the switch window's 1.2 us to 0.6: docs/speed.md, "A ninth sitting"), so its
    arguments must have exactly those types: an array of another dtype or layout would be misread, not refused."""
    return kernel.compile(_KERNELS[kernel])
