"""A cam follower's motion law over the cam's turn (docs/theory.md §5.7): its displacement s(theta) and the first
and second derivatives s', s'' with respect to the cam angle theta, from segments (rise, dwell, return) or a table.

A segment of angle beta [rad] with lift h moves the follower by h f(x), x = (theta - theta_start) / beta in [0, 1],
f one of the normalised laws below (CODES) (f(0) = 0, f(1) = 1), so that `s = s_start +- h f(x)`, `s' = +-h f'(x) / beta`,
`s'' = +-h f''(x) / beta^2` (+ rise, - return; a dwell keeps s_start):
- uniform:     f = x,                          f' = 1,               f'' = 0 (infinite acceleration at its ends);
- harmonic:    f = (1 - cos(pi x)) / 2,        f' = pi/2 sin(pi x),  f'' = pi^2/2 cos(pi x);
- cycloidal:   f = x - sin(2 pi x) / (2 pi),   f' = 1 - cos(2 pi x), f'' = 2 pi sin(2 pi x);
- polynomial_345: f = 10 x^3 - 15 x^4 + 6 x^5, f' = 30 x^2 (1 - x)^2, f'' = 60 x (1 - x) (1 - 2 x).
A table law is a periodic cubic spline through the given (theta, s) points (its s', s'' the spline's).
The lift is in metres for a translating follower and in radians for an oscillating one. A law is kept as pieces
(`pieces`), which linkage/flat.py's law_at evaluates: the one implementation both solver paths and this module run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mech_regulator.mechanisms.linkage.flat_positions import law_at

TWO_PI = 2.0 * math.pi
CODES = {"dwell": 0.0, "uniform": 1.0, "harmonic": 2.0, "cycloidal": 3.0, "polynomial_345": 4.0, "cubic": 5.0}
TURN_TOLERANCE = 1e-9  # how far the segments' angles may sum away from a full turn [rad]


@dataclass(frozen=True)
class Segment:
    """One part of the turn: motion (rise, dwell, return), law (LAWS; none for a dwell), angle [rad], lift (the
    follower's travel over the segment [m or rad], positive; 0 for a dwell)."""

    motion: str
    angle: float
    law: str = "uniform"
    lift: float = 0.0


class MotionLaw:
    """s(theta), s'(theta), s''(theta) of a follower (module docstring), theta the cam angle from the law's start
    [rad] (any value: taken modulo the turn), from its pieces."""

    _pieces: list[list[float]]  # set by each kind of law (pieces())

    def pieces(self) -> list[list[float]]:
        """The law as flat_positions.law_at's pieces [start, length, code, a, b, c, d], in order of start from 0 to
        the turn."""
        return self._pieces

    def kinks(self) -> np.ndarray:
        """The cam angles [rad] in [0, 2 pi) where a piece starts (where s'' may jump)."""
        return np.array([piece[0] for piece in self._pieces])

    def evaluate(self, theta) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(s, s', s'') at the cam angles theta [rad]: [m, m/rad, m/rad^2] or [rad, -, 1/rad]
        (flat_positions.law_at)."""
        program = np.array([float(len(self._pieces))] + [v for piece in self._pieces for v in piece])
        theta = np.atleast_1d(np.asarray(theta, dtype=float))
        values = np.array([law_at(angle, program, 0) for angle in theta.ravel()]).reshape(theta.shape + (3,))
        return values[..., 0], values[..., 1], values[..., 2]


class SegmentLaw(MotionLaw):
    """A law of segments that fill the turn in order from theta = 0, the follower back at s = 0 after the last."""

    def __init__(self, segments: tuple[Segment, ...]):
        total = sum(segment.angle for segment in segments)
        if abs(total - TWO_PI) > TURN_TOLERANCE:
            raise ValueError(
                f"the follower law's segments span {math.degrees(total):.6g} deg; expected 360 deg "
                "(one turn of the cam)"
            )
        heights = np.cumsum([0.0] + [_signed_lift(segment) for segment in segments])
        scale = max(1.0, float(np.max(np.abs(heights))))
        if abs(heights[-1]) > 1e-12 * scale:
            raise ValueError(
                f"the follower law rises {sum(s.lift for s in segments if s.motion == 'rise'):.6g} "
                f"but returns {sum(s.lift for s in segments if s.motion == 'return'):.6g} over the turn; "
                "expected the returns to bring the follower back to where it started"
            )
        if np.min(heights) < -1e-12 * scale:
            raise ValueError(
                "the follower law returns below its start (s < 0); expected s >= 0 over the turn, "
                "s = 0 on the base circle"
            )
        starts = np.cumsum([0.0] + [segment.angle for segment in segments[:-1]])
        self._pieces = [
            [
                float(start),
                segment.angle,
                CODES["dwell" if segment.motion == "dwell" else segment.law],
                float(height),
                _signed_lift(segment),
                0.0,
                0.0,
            ]
            for start, segment, height in zip(starts, segments, heights)
        ]


class TableLaw(MotionLaw):
    """A periodic cubic spline through (theta_k, s_k) [rad, m or rad] (scipy's CubicSpline, periodic over the
    turn), s >= 0; its pieces are the spline's cubics, the one across theta = 0 split there."""

    def __init__(self, angles: list[float] | np.ndarray, lifts: list[float]):
        from scipy.interpolate import CubicSpline

        angles = np.asarray(angles, dtype=float)
        if np.any(np.diff(angles) <= 0.0) or angles[-1] - angles[0] >= TWO_PI:
            raise ValueError("the follower table's angles must increase strictly within one turn (360 deg)")
        if min(lifts) < 0.0:
            raise ValueError(
                f"the follower table's lift has {min(lifts):.6g} < 0; expected s >= 0 (s = 0 on the base circle)"
            )
        knots = np.append(angles, angles[0] + TWO_PI)
        spline = CubicSpline(knots, list(lifts) + [lifts[0]], bc_type="periodic")
        starts = np.mod(angles, TWO_PI)
        if starts[0] != 0.0 or np.any(np.diff(starts) < 0.0):  # the piece across theta = 0 starts again at 0
            starts = np.sort(np.append(starts, 0.0))
        ends = np.append(starts[1:], TWO_PI)
        self._pieces = []
        for start, end in zip(starts, ends):
            at = angles[0] + np.mod(start - angles[0], TWO_PI)  # the same angle on the spline's domain
            a, b, c, d = (float(spline(at, order)) / math.factorial(order) for order in range(4))
            self._pieces.append([float(start), float(end - start), CODES["cubic"], a, b, c, d])


def _signed_lift(segment: Segment) -> float:
    """The segment's change of s: +lift (rise), -lift (return), 0 (dwell)."""
    return {"rise": segment.lift, "return": -segment.lift, "dwell": 0.0}[segment.motion]
