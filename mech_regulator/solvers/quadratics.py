"""The quadratics of the co-simulation's coupling (solvers/cosim.py): plain Python on floats and arrays, which numba
compiles as it is on the fast path (solvers/compiled/pieces.py: the governor's speed pieces, the machine's speed
samples and its prediction one cycle back), so that both paths work out the same numbers in the same operations."""

from __future__ import annotations

import math

import numpy as np


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


def speed_samples_times(t_start: float, t_end: float, longest: float) -> np.ndarray:
    """The times [s] at which the co-simulation samples the machine's speed over [t_start, t_end] [s]
    (cosim.speed_samples): 2 m + 1 evenly spaced, both ends included, m the fewest pieces no longer than `longest` [s];
    np.linspace's numbers in its operations (the step numbers times the spacing, plus t_start, the last t_end) without
    its set-up, which cost as much as the rest of a speed sample (docs/speed.md, "A sixth sitting")."""
    count = 2 * max(1, math.ceil((t_end - t_start) / longest - 1e-9)) + 1
    spacing = (t_end - t_start) / (count - 1)
    times = np.empty(count)
    for k in range(count - 1):
        times[k] = k * spacing + t_start
    times[count - 1] = t_end
    return times


def speeds_one_cycle_back(
    kept: np.ndarray, t_start: float, t_end: float, longest: float, back: float, omega: float
) -> tuple[np.ndarray, np.ndarray]:
    """The machine's speed over [t_start, t_end] [s] predicted one cycle of the crank back (cosim.MachineStepper's
    _cycle_back): at the times cosim.speed_samples takes (speed_samples_times, pieces no longer than `longest` [s]),
    omega + q(t - back) - q(t_start - back), omega [rad/s] the speed at t_start, back [s] the time one cycle back, q
    the kept speed: kept's rows are times [s] and speeds [rad/s], the samples of consecutive steps one after the
    other, each step's an odd number with its last repeated (so that every piece starts at an even column), q on a
    piece the quadratic through its three samples (quadratic_through), the first and the last piece continued beyond
    the ends. Returns (times [s], speeds [rad/s])."""
    times = speed_samples_times(t_start, t_end, longest)
    speeds = np.empty(times.size)
    starts = kept[0, ::2]  # the pieces' starts [s], and each step's end repeated: a piece of no length, never taken
    first = 0.0  # q(t_start - back)
    for k in range(times.size):
        before = times[k] - back
        at = 2 * min(max(np.searchsorted(starts, before, side="right") - 1, 0), starts.size - 2)  # the piece's column
        a, b = quadratic_through(kept[0, at + 2] - kept[0, at], kept[1, at], kept[1, at + 1], kept[1, at + 2])
        elapsed = before - kept[0, at]
        value = kept[1, at] + elapsed * (a + elapsed * b)
        if k == 0:
            first = value
        speeds[k] = omega + value - first
    return times, speeds
