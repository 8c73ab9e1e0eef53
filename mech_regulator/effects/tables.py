"""Tabulated characteristics evaluated in the hot path: periodic and clamped piecewise-linear tables.

`np.interp` does the same for arrays; these closures do it for one scalar per call without array
allocation, which matters because they run on every right-hand-side evaluation.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Sequence


def periodic_linear(xs: Sequence[float], ys: Sequence[float], period: float) -> Callable[..., float]:
    """Return y(x, anchor=None): linear between the points, periodic with `period`, wrapping from the last point to
    the first plus one period (equals np.interp(x, xs, ys, period=period)); with an anchor, the line of the segment
    that holds the anchor, continued to x: y(anchor) + slope (x - anchor) (a solver between two knots sees a smooth
    function, its kink only once it restarts on the knot)."""
    x0 = xs[0]
    knots = [x - x0 for x in xs] + [period]
    values = list(ys) + [ys[0]]
    slopes = [(values[i + 1] - values[i]) / (knots[i + 1] - knots[i]) for i in range(len(xs))]

    def table(x: float, anchor: float | None = None) -> float:
        at = x if anchor is None else anchor
        u = math.fmod(at - x0, period)
        if u < 0.0:
            u += period
        i = bisect.bisect_right(knots, u) - 1
        if i >= len(slopes):  # u rounded up to exactly one period
            i = len(slopes) - 1
        return values[i] + slopes[i] * (u - knots[i] + (x - at))

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
    """Return y(x, anchor=None): linear between the points, constant beyond the first and last (as np.interp); with an
    anchor, the piece (a segment, or a constant end) that holds the anchor, continued to x (as periodic_linear's); an
    anchor on an end point holds the end segment (a slider at a dead centre that touches the table's end)."""
    knots, values = list(xs), list(ys)
    slopes = [(values[i + 1] - values[i]) / (knots[i + 1] - knots[i]) for i in range(len(knots) - 1)]
    last = len(slopes) - 1

    def table(x: float, anchor: float | None = None) -> float:
        at = x if anchor is None else anchor
        if at < knots[0]:
            return values[0]
        if at > knots[-1]:
            return values[-1]
        i = min(bisect.bisect_right(knots, at) - 1, last)
        return values[i] + slopes[i] * (x - knots[i])

    return table


def extrapolated_linear(xs: Sequence[float], ys: Sequence[float]) -> Callable[..., float]:
    """Return y(x, anchor=None): linear between the points, the first and last segments continued beyond the ends
    (a characteristic that keeps its end slopes); with an anchor, the segment that holds the anchor, continued to x
    (as periodic_linear's)."""
    knots, values = list(xs), list(ys)
    slopes = [(values[i + 1] - values[i]) / (knots[i + 1] - knots[i]) for i in range(len(knots) - 1)]
    last = len(slopes) - 1

    def table(x: float, anchor: float | None = None) -> float:
        i = min(max(bisect.bisect_right(knots, x if anchor is None else anchor) - 1, 0), last)
        return values[i] + slopes[i] * (x - knots[i])

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
    """Return inside(x): 1.0 while x mod period lies in one of the intervals [edges[2k], edges[2k+1]), else 0.0 (the
    edges from 0, ascending, within one period)."""
    bounds = list(edges)

    def inside(x: float) -> float:
        u = math.fmod(x, period)
        if u < 0.0:
            u += period
        return 1.0 if bisect.bisect_right(bounds, u) % 2 == 1 else 0.0

    return inside
