"""How a governed machine answers the scenario's load changes: peak speed deviation, settling time,
overshoot, new steady speed and static error, and whether the governor saturated or hit a stop.

Speeds are cycle means, omega_bar(t) = Phi / (time the crank took for the last dynamic period Phi), so
the speed fluctuation inside a cycle (the flywheel's business) does not count as regulation error.
A machine with nothing periodic in phi uses omega itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from mech_regulator.analysis.stability import is_periodic
from mech_regulator.analysis.statics import operating_point
from mech_regulator.model import MachineModel
from mech_regulator.solvers import Trajectory

THROTTLE_LIMIT = 1e-9  # a throttle this close to 0 or 1 counts as saturated
GRID_PER_CYCLE = 400  # samples per dynamic period for reading the time a cycle took
CYCLE_CHUNK = 100_000  # times whose cycle-mean speed is worked out at once (its grid covers their span only)
MAX_RESPONSE_SAMPLES = 1_000_000  # samples of a load change's window at most: its sample rate, fewer for a window
# longer than 500 s at 2000 Hz (the cycle-mean speed is smooth within a cycle), so memory stays bounded
WINDOW_CHUNK_SPAN = 50.0  # s: a load change's window is read CYCLE_CHUNK times at a time, at most this long a stretch
# (a streamed run keeps the dense output of the chunk it has not read, analysis/stream.py)


def cycle_mean_speed(model: MachineModel, trajectory: Trajectory, times: np.ndarray) -> np.ndarray:
    """Cycle-mean crank speed [rad/s] at each time: Phi / (t - t(phi(t) - Phi)), where t(phi) is read
    from the run sampled at GRID_PER_CYCLE points per dynamic period; NaN during the first cycle. For
    a machine with nothing periodic in phi, omega(t). The times are taken CYCLE_CHUNK at a time (_chunk_speed), so
    that memory does not grow with the run."""
    if not is_periodic(model):
        return trajectory(times)[1]
    speed = np.empty(np.size(times))
    for first in range(0, speed.size, CYCLE_CHUNK):
        speed[first : first + CYCLE_CHUNK] = _chunk_speed(
            model, trajectory, np.asarray(times[first : first + CYCLE_CHUNK])
        )
    return speed


def _chunk_speed(model: MachineModel, trajectory: Trajectory, chunk: np.ndarray) -> np.ndarray:
    """cycle_mean_speed of a periodic machine at one chunk of ascending times [s], from a grid from a dynamic period
    before its first time (period_before) to its last."""
    period = model.dynamic_period()
    start, end = period_before(trajectory, float(chunk.min()), period), float(chunk.max())
    turns = abs(trajectory(end)[0] - trajectory(start)[0]) / period
    grid = np.linspace(start, end, max(2000, int(GRID_PER_CYCLE * turns)))
    phi = np.maximum.accumulate(trajectory(grid)[0])  # the angle of a turning crank; flat where it stops
    earlier = np.interp(trajectory(chunk)[0] - period, phi, grid, left=math.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        return period / (chunk - earlier)


def period_before(trajectory: Trajectory, t: float, period: float) -> float:
    """A time [s] at which the crank was at least `period` [rad] behind its angle at t [s] (spans back from t
    doubled from the time a period takes at t's speed), or the start of what the trajectory holds (t_kept: the run's
    start unless streamed) when it never was."""
    phi, omega = trajectory(t)[:2]
    span = period / max(abs(omega), 1e-12)
    while t - span > trajectory.t_kept:
        if trajectory(t - span)[0] <= phi - period:
            return t - span
        span *= 2.0
    return trajectory.t_kept


@dataclass(frozen=True)
class LoadResponse:
    """The answer to one load change (all speeds cycle means).

    time [s] the change starts; load_before, load_after [N m]; speed_before [rad/s] at the change;
    peak_deviation [rad/s] (signed, largest |speed - speed_before|) at peak_time [s after the change];
    speed_after [rad/s] at the end of the window (next change or end of run); static_error =
    speed_after - speed_before [rad/s]; predicted_static_error from the statics [rad/s];
    settling_time [s after the change] when the speed enters and stays within the settling band around
    the new steady speed the statics predict (around speed_after if the governor is saturated there);
    None if it had not settled by the end of the window; overshoot [%] past that speed relative to the
    peak's distance from it; limits: stops and saturations met in the window.
    """

    time: float
    load_before: float
    load_after: float
    speed_before: float
    peak_deviation: float
    peak_time: float
    speed_after: float
    static_error: float
    predicted_static_error: float
    settling_time: float | None
    overshoot: float
    limits: list[str] = field(default_factory=list)


@dataclass
class ResponseWindow:
    """One load change's window (the change `index` of the scenario) as it is read: its sample times [s], and the
    cycle-mean speed [rad/s] and the governor's throttle [-] at the first `done` of them."""

    index: int
    times: np.ndarray
    speed: np.ndarray
    throttle: np.ndarray
    done: int = 0

    def read(self, model: MachineModel, trajectory: Trajectory, t_until: float = math.inf) -> None:
        """Read the times CYCLE_CHUNK at a time (as cycle_mean_speed does) and WINDOW_CHUNK_SPAN long at most, each
        chunk whose last time is at most t_until [s] and at most the trajectory's end."""
        governor = model.governor
        assert governor is not None, "a load change's window is read for a governed run (load_responses)"
        while self.done < self.times.size:
            span_end = int(np.searchsorted(self.times, self.times[self.done] + WINDOW_CHUNK_SPAN, side="right"))
            chunk = self.times[self.done : min(self.done + CYCLE_CHUNK, span_end)]
            if chunk[-1] > min(t_until, trajectory.t_end):
                break
            states = trajectory(chunk)
            part = slice(self.done, self.done + chunk.size)
            self.speed[part] = _chunk_speed(model, trajectory, chunk) if is_periodic(model) else states[1]
            self.throttle[part] = [governor.throttle(states[:, i]) for i in range(chunk.size)]
            self.done += chunk.size

    def cut(self, t_end: float) -> None:
        """Keep only the times up to t_end [s] (a run that ended before the window's planned end)."""
        keep = int(np.searchsorted(self.times, t_end, side="right"))
        self.times, self.speed, self.throttle = self.times[:keep], self.speed[:keep], self.throttle[:keep]
        self.done = min(self.done, keep)


