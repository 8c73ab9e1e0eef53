"""Integration in time: scipy's adaptive OdeSolver classes (RK45, RK23, DOP853, Radau, BDF, LSODA)
stepped one step at a time, and the classic fixed-step RK4.

Load changes in time are breakpoints: each external-load piece is integrated on its own, so no step
straddles a jump or a kink. Moments that jump with the crank angle (an on-off cutting load) are
switches: every accepted step is checked for a crossing of a switch angle, also inside the step
(the dense output is probed at interior points, so a step that crosses and comes back is caught),
the crossing is located on the dense output, and the solver restarts exactly on the switch.
"""

from __future__ import annotations

import bisect
import math

import numpy as np
from scipy import integrate, optimize
from scipy.interpolate import CubicHermiteSpline

from mech_regulator.model import MachineModel
from mech_regulator.solvers.trajectory import Progress, Trajectory

PROBES_PER_STEP = 4  # interior points of each step checked for a switch crossing
RESTART_PERIODS = 4  # the solver's wrapped crank angle stays within this many dynamic periods


def integrate_time_domain(model: MachineModel, progress: Progress | None = None) -> Trajectory:
    """Integrate the scene's scenario with its solver settings; returns the (possibly partial) trajectory."""
    solver = model.scene.solver
    scenario = model.scene.scenario
    trajectory = Trajectory(method=solver.method, t_start=0.0)
    y = np.array([scenario.initial.phi, scenario.initial.omega], dtype=float)
    edges = [0.0] + [t for t in model.breakpoints() if 0.0 < t < scenario.duration] + [scenario.duration]
    try:
        for t_start, t_end in zip(edges[:-1], edges[1:]):
            piece = model.piece_at(t_start)
            if solver.method == "RK4":
                y = _rk4_segment(model.rhs(piece), t_start, t_end, y, solver.step, trajectory, progress)
            else:
                y = _adaptive_segment(model, piece, t_start, t_end, y, trajectory, progress)
            if trajectory.status != "complete":
                break
        trajectory.stats.restarts += len(edges) - 2
    except KeyboardInterrupt:
        trajectory.status = "interrupted"
        trajectory.message = f"interrupted by the user at t = {trajectory.t_end:.6g} s"
    return trajectory


def _rk4_segment(rhs, t_start: float, t_end: float, y: np.ndarray, step: float, trajectory: Trajectory,
                 progress: Progress | None) -> np.ndarray:
    """Classic fixed-step RK4 on [t_start, t_end] with the step shortened to divide the segment evenly;
    dense output by cubic Hermite interpolation of the states and their derivatives."""
    count = max(1, math.ceil((t_end - t_start) / step - 1e-9))
    h = (t_end - t_start) / count
    times = t_start + h * np.arange(count + 1)
    states = np.empty((count + 1, 2))
    slopes = np.empty((count + 1, 2))
    states[0] = y
    slopes[0] = k1 = np.asarray(rhs(t_start, y))
    for i in range(count):
        t = times[i]
        k2 = np.asarray(rhs(t + 0.5 * h, y + 0.5 * h * k1))
        k3 = np.asarray(rhs(t + 0.5 * h, y + 0.5 * h * k2))
        k4 = np.asarray(rhs(t + h, y + h * k3))
        y = y + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        if not np.all(np.isfinite(y)):
            trajectory.status = "failed"
            trajectory.message = f"RK4: the state became non-finite at t = {times[i + 1]:.6g} s; use a smaller step"
            count = i
            break
        k1 = np.asarray(rhs(times[i + 1], y))
        states[i + 1], slopes[i + 1] = y, k1
        if progress is not None and i % 1000 == 0:
            progress(times[i + 1])
    trajectory.stats.nfev += 4 * count + 1
    trajectory.stats.steps += count
    if count > 0:
        spline = CubicHermiteSpline(times[: count + 1], states[: count + 1].T, slopes[: count + 1].T, axis=1)
        trajectory.add_piece(times[0], times[count], spline)
    return states[count]


