"""Speed over the dynamic period: steady-state detection and the coefficient of speed fluctuation.

docs/theory.md §2.5 and §3.1: the dynamic period Phi_omega = lcm(kinematic period, work period) in phi;
over one period `delta = (omega_max - omega_min) / omega_m` with `omega_m = (omega_max + omega_min) / 2`.
Steady (periodic) motion: omega at the start of successive dynamic periods repeats. Its mean speed, when the
moments read omega, is where the cycle-mean moments balance (model/steady.py, balance_speed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from mech_regulator.model import MachineModel
from mech_regulator.solvers import Trajectory

SAMPLES_PER_PERIOD = 200
MAX_PERIODS = 10_000  # dynamic periods examined for repetition (the last ones of a longer run): each start is located
# on the dense output, and a run of millions of periods would take minutes (or not fit in memory)


@dataclass(frozen=True)
class PeriodSpeeds:
    """Speeds over one dynamic period [t_start, t_end] [s]: extrema located on the dense output [rad/s],
    omega_m = (max + min) / 2, delta = (max - min) / omega_m, omega_average = Phi / (t_end - t_start)."""

    t_start: float
    t_end: float
    omega_start: float
    omega_max: float
    omega_min: float
    omega_m: float
    delta: float
    omega_average: float


@dataclass(frozen=True)
class SteadyState:
    """Whether the motion became periodic, from when, and the speeds over the last complete period.

    steady: True/False, or None when too few periods were simulated to judge; t_steady: start of the
    first period from which omega repeats within the tolerance; note: why not steady, if not.
    """

    steady: bool | None
    t_steady: float | None
    period: float
    periods: int
    last: PeriodSpeeds | None
    note: str


def analyse_steady_state(
    model: MachineModel, trajectory: Trajectory, tolerance: float | None = None, stopped_at: float | None = None
) -> SteadyState:
    """Split the run after the last load change into dynamic periods (at most its last MAX_PERIODS; of a streamed
    run, those its trajectory still holds, analysis/stream.py) and test them for repetition. stopped_at: the first
    time [s] after the last load change at which a streamed run found omega <= 0 in what it dropped, if any."""
    tolerance = tolerance if tolerance is not None else model.scene.analysis.steady_tolerance
    period = model.dynamic_period()
    t_from = steady_from(model)
    t_to = trajectory.t_end
    if t_to <= t_from:
        return SteadyState(None, None, period, 0, None, "the run ends before the last load change")
    if stopped_at is not None:
        return _stopped(period, stopped_at)
    t_from = max(t_from, trajectory.t_kept)
    phi_from, phi_to = trajectory(np.array([t_from, t_to]))[0]
    count = int(min(2_000_000, max(4000, SAMPLES_PER_PERIOD * abs(phi_to - phi_from) / period)))
    times = np.linspace(t_from, t_to, count)
    phi, omega = trajectory(times)[:2]
    if np.any(omega[1:] <= 0.0):  # a start from rest is not a stop
        return _stopped(period, times[1 + np.argmax(omega[1:] <= 0.0)])
    # Periods start at whole multiples of Phi_omega, so each one begins at the same phase of the cycle
    # (for an engine: cycle angle 0 at phi = 0).
    last_level = math.floor(phi[-1] / period)
    levels = period * np.arange(max(math.ceil(phi[0] / period), last_level - MAX_PERIODS), last_level + 1)
    starts = np.array([_time_at_angle(trajectory, times, phi, level) for level in levels])
    periods = max(starts.size - 1, 0)
    if periods < 1:
        return SteadyState(
            None, None, period, 0, None, "less than one dynamic period simulated after the last load change"
        )
    last = _period_speeds(trajectory, starts[-2], starts[-1], period)
    if periods < 2:
        return SteadyState(None, None, period, periods, last, "only one dynamic period simulated: too short to judge")
    omega_starts = trajectory(starts)[1]
    repeats = np.abs(np.diff(omega_starts)) <= tolerance * last.omega_m
    if not repeats[-1]:
        change = abs(omega_starts[-1] - omega_starts[-2]) / last.omega_m
        return SteadyState(
            False,
            None,
            period,
            periods,
            last,
            f"omega still changes by {change:.3g} of omega_m per dynamic period (tolerance {tolerance:g})",
        )
    first = periods - 1
    while first > 0 and repeats[first - 1]:
        first -= 1
    return SteadyState(True, float(starts[first]), period, periods, last, "")


def steady_from(model: MachineModel) -> float:
    """Where the steady-state analysis starts [s]: the last load change (0 without one)."""
    return max([0.0] + [piece.start for piece in model.load_pieces])


def _stopped(period: float, t_stop: float) -> SteadyState:
    """The verdict on a run whose machine stops or turns back at t_stop [s]: not steady."""
    return SteadyState(
        False, None, period, 0, None, f"the machine stops or turns back (omega <= 0 at t = {t_stop:.6g} s)"
    )


def _time_at_angle(trajectory: Trajectory, times: np.ndarray, phi: np.ndarray, level: float) -> float:
    """Time at which the (increasing) crank angle reaches level, by Brent's method on the dense output."""
    i = int(np.searchsorted(phi, level))
    lo, hi = times[max(i - 1, 0)], times[min(i, times.size - 1)]
    if lo == hi:
        return float(lo)
    return optimize.brentq(lambda t: trajectory(t)[0] - level, lo, hi, xtol=1e-14)


def _period_speeds(trajectory: Trajectory, t_start: float, t_end: float, period: float) -> PeriodSpeeds:
    """Extreme speeds in [t_start, t_end], refined from a sampled guess by bounded scalar minimisation."""
    times = np.linspace(t_start, t_end, 2001)
    omega = trajectory(times)[1]
    omega_max = _refine(trajectory, times, int(np.argmax(omega)), sign=-1.0)
    omega_min = _refine(trajectory, times, int(np.argmin(omega)), sign=1.0)
    omega_m = 0.5 * (omega_max + omega_min)
    return PeriodSpeeds(
        t_start,
        t_end,
        float(omega[0]),
        omega_max,
        omega_min,
        omega_m,
        (omega_max - omega_min) / omega_m,
        period / (t_end - t_start),
    )


def _refine(trajectory: Trajectory, times: np.ndarray, index: int, sign: float) -> float:
    """Local extremum of omega near times[index] (sign -1 for a maximum, +1 for a minimum) [rad/s].

    Minimised over tau = t - lo, so the tolerance is relative to the bracket, not to the run's time."""
    lo, hi = times[max(index - 1, 0)], times[min(index + 1, times.size - 1)]
    sampled = trajectory(times[index])[1]
    result = optimize.minimize_scalar(
        lambda tau: sign * trajectory(lo + tau)[1],
        bounds=(0.0, hi - lo),
        method="bounded",
        options={"xatol": 1e-10 * (hi - lo)},
    )
    refined = sign * result.fun
    return float(refined if sign * refined < sign * sampled else sampled)