def response_windows(model: MachineModel, t_end: float, sample_rate: float = 2000.0) -> list[ResponseWindow]:
    """The windows of the scenario's load changes that start before t_end [s], none read yet: each from its change to
    the next change or the scenario's end, cut at t_end, sampled at sample_rate [Hz] (at least 50 samples, at most
    MAX_RESPONSE_SAMPLES)."""
    scenario = model.scene.scenario
    events = scenario.load_events
    windows = []
    for index, event in enumerate(events):
        start = event.time
        end = min(events[index + 1].time if index + 1 < len(events) else scenario.duration, t_end)
        if end <= start:
            break
        times = np.linspace(start, end, min(max(int((end - start) * sample_rate), 50), MAX_RESPONSE_SAMPLES) + 1)
        windows.append(ResponseWindow(index, times, np.empty(times.size), np.empty(times.size)))
    return windows


def load_responses(
    model: MachineModel, trajectory: Trajectory, windows: list[ResponseWindow] | None = None
) -> list[LoadResponse]:
    """Analyse every load event of the scenario that the trajectory reached, but one within the run's first dynamic
    cycle: there is no cycle-mean speed before it (cycle_mean_speed is NaN there), so it has no response to measure.
    windows: those a streamed run read in part already (response_windows of its planned end), else all afresh."""
    band = model.scene.analysis.settling_band
    responses = []
    scenario = model.scene.scenario
    loads = [scenario.external_load] + [event.torque for event in scenario.load_events]
    for window in response_windows(model, trajectory.t_end) if windows is None else windows:
        window.cut(trajectory.t_end)
        if window.times.size == 0 or window.times[-1] <= window.times[0]:
            break
        window.read(model, trajectory)
        index, times, speed = window.index, window.times, window.speed
        start, end = float(times[0]), float(times[-1])
        if math.isnan(speed[0]):  # within the first cycle: no speed before the change to measure from
            continue
        before = speed[0]
        after = speed[-1]
        deviation = speed - before
        peak = int(np.nanargmax(np.abs(deviation)))
        old_point, new_point = operating_point(model, loads[index]), operating_point(model, loads[index + 1])
        target = after if new_point.limited else new_point.speed
        from_final = speed - target
        outside = np.nonzero(np.abs(from_final) > band * abs(target))[0]
        last_cycle = model.dynamic_period() / max(abs(after), 1e-12)
        settled = outside.size == 0 or times[outside[-1]] < end - last_cycle
        settling = (times[outside[-1]] - start if outside.size else 0.0) if settled else None
        direction = math.copysign(1.0, from_final[peak]) if from_final[peak] != 0.0 else 1.0
        overshoot = max(0.0, float(np.nanmax(-direction * from_final[peak:])))
        overshoot_percent = 100.0 * overshoot / abs(from_final[peak]) if from_final[peak] != 0.0 else 0.0
        predicted = new_point.speed - old_point.speed
        responses.append(
            LoadResponse(
                time=start,
                load_before=loads[index],
                load_after=loads[index + 1],
                speed_before=float(before),
                peak_deviation=float(deviation[peak]),
                peak_time=float(times[peak] - start),
                speed_after=float(after),
                static_error=float(after - before),
                predicted_static_error=float(predicted),
                settling_time=None if settling is None else float(settling),
                overshoot=overshoot_percent,
                limits=_limits(trajectory, start, end, window.throttle),
            )
        )
    return responses


def _limits(trajectory: Trajectory, start: float, end: float, throttle: np.ndarray) -> list[str]:
    """Stops of the governor within [start, end] [s] (its mode log) and saturations of its throttle [-] there."""
    found: list[str] = []
    names = {"low": "on its low stop", "high": "on its high stop"}
    spans = [(t, mode) for t, mode in trajectory.modes if t < end]
    for position, (_, mode) in enumerate(spans):
        t_next = spans[position + 1][0] if position + 1 < len(spans) else end
        if t_next <= start:
            continue
        for part, label in zip(mode, ("sleeve", "servo")):
            if part in names and f"{label} {names[part]}" not in found:
                found.append(f"{label} {names[part]}")
    if np.any(throttle >= 1.0 - THROTTLE_LIMIT):
        found.append("throttle fully open")
    if np.any(throttle <= THROTTLE_LIMIT):
        found.append("throttle closed")
    return found
