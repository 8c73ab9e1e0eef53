"""The integration loop of the fast path's compiled steppers: RK45 (scipy's RK45), DOP853 (scipy's DOP853), RK4 (the
classic fixed-step RK4 of solvers/rk4.py) and Rosenbrock23 (MATLAB's ode23s, for stiff scenes), each compiled by
numba with its explicit signature when first asked for (steppers.stepper(method)) and cached on disk; a scene's rhs
and guards come in as first-class functions (signatures.RHS_TYPE, GUARDS_TYPE). One step of each method is in
steps.py, the location of a guard's crossing inside a step in events.py, what a call gives back in results.py.

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

results.CompiledRun.from_result(result) wraps the tuple; StepsDense(times, y_old, coefficients, step_offsets, restarted)
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

import numpy as np
from numba import njit

from mech_regulator import numba_cache
from mech_regulator.scene.limits import MAX_SPEED
from mech_regulator.solvers.compiled.events import (
    STEP_ONTO,
    _dense_at,
    _first_event,
    _journal_branches,
    _reach_from,
    _rescale,
    _smallest_step_limit,
    _step_limit,
    _switch_window,
)
from mech_regulator.solvers.compiled.steps import (
    _DOP853,
    _RK4,
    _RK45,
    _ROSENBROCK23,
    DOP853_A,
    MAX_FACTOR,
    MIN_FACTOR,
    RK45_A,
    SAFETY,
    _dense_coefficients,
    _derivatives,
    _error_norm,
    _initial_step,
    _rk4_step,
    _rk_step,
    _rosenbrock_step,
)
from mech_regulator.solvers.time_domain import GUARD_NODES, GUARD_TOLERANCE

numba_cache.install()  # before the first njit(cache=True): keyed on the package's source

REACHED, EVENT, WRAPPED, FAILED = 0, 1, 2, 3
NONFINITE, STEP_TOO_SMALL, TOO_MANY_STEPS, BLOWN_UP = 1, 2, 3, 4
FAILURES = {
    NONFINITE: "the state became non-finite",
    STEP_TOO_SMALL: "the step size fell below round-off",
    TOO_MANY_STEPS: "the step limit (max_steps) was reached",
    BLOWN_UP: "a speed went beyond MAX_SPEED",
}
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
