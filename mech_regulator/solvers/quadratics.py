"""The quadratics of the co-simulation's coupling (solvers/cosim.py): plain Python on floats, which numba compiles as
it is for the governor's speed pieces on the fast path (solvers/compiled/pieces.py), so that both paths work out the
same numbers in the same operations."""

from __future__ import annotations


def quadratic_through(duration: float, start: float, middle: float, end: float) -> tuple[float, float]:
    """(a, b) of the quadratic q(s) = start + a s + b s^2 with q(duration / 2) = middle and q(duration) = end
    (duration [s] > 0)."""
    b = 2.0 * (end - 2.0 * middle + start) / (duration * duration)
    return (end - start) / duration - b * duration, b


def speed_load_line(a: float, b: float, t_start: float) -> tuple[float, float]:
    """The governor subsystem's input from t_start [s] on that makes its omega state follow the quadratic
    q(s) = omega_start + a s + b s^2, s = t - t_start (a [rad/s^2], b [rad/s^3]: quadratic_through's, through the
    machine's speeds): on its unit free inertia omega' = -L(t), so L(t) = -(a + 2 b s), an external load line
    offset + slope t, returned as (offset [N m], slope [N m/s]) (cosim.speed_waveform's LoadPiece)."""
    return -a + 2.0 * b * t_start, -2.0 * b
