"""The compiled steppers of the fast path: RK45 (scipy's RK45), DOP853 (scipy's DOP853), RK4 (the classic
fixed-step RK4 of solvers/rk4.py) and Rosenbrock23 (MATLAB's ode23s, for stiff scenes), each compiled by numba
with its explicit signature when first asked for (stepper(method)) and cached on disk; a scene's rhs and guards
come in as first-class functions (signatures.RHS_TYPE, GUARDS_TYPE).

Each stepper integrates dy/dt = rhs(t, y, p) from (t0, y0) towards t_end and stops at the first of:
t_end reached; a guard falling below its threshold inside a step (an event, located, the step cut there);
|y[0]| > wrap_limit at the end of an accepted step before t_end when wrap_period is 0 (the caller re-wraps the
crank angle and restarts); a speed beyond MAX_SPEED (limits.py) or not finite at the end of an accepted step (the
states speed_indices; the step kept, the call stops there: 'beyond'); failure (non-finite state, step size underflow,
max_steps accepted steps since the last restart, run_steps accepted steps in the call). With
wrap_period > 0 [rad] the stepper wraps the angle itself at the wrap limit, doing what the caller's restart would:
y[0] less whole periods, f evaluated anew, the last step's size kept (RK4: the rest divided evenly again); its
outputs (y_old, y_end) carry the unwrapped angle. Only for guards that do not read y[0] (no switch window).

With a kink grid (the switch window's restarts inside the call), a switch window's edge reached (its guard, from
kink_slots[0] on) is restarted on inside the loop as the caller (solvers/compiled/run.py) would, when that restart
changes nothing but the window (_kink_restart): phi set onto the edge and wrapped anew into [0, kink_period), the
next window's slots written into p and its guards' rows into linear, f evaluated anew, the last step's size kept
(RK4: the rest divided evenly again), max_steps counted from there; it returns the event instead when a mode guard
is within RESTART_MARGIN of its threshold there, or max_steps (run_steps) steps or max_restarts restarts were done in
the call. The numbers are those of the caller's restarts, bit for bit.

    stepper("RK45")(rhs, guards, n_guards, linear, thresholds, reactions, n_journals, t0, y0, t_end, p,
                    rtol, atol, max_step, first_step, wrap_limit, wrap_period, max_steps, run_steps,
                    kink_grid, kink_period, kink_offset, kink_slots, speed_indices, pieces, piece_slots,
                    max_restarts) -> result
    stepper("DOP853")(... as RK45 ...), stepper("Rosenbrock23")(... as RK45 ...)
    stepper("RK4")(rhs, guards, n_guards, linear, thresholds, t0, y0, t_end, p,
                   step, wrap_limit, wrap_period, max_steps, run_steps, kink_grid, kink_period, kink_offset,
                   kink_slots, speed_indices, pieces, piece_slots, max_restarts) -> result

t0, t_end, max_step, first_step (0 = choose it as scipy's select_initial_step), step [s]; atol per state
(units of the state); wrap_limit [rad] (inf = none); rk4's step is the largest step, shortened to divide
[t0, t_end] evenly as in solvers/rk4.py; run_steps: the most accepted steps of the call (the run's steps left below
limits.MAX_STEPS; failure 3 when reached before anything else stops the call). kink_grid: the switch grid [rad] in one
period kink_period [rad], sorted (empty: every edge returns; NO_RESTARTS are the arguments of such a call);
kink_offset [rad]: the whole periods taken off phi in y0 (added back in the dense output); kink_slots: the window's
first guard slot, then the slots in p of the clamp (lo, hi), the window's edges (lo, hi) and the sign of omega
(codegen's layout); speed_indices: the states kept within MAX_SPEED (the call stops at the first step end beyond it).
pieces: per row a piece that follows t_end, [its end [s], its start speed y[1] [rad/s], the values of p[piece_slots]]:
at t_end the call goes on into the next (_piece_restart: y[1] and those slots set, f anew, a fresh first step, as the
caller's next call would), on the same conditions as a kink, then to its end, and so on.
max_restarts: the most restarts (kinks and pieces) made inside one call (so that the caller hears of progress).

Joint friction's journals (docs/theory.md §6.5; as the reference path's one-step methods, time_domain._segment):
reactions(t, y, p, squares) writes the |R_j|^2 [N^2] of the n_journals journals with friction (a scene's generated
function; any function of that type when n_journals is 0: no limit, the steps exactly as without it). After every
accepted step of RK45, DOP853 or Rosenbrock23 they are sampled along the step's dense output at the GUARD_NODES
Chebyshev points and the complex zeros of their interpolants are the branch points of |R_j|
(time_domain._branch_points); every step stays at least its own length away from them (time_domain._reach): a
step that reaches closer is taken again from its start with the longest admissible step (once), and the next
steps, the first after a kink restart too, are limited to the reach from where they start (never below
time_domain._smallest_limit); a piece restart starts afresh, as the caller's next piece would.

The result tuple, in this order:
     0 status        int64: 0 reached t_end, 1 event, 2 wrap limit, 3 failed
     1 n_steps       int64: accepted steps n
     2 times         float64[n + 1]: step edges [s] (times[n]: the event time after an event)
     3 y_old         float64[n, n_states]: the state at each step's start
     4 coefficients  float64[n, n_states, K]: dense output y(t) = y_old[k] + h_k sum_{j=1..K} c[k, :, j-1] theta^j,
                     theta = (t - times[k]) / h_k, h_k = times[k+1] - times[k]; K = 4 (rk45: scipy's
                     RkDenseOutput; rk4: the Hermite cubic, column 4 zero; rosenbrock23: ode23s's quadratic,
                     columns 3-4 zero) or 7 (dop853: scipy's Dop853DenseOutput expanded into powers of theta).
                     A step cut by an event keeps the full step's polynomial, rescaled to the cut step's theta.
     5 event_guard   int64: index of the guard that fired, -1 if none
     6 event_time    float64 [s]: the event time (nan if none)
     7 y_end         float64[n_states]: the state at times[n] (the dense output at the event time after an
                     event; else the last accepted step's end state; y0 if no step was taken)
     8 nfev, 9 njev, 10 nlu  int64: rhs evaluations, Jacobian evaluations, LU factorisations
    11 last_step     float64 [s]: the last accepted step's full size (scipy's step_size), to warm-start the
                     next call (0 if none)
    12 failure       int64: why status 3: 1 non-finite state, 2 step size underflow, 3 max_steps or run_steps
                     reached, 4 a speed beyond MAX_SPEED (beyond)
    13 wraps         int64: wraps of the angle made inside the call (wrap_period > 0)
    14 kinks         int64: restarts on a switch window's edge made inside the call (each also a switch)
    15 step_offsets  float64[n]: the whole periods [rad] wrapped off phi on each step (kink_offset, then each
                     restart's), added back by the dense output
    16 restarted     bool[n]: whether the step begins a restart inside the call
    17 offset        float64 [rad]: the whole periods wrapped off phi at the end (y_end is less them)
    18 window_lo, 19 window_hi  float64 [rad]: the switch window at the end (nan without a kink grid)
    20 pieces_done   int64: rows of pieces the call went on into (y_end is in the last of them)
    21 step_limit    float64 [s]: the longest first step of the next call that the last step's branch points of the
                     journals' |R_j| allow from times[n] (inf: none; the caller's restart takes min(last_step, it))
    22 beyond        int64: the index of the first of speed_indices whose value at times[n] (y_end) is beyond
                     MAX_SPEED or not finite, -1 if none: the call stopped at the first such step end, that step kept
                     (status 1 when an event ended that step, else 3 with failure 4)

CompiledRun.from_result(result) wraps the tuple; StepsDense(times, y_old, coefficients, step_offsets, restarted)
is the dense output of all the steps of one call, for Trajectory.add_piece.

Guards: guards(t, y, p, levels) writes every guard's level (+inf: not active in this mode). A mode holds
while level >= threshold. linear[g] = [flag, c0, c1..c_n]: flag LINEAR (1) says the guard is c0 + sum c_i y_i, flag
STEP_ONTO (2) the same for a switch (a switch window's edge, solvers/time_domain.py's _step_onto): the event's state
is then not read off the dense output but computed by the method's own step from the step's start to the event
time, so a restart on a switch or kink keeps the method's accuracy; flag NONLINEAR_ONTO (3) a guard that is not
linear (its row otherwise unused) whose event is reached by such a step too (joint friction's guide N = 0); linear ones
along a step it is a polynomial in theta, whose first crossing in (0, 1] is found exactly (its derivative's
roots split the step into monotone pieces). Other guards are interpolated along the step at GUARD_NODES
Chebyshev points by a polynomial with an error bound, cut into monotone pieces in the same way, checked on the
guard itself where a piece ends near the threshold and located by Brent's method on the dense output, as the
reference does (time_domain._guard_crossing): a dip below the threshold and back is found however short.
Thresholds follow solvers/time_domain.py's _first_event: pass
thresholds[g] = 0 for its semantics; at every step start a guard within GUARD_TOLERANCE above its threshold
(at its boundary, as a transition leaves it) fires only when it falls GUARD_TOLERANCE below it. A guard
already more than GUARD_TOLERANCE below its threshold at t0 is an event at t0 with no step. The earliest
event over all guards wins.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numba import njit, types
from scipy.integrate import DOP853, RK45, DenseOutput
from scipy.integrate._ivp import dop853_coefficients

from mech_regulator.scene.limits import MAX_SPEED
from mech_regulator.solvers.compiled.dense import steps_dense
from mech_regulator.solvers.compiled.locks import method_lock
from mech_regulator.solvers.compiled.signatures import GUARDS_TYPE, REACTIONS_TYPE, RHS_TYPE
from mech_regulator.solvers.time_domain import (
    GUARD_NODE_FRACTIONS,
    GUARD_NODES,
    GUARD_TOLERANCE,
    _branch_points,
    _reach,
    _smallest_limit,
    guard_polynomial,
    monotone_ends,
    switch_window,
)

REACHED, EVENT, WRAPPED, FAILED = 0, 1, 2, 3
LINEAR, STEP_ONTO, NONLINEAR_ONTO = 1.0, 2.0, 3.0  # flags of guards with a row or a step onto (module docstring)
NONFINITE, STEP_TOO_SMALL, TOO_MANY_STEPS, BLOWN_UP = 1, 2, 3, 4
FAILURES = {
    NONFINITE: "the state became non-finite",
    STEP_TOO_SMALL: "the step size fell below round-off",
    TOO_MANY_STEPS: "the step limit (max_steps) was reached",
    BLOWN_UP: "a speed went beyond MAX_SPEED",
}

_RK4, _RK45, _DOP853, _ROSENBROCK23 = 0, 1, 2, 3
SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0  # scipy's step-size controller (scipy.integrate._ivp.rk)

# scipy's tableaux, taken from scipy itself (numba freezes these global arrays into the compiled code)
RK45_A = np.ascontiguousarray(RK45.A, dtype=np.float64)
RK45_B = np.ascontiguousarray(RK45.B, dtype=np.float64)
RK45_C = np.ascontiguousarray(RK45.C, dtype=np.float64)
RK45_E = np.ascontiguousarray(RK45.E, dtype=np.float64)
RK45_P = np.ascontiguousarray(RK45.P, dtype=np.float64)
DOP853_STAGES = dop853_coefficients.N_STAGES  # 12; the step adds f(t + h, y_new), the dense output 3 more
DOP853_A = np.ascontiguousarray(dop853_coefficients.A, dtype=np.float64)  # (16, 16) with the extra stages
DOP853_B = np.ascontiguousarray(DOP853.B, dtype=np.float64)
DOP853_C = np.ascontiguousarray(dop853_coefficients.C, dtype=np.float64)  # (16,)
DOP853_E3 = np.ascontiguousarray(DOP853.E3, dtype=np.float64)
DOP853_E5 = np.ascontiguousarray(DOP853.E5, dtype=np.float64)
DOP853_D = np.ascontiguousarray(DOP853.D, dtype=np.float64)  # (4, 16)
ROSENBROCK_D = 1.0 / (2.0 + np.sqrt(2.0))  # ode23s's gamma
ROSENBROCK_E32 = 6.0 + np.sqrt(2.0)

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
# kink_slots: the window's first guard slot, then the slots in p of the clamp (lo, hi), the window (lo, hi) and the
# sign of the crank's speed at the segment's start (codegen's CLAMP_LO, CLAMP_HI, WINDOW_LO, WINDOW_HI, CRANK_DIRECTION)
KINK_WINDOW_GUARD, KINK_CLAMP_LO, KINK_CLAMP_HI, KINK_WINDOW_LO, KINK_WINDOW_HI, KINK_DIRECTION = range(6)
RESTART_MARGIN = 1e-9  # a kink or piece is restarted inside only when every mode guard is this above its threshold


@njit(cache=True)
def _integrate(
    method,
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
    fixed_step,
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
    """The stepping loop shared by the four methods: accepted steps with their dense output stored in
    arrays grown by doubling, an event check on every step, the speed, wrap and step limits, the journals' reach, and
    the restarts inside the loop on a switch window's edges (_kink_restart) and into the following pieces
    (_piece_restart)."""
    n = y0.size
    powers = 7 if method == _DOP853 else 4
    stages = DOP853_A.shape[0] if method == _DOP853 else RK45_A.shape[0] + 1
    capacity = 256
    times = np.empty(capacity + 1)
    y_old = np.empty((capacity, n))
    coefficients = np.zeros((capacity, n, powers))
    step_offsets = np.empty(capacity)
    restarted = np.zeros(capacity, dtype=np.bool_)
    stage = np.empty((stages, n))
    work = np.empty(n)
    jacobian = np.empty((n, n))
    dfdt = np.empty(n)
    levels = np.empty(max(n_guards, 1))
    squares = np.empty((GUARD_NODES, max(n_journals, 1)))  # the journals' |R_j|^2 at the step's nodes [N^2]
    node_state = np.empty(n)
    branches = np.zeros(0, dtype=np.complex128)  # the branch points of the journals' |R_j| the last step saw [s]
    limit = np.inf  # the longest step they allow from where the next step starts [s] (inf: none)
    redone = False  # the last step was taken again within their reach
    t = t0
    y = y0.copy()
    f = np.empty(n)
    y_new = np.empty(n)
    f_new = np.empty(n)
    y_end = y0.copy()
    rhs(t, y, p, f)
    nfev, njev, nlu = 1, 0, 0
    status, failure, n_steps = -1, 0, 0
    event_guard, event_time = -1, np.nan
    h_previous = 0.0
    offset, wraps = 0.0, 0  # whole periods [rad] taken off y[0] by wraps inside this call, and how many
    # kink restarts made, the first step after the last one (and whether it is yet to be stored)
    kinks, first_of_segment, restart_pending = 0, 0, False
    beyond = -1  # the speed state beyond MAX_SPEED at the last step's end (-1: none)
    pieces_done = 0  # the pieces after the first that the call went on into
    window_lo, window_hi = np.nan, np.nan
    if kink_grid.size > 0:
        window_lo, window_hi = p[kink_slots[KINK_WINDOW_LO]], p[kink_slots[KINK_WINDOW_HI]]
    times[0] = t0
    if t_end <= t0:
        status = REACHED
    elif n_guards > 0:
        guards(t, y, p, levels)
        for g in range(n_guards):
            if levels[g] < thresholds[g] - GUARD_TOLERANCE:
                status, event_guard, event_time = EVENT, g, t0
                break
    order = 7 if method == _DOP853 else (4 if method == _RK45 else 2)
    if method == _RK4:
        count = max(1, np.ceil((t_end - t0) / fixed_step - 1e-9))
        h_abs = (t_end - t0) / count
    elif first_step > 0.0 or status >= 0:
        h_abs = first_step
    else:
        h_abs = _initial_step(rhs, t0, y, f, t_end, max_step, order, rtol, atol, p, y_new, f_new)
        nfev += 1
    exponent = -1.0 / 8.0 if method == _DOP853 else (-1.0 / 5.0 if method == _RK45 else -1.0 / 3.0)
    jacobian_current = False
    while status < 0:
        if n_steps - first_of_segment >= max_steps or n_steps >= run_steps:
            status, failure = FAILED, TOO_MANY_STEPS
            break
        if method == _RK4:
            h = t_end - t if t_end - t < 1.5 * h_abs else h_abs
            t_new = t + h
            nfev += _rk4_step(rhs, t, y, f, h, p, stage, y_new, f_new)
        else:
            min_step = 10.0 * abs(np.nextafter(t, np.inf) - t)
            h_abs = min(max(h_abs, min_step), min(max_step, limit))
            rejected = False
            finite = True
            while True:
                if h_abs < min_step:
                    status, failure = FAILED, (STEP_TOO_SMALL if finite else NONFINITE)
                    break
                t_new = min(t + h_abs, t_end)
                h = t_new - t
                h_abs = abs(h)
                if method == _ROSENBROCK23:
                    if not jacobian_current:
                        nfev += _derivatives(rhs, t, y, f, h, atol, rtol, p, jacobian, dfdt, y_new, f_new)
                        njev += 1
                        jacobian_current = True
                    error = _rosenbrock_step(rhs, t, y, f, h, jacobian, dfdt, rtol, atol, p, stage, y_new, f_new)
                    nfev += 2
                    nlu += 1
                else:
                    nfev += _rk_step(method, rhs, t, y, f, h, p, stage, y_new, f_new)
                    error = _error_norm(method, stage, h, y, y_new, rtol, atol)
                finite = _finite(y_new)
                if error < 1.0:
                    factor = MAX_FACTOR if error == 0.0 else min(MAX_FACTOR, SAFETY * error**exponent)
                    if rejected:
                        factor = min(1.0, factor)
                    h_abs *= factor
                    break
                factor = SAFETY * error**exponent
                h_abs *= factor if factor > MIN_FACTOR else MIN_FACTOR  # a nan error norm shrinks by MIN_FACTOR
                rejected = True
            if status >= 0:
                break
        if not _finite(y_new):
            status, failure = FAILED, NONFINITE
            break
        if n_steps == capacity:
            times, y_old, coefficients, step_offsets, restarted = _grown(
                times, y_old, coefficients, step_offsets, restarted
            )
            capacity *= 2
        nfev += _dense_coefficients(method, rhs, t, y, f, h, y_new, f_new, p, stage, work, coefficients[n_steps])
        if n_journals > 0:
            branches = _journal_branches(reactions, n_journals, t, h, y, coefficients[n_steps], p, squares, node_state)
            longest = _reach_from(branches, t)
            if h > longest and not redone:  # the step again from its start, within the reach
                h_abs = max(longest, _smallest_step_limit(t))
                redone = True
                continue
            redone = False
            limit = _step_limit(branches, t_new)
        y_old[n_steps] = y
        y_old[n_steps, 0] += offset
        step_offsets[n_steps] = kink_offset
        restarted[n_steps] = restart_pending
        restart_pending = False
        times[n_steps + 1] = t_new
        h_previous = h
        n_steps += 1
        if n_guards > 0:
            event_guard, event_time = _first_event(
                guards, n_guards, linear, thresholds, t, h, y, coefficients[n_steps - 1], p, levels, y_end
            )
            if event_guard >= 0:
                status = EVENT
                if event_time <= t:  # at the step's very start: no step taken
                    n_steps -= 1
                    y_end[:] = y
                elif linear[event_guard, 0] >= STEP_ONTO:  # the method's step from t onto the switch
                    h = event_time - t
                    if method == _RK4:
                        nfev += _rk4_step(rhs, t, y, f, h, p, stage, y_new, f_new)
                    elif method == _ROSENBROCK23:
                        _rosenbrock_step(rhs, t, y, f, h, jacobian, dfdt, rtol, atol, p, stage, y_new, f_new)
                        nfev += 2
                        nlu += 1
                    else:
                        nfev += _rk_step(method, rhs, t, y, f, h, p, stage, y_new, f_new)
                    coefficients[n_steps - 1] = 0.0
                    nfev += _dense_coefficients(
                        method, rhs, t, y, f, h, y_new, f_new, p, stage, work, coefficients[n_steps - 1]
                    )
                    y_end[:] = y_new
                    times[n_steps] = event_time
                else:
                    _dense_at(event_time, t, h, y, coefficients[n_steps - 1], y_end)
                    _rescale(coefficients[n_steps - 1], (event_time - t) / h)
                    times[n_steps] = event_time
                y_end[0] += offset
                if event_time > t:
                    beyond = _speed_beyond(y_end, speed_indices)
                if (
                    kink_grid.size > 0
                    and event_guard >= kink_slots[KINK_WINDOW_GUARD]
                    and t < event_time < t_end
                    and beyond < 0
                    and n_steps < max_steps
                    and n_steps < run_steps
                    and kinks + pieces_done < max_restarts
                ):
                    restart_offset = _kink_restart(
                        guards,
                        n_guards,
                        linear,
                        thresholds,
                        event_time,
                        y_end,
                        p,
                        levels,
                        kink_grid,
                        kink_period,
                        kink_offset,
                        kink_slots,
                        event_guard,
                        window_lo,
                        window_hi,
                        work,
                    )
                    if restart_offset == restart_offset:  # not nan: restarted on the next window, y its start
                        t = event_time
                        y[:] = work
                        kink_offset = restart_offset
                        window_lo, window_hi = p[kink_slots[KINK_WINDOW_LO]], p[kink_slots[KINK_WINDOW_HI]]
                        rhs(t, y, p, f)
                        nfev += 1
                        kinks += 1
                        first_of_segment = n_steps
                        restart_pending = True
                        status, event_guard, event_time = -1, -1, np.nan
                        if method == _RK4:
                            h_abs = (t_end - t) / max(1, np.ceil((t_end - t) / fixed_step - 1e-9))
                        else:
                            h_abs = min(abs(h_previous), t_end - t)
                        h_previous = 0.0
                        jacobian_current = False
                        limit = _step_limit(branches, t)  # as the caller's restart: within the reach from there
                        continue
                break
        t = t_new
        y[:] = y_new
        f[:] = f_new
        jacobian_current = False
        beyond = _speed_beyond(y, speed_indices)
        if beyond >= 0:  # the step that carried it there is kept, the call stops
            status, failure = FAILED, BLOWN_UP
        elif t >= t_end:
            if (
                pieces_done < pieces.shape[0]
                and pieces[pieces_done, 0] > t
                and n_steps < max_steps
                and n_steps < run_steps
                and kinks + pieces_done < max_restarts
                and _piece_restart(
                    guards, n_guards, thresholds, t, y, p, levels, pieces[pieces_done], piece_slots, work
                )
            ):
                # the caller's next piece, started here as it would: y[1] and p set, f anew, a fresh first step
                y[:] = work
                t_end = pieces[pieces_done, 0]
                pieces_done += 1
                branches, limit = branches[:0], np.inf  # a fresh start, as the caller's next piece (a new segment)
                rhs(t, y, p, f)
                nfev += 1
                first_of_segment = n_steps
                restart_pending = True
                h_previous = 0.0
                if method == _RK4:
                    h_abs = (t_end - t) / max(1, np.ceil((t_end - t) / fixed_step - 1e-9))
                else:
                    h_abs = _initial_step(rhs, t, y, f, t_end, max_step, order, rtol, atol, p, y_new, f_new)
                    nfev += 1
            else:
                status = REACHED
        elif abs(y[0]) > wrap_limit and wrap_period > 0.0:
            # what the reference path's restart does: the angle less whole periods, f evaluated anew there, the
            # last step's size (RK4: the remaining interval divided evenly again)
            unwrapped = y[0] + offset
            offset = wrap_period * np.floor(unwrapped / wrap_period)
            y[0] = unwrapped - offset
            rhs(t, y, p, f)
            nfev += 1
            wraps += 1
            if method == _RK4:
                h_abs = (t_end - t) / max(1, np.ceil((t_end - t) / fixed_step - 1e-9))
            else:
                h_abs = min(abs(h_previous), t_end - t)
        elif abs(y[0]) > wrap_limit:
            status = WRAPPED
    if status != EVENT:
        y_end[:] = y
        y_end[0] += offset
    return (
        status,
        n_steps,
        times[: n_steps + 1].copy(),
        y_old[:n_steps].copy(),
        coefficients[:n_steps].copy(),
        event_guard,
        event_time,
        y_end,
        nfev,
        njev,
        nlu,
        abs(h_previous),
        failure,
        wraps,
        kinks,
        step_offsets[:n_steps].copy(),
        restarted[:n_steps].copy(),
        kink_offset,
        window_lo,
        window_hi,
        pieces_done,
        _step_limit(branches, times[n_steps]),
        beyond,
    )


@njit(cache=True)
def _speed_beyond(y, speed_indices):
    """The first index of speed_indices whose speed in y is beyond MAX_SPEED [rad/s] or not finite, -1 if none."""
    for i in speed_indices:
        if not abs(y[i]) <= MAX_SPEED:
            return i
    return -1


@njit(cache=True)
def _kink_restart(
    guards,
    n_guards,
    linear,
    thresholds,
    t,
    y_end,
    p,
    levels,
    grid,
    period,
    offset,
    slots,
    edge_guard,
    window_lo,
    window_hi,
    start,
):
    """The outer loop's restart (run._compiled_pieces) on the edge of the switch window (window_lo, window_hi) [rad]
    that guard edge_guard reached at t [s] in the state y_end (phi less offset [rad]), when it changes nothing but the
    window: phi set onto the edge, wrapped anew into one period (the edge less whole periods: the phase is carried, never
    read back off the growing phi; the new offset is those periods added to offset's), the
    window ahead (_switch_window) written into p (the clamp, 1e-9 of its width inside, the window's edges, the sign of
    omega) and into the window guards' linear rows. Done only when every other guard is at least RESTART_MARGIN above
    its threshold there (no mode change the outer loop's time_domain._settle_mode would apply) and the window's own do
    not fire at once: then start holds the restart state (phi wrapped) and the new offset [rad] is returned; else p
    is left as it was and nan is returned (the caller returns the event)."""
    window_guard = slots[KINK_WINDOW_GUARD]
    edge = window_lo if edge_guard == window_guard else window_hi  # less offset, as the window
    whole = np.floor(edge / period)  # the phase on the edge wrapped into one period, never read off phi
    new_offset = period * (np.round(offset / period) + whole)  # (time_domain.turns_and_phase)
    start[:] = y_end
    start[0] = edge - whole * period
    lo, hi = _switch_window(grid, period, start[0], y_end[1] >= 0.0)
    saved = np.empty(slots.size)
    for k in range(1, slots.size):
        saved[k] = p[slots[k]]
    margin = 1e-9 * (hi - lo)
    p[slots[KINK_CLAMP_LO]], p[slots[KINK_CLAMP_HI]] = lo + margin, hi - margin
    p[slots[KINK_WINDOW_LO]], p[slots[KINK_WINDOW_HI]] = lo, hi
    p[slots[KINK_DIRECTION]] = np.sign(start[1])
    guards(t, start, p, levels)
    for g in range(n_guards):
        own = g == window_guard or g == window_guard + 1
        if levels[g] < thresholds[g] + (-GUARD_TOLERANCE if own else RESTART_MARGIN):
            for k in range(1, slots.size):
                p[slots[k]] = saved[k]
            return np.nan
    linear[window_guard, 1], linear[window_guard + 1, 1] = -lo, hi
    return new_offset


@njit(cache=True)
def _piece_restart(guards, n_guards, thresholds, t, y, p, levels, row, slots, start):
    """The caller's start of its next piece at t [s] (cosim's governor following the machine's speed piece by piece),
    when that changes nothing but the crank speed y[1] and the piece's slots of p: row = [the piece's end [s], its
    start speed [rad/s], the values of p[slots]]. Done only when every guard is at least RESTART_MARGIN above its
    threshold there (no mode change the caller's time_domain._settle_mode would apply): then start holds the
    piece's start state and p its slots, and True is returned; else p is left as it was and False is returned."""
    start[:] = y
    start[1] = row[1]
    saved = np.empty(slots.size)
    for k in range(slots.size):
        saved[k] = p[slots[k]]
        p[slots[k]] = row[2 + k]
    guards(t, start, p, levels)
    for g in range(n_guards):
        if levels[g] < thresholds[g] + RESTART_MARGIN:
            for k in range(slots.size):
                p[slots[k]] = saved[k]
            return False
    return True


@njit(cache=True)
def _finite(x):
    """Whether every entry of x is finite (no temporary array)."""
    for value in x:
        if not np.isfinite(value):
            return False
    return True


@njit(cache=True)
def _grown(times, y_old, coefficients, step_offsets, restarted):
    """The output arrays with twice the room for steps, the stored steps copied."""
    capacity = y_old.shape[0]
    new_times = np.empty(2 * capacity + 1)
    new_times[: capacity + 1] = times
    new_y_old = np.empty((2 * capacity, y_old.shape[1]))
    new_y_old[:capacity] = y_old
    new_coefficients = np.zeros((2 * capacity, coefficients.shape[1], coefficients.shape[2]))
    new_coefficients[:capacity] = coefficients
    new_offsets = np.empty(2 * capacity)
    new_offsets[:capacity] = step_offsets
    new_restarted = np.zeros(2 * capacity, dtype=np.bool_)
    new_restarted[:capacity] = restarted
    return new_times, new_y_old, new_coefficients, new_offsets, new_restarted


@njit(cache=True)
def _rms(x):
    """Root mean square of x (scipy's norm for step control)."""
    return np.sqrt(np.sum(x * x) / x.size)


@njit(cache=True)
def _initial_step(rhs, t0, y0, f0, t_bound, max_step, order, rtol, atol, p, y1, f1):
    """scipy's select_initial_step (Hairer, Nørsett & Wanner, II.4): h0 from |y0| / |f0|, refined by the
    change of f over h0 so that h^(order+1) times it is about 0.01 (one rhs evaluation)."""
    interval = abs(t_bound - t0)
    scale = atol + np.abs(y0) * rtol
    d0 = _rms(y0 / scale)
    d1 = _rms(f0 / scale)
    h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    h0 = min(h0, interval)
    y1[:] = y0 + h0 * f0
    rhs(t0 + h0, y1, p, f1)
    d2 = _rms((f1 - f0) / scale) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / (order + 1))
    return min(100.0 * h0, h1, interval, max_step)


@njit(cache=True)
def _stage_state(y, h, stage, weights, count, out):
    """out = y + h sum_{s < count} weights[s] stage[s]: the state a Runge–Kutta stage is evaluated at (plain
    loops over preallocated arrays: for a machine of a few states this is most of a step's cost)."""
    for i in range(y.size):
        total = 0.0
        for s in range(count):
            total += weights[s] * stage[s, i]
        out[i] = y[i] + h * total


@njit(cache=True)
def _rk_step(method, rhs, t, y, f, h, p, stage, y_new, f_new):
    """One explicit Runge–Kutta step as scipy's rk_step: stage[s] = f(t + c_s h, y + h sum_j a_sj stage[j]),
    y_new = y + h sum_s b_s stage[s], f_new = f(t + h, y_new) kept as the last stage (FSAL); the stage states
    are built in y_new. Returns the number of rhs evaluations."""
    if method == _DOP853:
        a, b, c, count = DOP853_A, DOP853_B, DOP853_C, DOP853_STAGES
    else:
        a, b, c, count = RK45_A, RK45_B, RK45_C, RK45_B.size
    stage[0] = f
    for s in range(1, count):
        _stage_state(y, h, stage, a[s], s, y_new)
        rhs(t + c[s] * h, y_new, p, stage[s])
    _stage_state(y, h, stage, b, count, y_new)
    rhs(t + h, y_new, p, f_new)
    stage[count] = f_new
    return count


@njit(cache=True)
def _error_norm(method, stage, h, y, y_new, rtol, atol):
    """scipy's error norm of an explicit step, scaled by scale_i = atol_i + rtol max(|y_i|, |y_new_i|): RK45's RMS
    of h sum_s e_s stage[s] / scale; DOP853's |h| |err5|^2 / sqrt(n (|err5|^2 + 0.01 |err3|^2)) with
    err5, err3 = sum_s e5_s stage[s] / scale, sum_s e3_s stage[s] / scale."""
    n = y.size
    if method == _RK45:
        total = 0.0
        for i in range(n):
            error = 0.0
            for s in range(RK45_E.size):
                error += RK45_E[s] * stage[s, i]
            error *= h / (atol[i] + max(abs(y[i]), abs(y_new[i])) * rtol)
            total += error * error
        return np.sqrt(total / n)
    err5_2, err3_2 = 0.0, 0.0
    for i in range(n):
        err5, err3 = 0.0, 0.0
        for s in range(DOP853_E5.size):
            err5 += DOP853_E5[s] * stage[s, i]
            err3 += DOP853_E3[s] * stage[s, i]
        scale = atol[i] + max(abs(y[i]), abs(y_new[i])) * rtol
        err5_2 += (err5 / scale) ** 2
        err3_2 += (err3 / scale) ** 2
    if err5_2 == 0.0 and err3_2 == 0.0:
        return 0.0
    return abs(h) * err5_2 / np.sqrt((err5_2 + 0.01 * err3_2) * n)


@njit(cache=True)
def _rk4_step(rhs, t, y, f, h, p, stage, y_new, f_new):
    """One classic RK4 step (k1 = f, k2, k3 at t + h/2, k4 at t + h; the stage states built in y_new) and
    f_new = f(t + h, y_new). Returns the number of rhs evaluations."""
    n = y.size
    for i in range(n):
        y_new[i] = y[i] + 0.5 * h * f[i]
    rhs(t + 0.5 * h, y_new, p, stage[1])
    for i in range(n):
        y_new[i] = y[i] + 0.5 * h * stage[1, i]
    rhs(t + 0.5 * h, y_new, p, stage[2])
    for i in range(n):
        y_new[i] = y[i] + h * stage[2, i]
    rhs(t + h, y_new, p, stage[3])
    for i in range(n):
        y_new[i] = y[i] + h / 6.0 * (f[i] + 2.0 * stage[1, i] + 2.0 * stage[2, i] + stage[3, i])
    rhs(t + h, y_new, p, f_new)
    return 4


@njit(cache=True)
def _derivatives(rhs, t, y, f, h, atol, rtol, p, jacobian, dfdt, y_work, f_work):
    """J = df/dy by forward differences (increment sqrt(eps) max(|y_i|, atol_i / rtol), as ode23s's
    threshold) and T = df/dt by a forward difference over min(sqrt(eps) max(|t|, |t + h|), h), as ode23s.
    Returns the number of rhs evaluations."""
    root_eps = np.sqrt(np.finfo(np.float64).eps)
    n = y.size
    for i in range(n):
        y_work[:] = y
        size = root_eps * max(abs(y[i]), atol[i] / rtol)
        if size == 0.0:
            size = root_eps
        y_work[i] = y[i] + size
        rhs(t, y_work, p, f_work)
        jacobian[:, i] = (f_work - f) / (y_work[i] - y[i])
    t_delta = (t + min(root_eps * max(abs(t), abs(t + h)), h)) - t
    rhs(t + t_delta, y, p, f_work)
    dfdt[:] = (f_work - f) / t_delta
    return n + 1


@njit(cache=True)
def _rosenbrock_step(rhs, t, y, f, h, jacobian, dfdt, rtol, atol, p, stage, y_new, f_new):
    """One ode23s step (formulas in rosenbrock23's docstring), one factorisation of W; stage[0..2] = k1, k2,
    k3, stage[3] = F1. Returns the error norm (scipy's RMS scaled by atol + rtol max(|y|, |y_new|))."""
    d = ROSENBROCK_D
    w_inverse = np.linalg.inv(np.eye(y.size) - h * d * jacobian)
    k1 = w_inverse @ (f + h * d * dfdt)
    rhs(t + 0.5 * h, y + 0.5 * h * k1, p, stage[3])
    k2 = w_inverse @ (stage[3] - k1) + k1
    y_new[:] = y + h * k2
    rhs(t + h, y_new, p, f_new)
    k3 = w_inverse @ (f_new - ROSENBROCK_E32 * (k2 - stage[3]) - 2.0 * (k1 - f) + h * d * dfdt)
    stage[0] = k1
    stage[1] = k2
    stage[2] = k3
    scale = atol + np.maximum(np.abs(y), np.abs(y_new)) * rtol
    return _rms(h / 6.0 * (k1 - 2.0 * k2 + k3) / scale)


@njit(cache=True)
def _dense_coefficients(method, rhs, t, y, f, h, y_new, f_new, p, stage, work, out):
    """The accepted step's dense output as powers of theta, out[i, j-1] the coefficient of h theta^j:
    RK45 stage^T P; the Hermite cubic from y, y_new, f, f_new; ode23s's
    y + h (theta (1 - theta) k1 + theta (theta - 2d) k2) / (1 - 2d); DOP853's nested form after 3 extra
    stages (work: room for a stage's state). Returns the number of rhs evaluations (DOP853's extra stages)."""
    if method == _RK45:
        for i in range(y.size):
            for j in range(RK45_P.shape[1]):
                total = 0.0
                for s in range(RK45_P.shape[0]):
                    total += stage[s, i] * RK45_P[s, j]
                out[i, j] = total
        return 0
    if method == _RK4:
        for i in range(y.size):
            slope = (y_new[i] - y[i]) / h
            out[i, 0] = f[i]
            out[i, 1] = 3.0 * slope - 2.0 * f[i] - f_new[i]
            out[i, 2] = f[i] + f_new[i] - 2.0 * slope
            out[i, 3] = 0.0
        return 0
    if method == _ROSENBROCK23:
        scale = 1.0 / (1.0 - 2.0 * ROSENBROCK_D)
        out[:, 0] = (stage[0] - 2.0 * ROSENBROCK_D * stage[1]) * scale
        out[:, 1] = (stage[1] - stage[0]) * scale
        out[:, 2:] = 0.0
        return 0
    return _dop853_dense(rhs, t, y, f, h, y_new, f_new, p, stage, work, out)


@njit(cache=True)
def _dop853_dense(rhs, t, y, f, h, y_new, f_new, p, stage, work, out):
    """scipy's DOP853 dense output: 3 extra stages, F = [dy, h f - dy, 2 dy - h (f_new + f), h D stage]
    (dy = y_new - y), y(theta) = y + x (F0 + (1 - x) (F1 + x (F2 + (1 - x) (F3 + ...)))) expanded into powers
    of theta and divided by h. Returns 3 (rhs evaluations)."""
    for s in range(DOP853_STAGES + 1, DOP853_A.shape[0]):
        _stage_state(y, h, stage, DOP853_A[s], s, work)
        rhs(t + DOP853_C[s] * h, work, p, stage[s])
    nested = np.empty(7)
    poly = np.empty(8)  # poly[j]: coefficient of theta^j
    for i in range(y.size):
        delta = y_new[i] - y[i]
        nested[0] = delta
        nested[1] = h * f[i] - delta
        nested[2] = 2.0 * delta - h * (f_new[i] + f[i])
        for row in range(DOP853_D.shape[0]):
            total = 0.0
            for s in range(DOP853_D.shape[1]):
                total += DOP853_D[row, s] * stage[s, i]
            nested[3 + row] = h * total
        poly[:] = 0.0
        for k in range(6, -1, -1):
            poly[0] += nested[k]
            if (6 - k) % 2 == 0:  # times theta
                for j in range(7, 0, -1):
                    poly[j] = poly[j - 1]
                poly[0] = 0.0
            else:  # times (1 - theta)
                for j in range(7, 0, -1):
                    poly[j] -= poly[j - 1]
        for j in range(7):
            out[i, j] = poly[j + 1] / h
    return 3


@njit(cache=True)
def _dense_at(time, t_old, h, y_old, coefficients, out):
    """The step's dense output at time: out = y_old + h sum_j c_j theta^j (Horner), theta = (time - t_old) / h."""
    theta = (time - t_old) / h
    for i in range(y_old.size):
        total = 0.0
        for j in range(coefficients.shape[1] - 1, -1, -1):
            total = (total + coefficients[i, j]) * theta
        out[i] = y_old[i] + h * total


@njit(cache=True)
def _rescale(coefficients, ratio):
    """Re-express a step's polynomial for the step cut to ratio of its length: c_j <- c_j ratio^(j-1), so that
    h' sum c'_j theta'^j (h' = ratio h, theta' = theta / ratio) is the same function of time."""
    for j in range(1, coefficients.shape[1]):
        coefficients[:, j] *= ratio**j


@njit(cache=True)
def _polynomial(theta, values):
    """sum_j values[j] theta^j (Horner)."""
    total = 0.0
    for j in range(values.size - 1, -1, -1):
        total = total * theta + values[j]
    return total


@njit(cache=True)
def _excess(time, g, line, t_old, h, y_old, coefficients, p, guards, levels, state, threshold):
    """How far guard g is above its threshold at time inside the step: the polynomial line in theta for a
    linear guard, else the guard evaluated on the dense output."""
    if line.size > 0:
        return _polynomial((time - t_old) / h, line)
    _dense_at(time, t_old, h, y_old, coefficients, state)
    guards(time, state, p, levels)
    return levels[g] - threshold


@njit(cache=True)
def _brent(a, b, g, line, t_old, h, y_old, coefficients, p, guards, levels, state, threshold):
    """Root of _excess in [a, b] by Brent's method, scipy's brentq (xtol 1e-15 s, rtol 4 eps) as the
    reference's event location; an end already on the root, or a bracket without a sign change
    (round-off), gives the end nearer to it, as the reference's _root."""
    xtol, rtol = 1e-15, 4.0 * np.finfo(np.float64).eps
    x_pre, x_cur = a, b
    f_pre = _excess(x_pre, g, line, t_old, h, y_old, coefficients, p, guards, levels, state, threshold)
    f_cur = _excess(x_cur, g, line, t_old, h, y_old, coefficients, p, guards, levels, state, threshold)
    if f_pre == 0.0 or f_pre * f_cur > 0.0:
        return a if abs(f_pre) <= abs(f_cur) else b
    if f_cur == 0.0:
        return b
    x_blk, f_blk, s_pre, s_cur = 0.0, 0.0, 0.0, 0.0
    for _ in range(100):
        if f_pre != 0.0 and f_cur != 0.0 and (f_pre < 0.0) != (f_cur < 0.0):
            x_blk, f_blk = x_pre, f_pre
            s_pre = s_cur = x_cur - x_pre
        if abs(f_blk) < abs(f_cur):
            x_pre, x_cur, x_blk = x_cur, x_blk, x_cur
            f_pre, f_cur, f_blk = f_cur, f_blk, f_cur
        delta = 0.5 * (xtol + rtol * abs(x_cur))
        s_bis = 0.5 * (x_blk - x_cur)
        if f_cur == 0.0 or abs(s_bis) < delta:
            return x_cur
        if abs(s_pre) > delta and abs(f_cur) < abs(f_pre):
            if x_pre == x_blk:  # secant
                s_try = -f_cur * (x_cur - x_pre) / (f_cur - f_pre)
            else:  # inverse quadratic interpolation
                d_pre = (f_pre - f_cur) / (x_pre - x_cur)
                d_blk = (f_blk - f_cur) / (x_blk - x_cur)
                s_try = -f_cur * (f_blk * d_blk - f_pre * d_pre) / (d_blk * d_pre * (f_blk - f_pre))
            if 2.0 * abs(s_try) < min(abs(s_pre), 3.0 * abs(s_bis) - delta):
                s_pre, s_cur = s_cur, s_try
            else:
                s_pre = s_cur = s_bis
        else:
            s_pre = s_cur = s_bis
        x_pre, f_pre = x_cur, f_cur
        x_cur += s_cur if abs(s_cur) > delta else (delta if s_bis > 0.0 else -delta)
        f_cur = _excess(x_cur, g, line, t_old, h, y_old, coefficients, p, guards, levels, state, threshold)
    return x_cur


_guard_polynomial = njit(cache=True)(guard_polynomial)
_switch_window = njit(cache=True)(switch_window)
_branch_points_of = njit(cache=True)(_branch_points)
_reach_from = njit(cache=True)(_reach)
_smallest_step_limit = njit(cache=True)(_smallest_limit)


@njit(cache=True)
def _journal_branches(reactions, n_journals, t_old, h, y_old, coefficients, p, squares, state):
    """The branch points [s, complex] of the journals' |R_j| along the step (t_old, t_old + h] [s]
    (time_domain._branch_points): reactions' |R_j|^2 on the step's dense output at the GUARD_NODES Chebyshev
    points (squares, state: room for them and for a state)."""
    for k in range(GUARD_NODES):
        time = t_old + GUARD_NODE_FRACTIONS[k] * h
        _dense_at(time, t_old, h, y_old, coefficients, state)
        reactions(time, state, p, squares[k])
    return _branch_points_of(squares[:, :n_journals], t_old, h)


@njit(cache=True)
def _step_limit(branches, t):
    """The longest step [s] from t [s] that the branch points allow (time_domain._reach), never below
    time_domain._smallest_limit; inf without any, as the reference's solver.max_step and first step."""
    return max(_reach_from(branches, t), _smallest_step_limit(t))


_monotone_ends = njit(cache=True)(monotone_ends)


@njit(cache=True)
def _golden_minimum(a, b, g, t_old, h, y_old, coefficients, p, guards, levels, state, threshold):
    """The minimum of guard g less threshold on [a, b] (a time interval inside the step) by golden-section search,
    to 1e-12 of the step: (time [s], value)."""
    ratio = 0.5 * (3.0 - np.sqrt(5.0))
    no_line = np.zeros(0)
    x1, x2 = a + ratio * (b - a), b - ratio * (b - a)
    f1 = _excess(x1, g, no_line, t_old, h, y_old, coefficients, p, guards, levels, state, threshold)
    f2 = _excess(x2, g, no_line, t_old, h, y_old, coefficients, p, guards, levels, state, threshold)
    for _ in range(100):
        if b - a <= 1e-12 * h:
            break
        if f1 < f2:
            b, x2, f2 = x2, x1, f1
            x1 = a + ratio * (b - a)
            f1 = _excess(x1, g, no_line, t_old, h, y_old, coefficients, p, guards, levels, state, threshold)
        else:
            a, x1, f1 = x1, x2, f2
            x2 = b - ratio * (b - a)
            f2 = _excess(x2, g, no_line, t_old, h, y_old, coefficients, p, guards, levels, state, threshold)
    return (x1, f1) if f1 < f2 else (x2, f2)


@njit(cache=True)
def _first_event(guards, n_guards, linear, thresholds, t_old, h, y_old, coefficients, p, levels, state):
    """The earliest guard crossing in (t_old, t_old + h]: (guard index, time [s]) or (-1, nan).

    Thresholds for this step: thresholds[g], lowered by GUARD_TOLERANCE for a guard that starts the step
    within GUARD_TOLERANCE above it. A linear guard is the polynomial g0 + sum_j a_j theta^j along the step;
    when g0 >= sum_j |a_j| it cannot fall below on [0, 1] and is done with at once (most steps); else the real
    parts of its derivative's roots cut (0, 1) into monotone pieces, so the first piece that ends below the
    threshold holds the first crossing (exact; a near-tangency that stays above does not fire). The other guards are
    sampled at GUARD_NODES Chebyshev points and checked as the reference's time_domain._guard_crossing does: their
    interpolating polynomial (with its error bound) cut into monotone pieces, the first piece that ends within the
    bound of the threshold checked on the guard itself at its end and, if above there, by a golden-section minimum
    over the pieces on both sides; a crossing is located by Brent's method from the last point known above."""
    n = y_old.size
    guards(t_old, y_old, p, levels)
    start = levels[:n_guards].copy()
    step_thresholds = thresholds[:n_guards].copy()
    nonlinear = False
    best_guard, best_time = -1, np.inf
    no_line = np.zeros(0)
    for g in range(n_guards):
        if start[g] == np.inf:
            continue
        if start[g] <= thresholds[g] + GUARD_TOLERANCE:
            step_thresholds[g] = thresholds[g] - GUARD_TOLERANCE
        if linear[g, 0] == 0.0 or linear[g, 0] == NONLINEAR_ONTO:
            nonlinear = True
            continue
        weights = linear[g, 2 : 2 + n].copy()
        line = np.zeros(coefficients.shape[1] + 1)  # level - threshold as powers of theta
        line[0] = linear[g, 1] + weights @ y_old - step_thresholds[g]
        line[1:] = h * (weights @ coefficients)
        if line[0] >= np.sum(np.abs(line[1:])):  # then line(theta) >= 0 on all of [0, 1]: no crossing (exact)
            continue
        lower = 0.0
        for upper in _monotone_ends(line):
            if _polynomial(upper, line) < 0.0:
                time = _brent(
                    t_old + lower * h,
                    t_old + upper * h,
                    g,
                    line,
                    t_old,
                    h,
                    y_old,
                    coefficients,
                    p,
                    guards,
                    levels,
                    state,
                    0.0,
                )
                if time < best_time:
                    best_guard, best_time = g, time
                break
            lower = upper
    if nonlinear:
        samples = np.empty((GUARD_NODES, n_guards))
        for k in range(GUARD_NODES):
            time = t_old + GUARD_NODE_FRACTIONS[k] * h
            _dense_at(time, t_old, h, y_old, coefficients, state)
            guards(time, state, p, levels)
            samples[k] = levels[:n_guards]
        for g in range(n_guards):
            if start[g] == np.inf or linear[g, 0] == LINEAR or linear[g, 0] == STEP_ONTO:
                continue
            line, margin = _guard_polynomial(samples[:, g] - step_thresholds[g])
            if line[0] - margin >= np.sum(np.abs(line[1:])):  # the polynomial stays above the margin on [0, 1]
                continue
            cuts = _monotone_ends(line)
            lower = 0.0
            for i in range(cuts.size):
                upper = cuts[i]
                if t_old + lower * h >= best_time:
                    break
                if _polynomial(upper, line) < margin:
                    t_low = t_old + upper * h
                    low = _excess(
                        t_low, g, no_line, t_old, h, y_old, coefficients, p, guards, levels, state, step_thresholds[g]
                    )
                    if low >= 0.0 and upper < 1.0:
                        t_min, v_min = _golden_minimum(
                            t_old + lower * h,
                            t_old + cuts[i + 1] * h,
                            g,
                            t_old,
                            h,
                            y_old,
                            coefficients,
                            p,
                            guards,
                            levels,
                            state,
                            step_thresholds[g],
                        )
                        if v_min < low:
                            t_low, low = t_min, v_min
                    if low < 0.0:
                        time = _brent(
                            t_old + lower * h,
                            t_low,
                            g,
                            no_line,
                            t_old,
                            h,
                            y_old,
                            coefficients,
                            p,
                            guards,
                            levels,
                            state,
                            step_thresholds[g],
                        )
                        if time < best_time:
                            best_guard, best_time = g, time
                        break
                lower = upper
    return best_guard, (best_time if best_guard >= 0 else np.nan)


# the four steppers; stepper(method) compiles the one a run needs
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
        _RK45,
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
        _DOP853,
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
        _ROSENBROCK23,
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
        _RK4,
        rhs,
        guards,
        n_guards,
        linear,
        thresholds,
        guards,
        0,
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
    process compiles or loads only the methods it runs (some 50 s of CPU each to compile on a fresh machine: warm.py).
    Under the method's lock (locks.method_lock): a process that finds another compiling the same stepper waits and then
    loads it, rather than compiling it a second time beside it."""
    function, signature = _STEPPERS[method]
    with method_lock(method):
        return njit(signature, cache=True)(function)


class StepsDense(DenseOutput):
    """The dense output of all the steps of one compiled call: y(t) = y_old[k] + h_k sum_j c[k, :, j-1]
    theta^j on step k (found by np.searchsorted over times), theta = (t - times[k]) / h_k, then phi plus the whole
    periods step_offsets[k] [rad] wrapped off it on that step (none by default). At the start of a step that begins a
    restart inside the call (restarted[k], a switch window's edge) the step before it answers, as between two pieces
    of a Trajectory (scipy's OdeSolution). Called with a scalar time [s] it gives shape (n_states,), with an array of
    m times shape (n_states, m)."""

    def __init__(
        self,
        times: np.ndarray,
        y_old: np.ndarray,
        coefficients: np.ndarray,
        step_offsets: np.ndarray | None = None,
        restarted: np.ndarray | None = None,
    ):
        super().__init__(times[0], times[-1])
        self.times, self.y_old, self.coefficients = times, y_old, coefficients
        self.step_offsets = np.empty(0) if step_offsets is None else step_offsets
        self.restarted = np.zeros(times.size - 1, dtype=np.bool_) if restarted is None else restarted

    def _call_impl(self, t):
        y = steps_dense(self.times, self.y_old, self.coefficients, self.step_offsets, self.restarted, np.atleast_1d(t))
        return y[:, 0] if np.ndim(t) == 0 else y


@dataclass
class CompiledRun:
    """One compiled call's result (the tuple of the module docstring, by name)."""

    status: int
    n_steps: int
    times: np.ndarray
    y_old: np.ndarray
    coefficients: np.ndarray
    event_guard: int
    event_time: float
    y_end: np.ndarray
    nfev: int
    njev: int
    nlu: int
    last_step: float
    failure: int
    wraps: int
    kinks: int
    step_offsets: np.ndarray
    restarted: np.ndarray
    offset: float
    window_lo: float
    window_hi: float
    pieces_done: int
    step_limit: float
    beyond: int

    @classmethod
    def from_result(cls, result: tuple) -> CompiledRun:
        """Name the fields of a stepper's result tuple."""
        return cls(*result)

    @property
    def t_end(self) -> float:
        """Where the call stopped [s]: t_end, the event time, the first step end past the wrap limit or the
        last good step end of a failed call."""
        return float(self.times[-1])

    @property
    def dense(self) -> StepsDense | None:
        """The dense output over [times[0], times[-1]], phi with the whole periods wrapped off it added back (the
        kink offsets), None when no step was taken."""
        return (
            StepsDense(self.times, self.y_old, self.coefficients, self.step_offsets, self.restarted)
            if self.n_steps
            else None
        )

    @property
    def message(self) -> str:
        """Why a failed call (status 3) stopped, '' otherwise."""
        return FAILURES[self.failure] + f" at t = {self.t_end:.6g} s" if self.status == FAILED else ""