def _adaptive_segment(model: MachineModel, piece, t_start: float, t_end: float, y: np.ndarray, trajectory: Trajectory,
                      progress: Progress | None) -> np.ndarray:
    """Step a scipy OdeSolver over [t_start, t_end], restarting it exactly at every switch crossing.

    The solver integrates the crank angle wrapped by whole dynamic periods (the right-hand side is
    periodic in them): a growing phi would otherwise loosen the relative tolerance on the phase step
    by step. It restarts, keeping its step size, whenever the wrapped angle passes RESTART_PERIODS
    periods; outputs carry the unwrapped angle.
    """
    settings = model.scene.solver
    solver_class = getattr(integrate, settings.method)
    switches = _unique_switches(model.switch_angles())
    grid = model.switch_grid()
    period = model.dynamic_period()
    t, first_step = t_start, None
    counts = _switch_counts(y[0], switches)
    while t < t_end and trajectory.status == "complete":
        offset = period * math.floor(y[0] / period)
        window = _switch_window(grid, period, y[0] - offset, forward=y[1] >= 0.0) if grid else None
        rhs = model.rhs(piece, window)
        solver = solver_class(rhs, t, y - (offset, 0.0), t_end, rtol=settings.rtol, atol=settings.atol,
                              max_step=settings.max_step or np.inf, first_step=first_step)
        restart = False
        while solver.status == "running" and not restart:
            message = solver.step()
            if solver.status == "failed":
                trajectory.status = "failed"
                trajectory.message = f"{settings.method} failed at t = {solver.t:.6g} s: {message}"
                break
            if not np.all(np.isfinite(solver.y)):
                trajectory.status = "failed"
                trajectory.message = f"{settings.method}: the state became non-finite at t = {solver.t:.6g} s"
                break
            dense = _Shifted(solver.dense_output(), offset)
            t_step, y_step = solver.t, solver.y + (offset, 0.0)
            if switches:
                t_cross, boundary, counts = _first_crossing(dense, solver.t_old, solver.t, counts, switches)
                if t_cross is not None:
                    t_step, y_step = t_cross, dense(t_cross)
                    y_step[0] = boundary
                    trajectory.stats.switches += 1
                    restart = t_step < t_end
            trajectory.add_piece(solver.t_old, t_step, dense)
            trajectory.stats.steps += 1
            t, y = t_step, np.array(y_step, dtype=float)
            restart = restart or (abs(solver.y[0]) > RESTART_PERIODS * period and t < t_end)
            if progress is not None:
                progress(t)
        first_step = min(solver.step_size, t_end - t) if solver.step_size else None
        trajectory.stats.nfev += int(solver.nfev)
        trajectory.stats.njev += int(solver.njev)
        trajectory.stats.nlu += int(solver.nlu)
        if restart:
            trajectory.stats.restarts += 1
    return y


class _Shifted:
    """A solver's dense output with the wrapped-off whole periods added back to the angle."""

    def __init__(self, dense, offset: float):
        self.dense, self.offset = dense, offset

    def __call__(self, t):
        y = self.dense(t)
        y[0] += self.offset
        return y


def _switch_window(grid: list[float], period: float, phi: float, forward: bool) -> tuple[float, float]:
    """The interval between consecutive switch angles that the motion from phi (in [0, period)) is in:
    on a switch angle, the one ahead in the direction of motion."""
    tolerance = 1e-9 * period
    if phi > period - tolerance:  # a whole period that floor() left unwrapped by round-off
        phi -= period
    i = bisect.bisect_right(grid, phi + tolerance) - 1 if forward else bisect.bisect_left(grid, phi - tolerance) - 1
    lo = grid[i] if i >= 0 else grid[-1] - period
    hi = grid[i + 1] if i + 1 < len(grid) else grid[0] + period
    return lo, hi


def _unique_switches(switches: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Switch (angle, period) pairs [rad] with duplicates (same angle and period) removed."""
    unique: dict[tuple[float, float], tuple[float, float]] = {}
    for angle, period in switches:
        unique.setdefault((round(angle % period, 12), round(period, 12)), (angle % period, period))
    return list(unique.values())


def _switch_counts(phi: float, switches: list[tuple[float, float]]) -> list[int]:
    """For each switch, how many of its angles (angle + k period) lie at or below phi."""
    return [math.floor((phi - angle) / period) for angle, period in switches]


def _first_crossing(dense, t_old: float, t_new: float, counts_old: list[int], switches: list[tuple[float, float]]
                    ) -> tuple[float | None, float, list[int]]:
    """Earliest time in (t_old, t_new] at which phi reaches a switch angle: (time, angle, counts after it),
    or (None, nan, counts at t_new) if the step crosses none.

    The step is probed at interior points so a crossing and return within one step is not missed;
    the crossing is then located by Brent's method on the dense output. Counts are carried, not
    recomputed from phi, so a restart exactly on a switch angle is never taken for a new crossing.
    """
    probe_times = np.linspace(t_old, t_new, PROBES_PER_STEP + 2)
    phis = dense(probe_times)[0]
    previous = counts_old
    for i in range(1, probe_times.size):
        current = _switch_counts(phis[i], switches)
        changed = [j for j in range(len(switches)) if current[j] != previous[j]]
        if changed:
            forward = phis[i] > phis[i - 1]
            earliest = None
            for j in changed:
                angle, period = switches[j]
                boundary = angle + period * (previous[j] + 1 if forward else previous[j])
                t_cross = _root(lambda tau: dense(tau)[0] - boundary, probe_times[i - 1], probe_times[i])
                if earliest is None or t_cross < earliest[0]:
                    earliest = (t_cross, boundary, j)
            t_cross, boundary, j = earliest
            after = list(previous)
            after[j] += 1 if forward else -1
            return t_cross, boundary, after
        previous = current
    return None, math.nan, previous


def _root(function, a: float, b: float) -> float:
    """Root of function in [a, b] by Brent's method; an end that is already on the root (round-off at a
    restart on the switch) is returned as it is."""
    fa, fb = function(a), function(b)
    if fa == 0.0 or fa * fb > 0.0:
        return a if abs(fa) <= abs(fb) else b
    return optimize.brentq(function, a, b, xtol=1e-15, rtol=4 * np.finfo(float).eps)
