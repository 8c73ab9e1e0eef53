"""Where a compiled step meets a guard, in the subset of Python numba compiles: the step's dense output, the first
crossing of a guard's threshold inside the step (exactly for a linear guard, by a polynomial with an error bound cut
into monotone pieces and Brent's method otherwise, as the reference path's time_domain._first_event) and the limit
the journals' branch points set on the next steps (docs/theory.md §6.5). integrators.py's docstring says the guards'
rows and flags."""

from __future__ import annotations

import numpy as np
from numba import njit, types

from mech_regulator import numba_cache
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

numba_cache.install()  # before the first njit(cache=True): keyed on the package's source

LINEAR, STEP_ONTO, NONLINEAR_ONTO = 1.0, 2.0, 3.0  # flags of guards with a row or a step onto (module docstring)


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


ROUND_OFF_ROOM = 1e-13  # of the sum of a polynomial's |coefficients|: far above its round-off on [0, 1]


@njit(cache=True)
def _stays_above(line, level):
    """Whether sum_j line[j] theta^j, evaluated anywhere on [0, 1], cannot come out below level [the guard's units],
    told from the coefficients alone (no roots): there theta^j <= theta for j >= 1, so the polynomial is at least the
    line from line[0] - level at theta = 0 to line[0] - level + line[1] - sum_{j >= 2} |line[j]| at 1; both ends at
    least ROUND_OFF_ROOM of the sum of |line[j]| and |level| above 0, far more than the round-off of Horner's scheme
    (about 2 x 7 eps of that sum) and of this sum. A guard that starts the step rising (line[1] > 0), as a switch
    window's edge behind the crank, is told apart at once; so is one that falls but ends the step clearly above."""
    tail = 0.0
    for j in range(2, line.size):
        tail += abs(line[j])
    room = ROUND_OFF_ROOM * (abs(level) + abs(line[0]) + abs(line[1]) + tail)
    start = line[0] - level
    return start >= room and start + line[1] - tail >= room


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
SWITCH_WINDOW_SIGNATURE = (types.float64[::1], types.float64, types.float64, types.boolean)
"""_switch_window's argument types as solvers/compiled/run.py calls it from Python: the grid, the period, phi, forward."""
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
def _monotone_pieces(line):
    """The polynomial sum_j line[j] theta^j cut into pieces monotone on (0, 1]: their upper ends, sorted, 1 last, as
    time_domain.monotone_ends gives them; but where its derivative cannot vanish on [0, 1] (|line[1]| above
    sum_{j >= 2} j |line[j]|, with ROUND_OFF_ROOM to spare) the one piece (0, 1], without the roots (most steps that
    reach a switch window's edge ahead of a turning crank). There monotone_ends would also cut at the real parts of
    complex roots, harmless cuts of a monotone piece that move where the crossing's bracket starts, and so the last
    bits of the crossing Brent's method finds, but never which crossing it finds."""
    tail = 0.0
    for j in range(2, line.size):
        tail += j * abs(line[j])
    if abs(line[1]) > tail * (1.0 + ROUND_OFF_ROOM) + ROUND_OFF_ROOM * abs(line[1]):
        return np.ones(1)
    return _monotone_ends(line)


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
    when g0 >= sum_j |a_j|, or when it is told above its threshold by _stays_above (a guard rising from the step's
    start, or ending it clearly above), it cannot fall below on [0, 1] and is done with at once (most steps, without
    the roots, which cost more than the rest of a step); else it is cut into monotone pieces (_monotone_pieces: the
    real parts of its derivative's roots in (0, 1), none where the derivative cannot vanish), so the first piece that
    ends below the
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
        if line[0] >= np.sum(np.abs(line[1:])) or _stays_above(line, 0.0):  # >= 0 on all of [0, 1]: no crossing
            continue
        lower = 0.0
        for upper in _monotone_pieces(line):
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
            if line[0] - margin >= np.sum(np.abs(line[1:])) or _stays_above(line, margin):  # above it on [0, 1]
                continue
            cuts = _monotone_pieces(line)
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
