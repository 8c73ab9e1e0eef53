"""Tabulated characteristics evaluated in the hot path: periodic, clamped and extrapolated piecewise-linear tables,
interval tables and the held pieces of a slider table; each lookup defined once for both paths (docs/effects.md).

A lookup is a plain function of floats over a flat sequence `p` that holds the table at p[offset:] (xs at
p[offset : offset + n], ys at p[offset + n : offset + 2 n]): no closures, no Python objects, no calls but `math`'s,
as effects/definition.py asks of a formula (an angle is wrapped with Python's `%`, which numba computes alike; the
segment is found by bisection). The reference path calls it over a list of the table's points (the closures below:
`np.interp` for one scalar, without array allocation, as they run on every right-hand-side evaluation); the fast
path compiles it unchanged with numba (solvers/compiled/kernels.py) and calls it over its parameter vector, so both
paths do the same arithmetic and agree bit for bit (test/test_effect_definitions.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence


def periodic_value(x: float, anchor: float, p, offset: int, n: int, period: float) -> float:
    """y(x) linear between the n points, periodic with `period`, the last point joined to the first plus one period
    (np.interp(x, xs, ys, period=period)), here the line of the segment that holds `anchor` continued to x
    (anchor = x: the table itself) [units of y]."""
    x0 = p[offset]
    u = (anchor - x0) % period
    i, last = 0, n - 1  # bisect for the last knot at or below u (u rounded up to one period: the last segment)
    while i < last:
        middle = (i + last + 1) // 2
        if p[offset + middle] - x0 > u:
            last = middle - 1
        else:
            i = middle
    lo = p[offset + i] - x0
    y_lo = p[offset + n + i]
    if i + 1 < n:
        hi, y_hi = p[offset + i + 1] - x0, p[offset + n + i + 1]
    else:
        hi, y_hi = period, p[offset + n]
    return y_lo + (y_hi - y_lo) / (hi - lo) * (u - lo + (x - anchor))


def clamped_value(x: float, anchor: float, p, offset: int, n: int) -> float:
    """y(x) linear between the n points, held at the end values beyond them; with an anchor (not NaN), the piece
    (a segment, or a constant end) that holds the anchor continued to x; an anchor on an end point holds the end
    segment (a slider at a dead centre that touches the table's end) [units of y]."""
    at = x if math.isnan(anchor) else anchor
    if at < p[offset]:
        return p[offset + n]
    if at > p[offset + n - 1]:
        return p[offset + 2 * n - 1]
    i, last = 0, n - 2  # bisect for the last knot at or below at, the end segment's at the last knot
    while i < last:
        middle = (i + last + 1) // 2
        if p[offset + middle] > at:
            last = middle - 1
        else:
            i = middle
    return p[offset + n + i] + (p[offset + n + i + 1] - p[offset + n + i]) / (p[offset + i + 1] - p[offset + i]) * (
        x - p[offset + i]
    )


def extrapolated_value(x: float, anchor: float, p, offset: int, n: int) -> float:
    """y(x) linear between the n points, the first and last segments continued beyond the ends (a characteristic
    that keeps its end slopes); with an anchor (not NaN), the segment that holds the anchor continued to x
    [units of y]."""
    at = x if math.isnan(anchor) else anchor
    i, last = 0, n - 2  # bisect for the last knot at or below at (the first segment below the first knot)
    while i < last:
        middle = (i + last + 1) // 2
        if p[offset + middle] > at:
            last = middle - 1
        else:
            i = middle
    return p[offset + n + i] + (p[offset + n + i + 1] - p[offset + n + i]) / (p[offset + i + 1] - p[offset + i]) * (
        x - p[offset + i]
    )


def interval_value(x: float, p, offset: int, n: int, period: float) -> float:
    """1.0 while x mod period lies in one of the intervals [e_2k, e_2k+1) of the n edges at p[offset : offset + n]
    (from 0, ascending, within one period), else 0.0."""
    u = x % period
    count, end = 0, n  # bisect_right(edges, u)
    while count < end:
        middle = (count + end) // 2
        if p[offset + middle] <= u:
            count = middle + 1
        else:
            end = middle
    return 1.0 if count % 2 == 1 else 0.0


def held_value(anchor: float, p, offset: int, n: int) -> float:
    """The value held on the interval between two kinks that holds anchor mod period: the n - 1 kinks, sorted in
    [0, period), at p[offset:], then the period, then the n values after them (effects.held_positions: a slider
    table's held positions [m], indexed by bisect_right(kinks, anchor mod period))."""
    period = p[offset + n - 1]
    u = anchor % period
    j, end = 0, n - 1  # bisect_right(kinks, u)
    while j < end:
        middle = (j + end) // 2
        if p[offset + middle] <= u:
            j = middle + 1
        else:
            end = middle
    return p[offset + n + j]


def _points(*columns: Sequence[float]) -> list[float]:
    """The columns of a table one after the other as Python floats: the `p` of a lookup, at offset 0."""
    return [float(value) for column in columns for value in column]


def periodic_linear(xs: Sequence[float], ys: Sequence[float], period: float) -> Callable[..., float]:
    """Return y(x, anchor=None): periodic_value of the points (xs increasing, within one period from xs[0]); with an
    anchor, the line of the segment that holds the anchor, continued to x (a solver between two knots sees a smooth
    function, its kink only once it restarts on the knot)."""
    points, n = _points(xs, ys), len(xs)

    def table(x: float, anchor: float | None = None) -> float:
        return periodic_value(x, x if anchor is None else anchor, points, 0, n, period)

    return table


def periodic_kinks(xs: Sequence[float], ys: Sequence[float], period: float) -> tuple[float, ...]:
    """The knots of periodic_linear(xs, ys, period) where its slope changes (by more than round-off, 1e-12 of the
    slopes), in [0, period) [units of x]."""
    n = len(xs)
    knots = list(xs) + [xs[0] + period]
    values = list(ys) + [ys[0]]
    slopes = [(values[i + 1] - values[i]) / (knots[i + 1] - knots[i]) for i in range(n)]
    return tuple(
        sorted(
            {
                xs[i] % period
                for i in range(n)
                if abs(slopes[i] - slopes[i - 1]) > 1e-12 * max(abs(slopes[i]), abs(slopes[i - 1]))
            }
        )
    )


def clamped_linear(xs: Sequence[float], ys: Sequence[float]) -> Callable[..., float]:
    """Return y(x, anchor=None): clamped_value of the points (xs increasing), as np.interp; with an anchor, the piece
    that holds the anchor, continued to x."""
    points, n = _points(xs, ys), len(xs)

    def table(x: float, anchor: float | None = None) -> float:
        return clamped_value(x, math.nan if anchor is None else anchor, points, 0, n)

    return table


def extrapolated_linear(xs: Sequence[float], ys: Sequence[float]) -> Callable[..., float]:
    """Return y(x, anchor=None): extrapolated_value of the points (xs increasing); with an anchor, the segment that
    holds the anchor, continued to x."""
    points, n = _points(xs, ys), len(xs)

    def table(x: float, anchor: float | None = None) -> float:
        return extrapolated_value(x, math.nan if anchor is None else anchor, points, 0, n)

    return table


def slope_breaks(xs: Sequence[float], ys: Sequence[float], ends: bool) -> tuple[float, ...]:
    """The points of a piecewise-linear table (xs increasing) where its slope changes (by more than round-off, 1e-12
    of the slopes): the interior points, and with `ends` (a table held constant beyond its ends, clamped_linear) also
    the end points next to a sloped segment [units of x]."""
    slopes = [0.0] + [(ys[i + 1] - ys[i]) / (xs[i + 1] - xs[i]) for i in range(len(xs) - 1)] + [0.0]
    return tuple(
        x
        for i, x in enumerate(xs)
        if (ends or 0 < i < len(xs) - 1)
        and abs(slopes[i + 1] - slopes[i]) > 1e-12 * max(abs(slopes[i + 1]), abs(slopes[i]))
    )


def interval_indicator(edges: Sequence[float], period: float) -> Callable[[float], float]:
    """Return inside(x): interval_value of the edges (from 0, ascending, within one period): 1.0 while x mod period
    lies in one of the intervals [edges[2k], edges[2k+1]), else 0.0."""
    points, n = _points(edges), len(edges)

    def inside(x: float) -> float:
        return interval_value(x, points, 0, n, period)

    return inside


def held_lookup(kinks: Sequence[float], period: float, values: Sequence[float]) -> Callable[[float], float]:
    """Return held(anchor): held_value of the kinks (sorted, in [0, period) [rad]) and the values held on the
    intervals between them (one more than the kinks, the interval across 0 first and last)."""
    points, n = _points(kinks, [period], values), len(kinks) + 1

    def held(anchor: float) -> float:
        return held_value(anchor, points, 0, n)

    return held
