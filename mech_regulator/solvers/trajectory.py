"""The result of an integration: a dense, piecewise trajectory with the solver's statistics."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import OdeSolution

Progress = Callable[[float], None]
Stream = Callable[["Trajectory"], None]  # called with the trajectory after each piece it gains (analysis/stream.py)
EVALUATION_CHUNK = 100_000  # times a Trajectory evaluates at once: its temporaries (each time's step coefficients,
# some 0.2 kB) stay bounded however many times it is asked for


@dataclass
class SolverStats:
    """Work done by a solver: right-hand-side evaluations (for the energy method: moment evaluations),
    Jacobian evaluations, LU decompositions, accepted steps, restarts at breakpoints and switches,
    and governor mode changes (events)."""

    nfev: int = 0
    njev: int = 0
    nlu: int = 0
    steps: int = 0
    restarts: int = 0
    switches: int = 0
    events: int = 0


@dataclass
class Trajectory:
    """Dense output of a run: `trajectory(t)` gives the state y (phi [rad], omega [rad/s], then the
    governor's states) at times t.

    status is 'complete', 'failed' (message says why and where) or 'interrupted'; a trajectory that
    did not complete still covers [t_start, t_end] and nothing computed is lost. modes: (start time,
    mode: the governor's, then the drive train's) of each stretch in one mode; events: (time, what happened)
    of every mode change.
    y_start: the state at t_start, what a run refused before its first step still gives at t_start.
    step_ends: for each piece, the ends [s] of the solver steps it spans, ascending, its last the piece's end (one
    for a piece of a single step; a compiled call's steps; the energy method's knots): the dense output is smooth
    within a step, which is what a quadrature over the run needs to know (analysis/energy.py).
    stream: called after each added piece (a run's figures taken while it runs, analysis/stream.py), which may drop
    the pieces it is done with from the front (drop_front): the trajectory then covers [t_kept, t_end] only;
    held_steps counts the solver steps of the pieces held, steps_dropped those dropped.
    """

    method: str
    t_start: float
    piece_edges: list[float] = field(default_factory=list)
    interpolants: list[Callable] = field(default_factory=list)
    stats: SolverStats = field(default_factory=SolverStats)
    modes: list[tuple[float, tuple[str, ...]]] = field(default_factory=list)
    events: list[tuple[float, str]] = field(default_factory=list)
    status: str = "complete"
    message: str = ""
    y_start: np.ndarray | None = None
    step_ends: list[np.ndarray] = field(default_factory=list)
    stream: Stream | None = field(default=None, repr=False)
    held_steps: int = 0
    steps_dropped: int = 0
    _solution: OdeSolution | None = field(default=None, repr=False)

    def add_piece(
        self, t_start: float, t_end: float, interpolant: Callable, step_ends: np.ndarray | None = None
    ) -> None:
        """Append the interpolant valid on [t_start, t_end] [s] (pieces are contiguous in time) and record the ends of
        the solver steps it spans: step_ends [s] ascending when it spans several; by default the knots `x` of a scipy
        piecewise polynomial (the energy method's spline), else one step. Ends at or beyond t_end are cut to t_end."""
        if t_end <= t_start:
            return
        if not self.piece_edges:
            self.piece_edges.append(t_start)
        self.piece_edges.append(t_end)
        self.interpolants.append(interpolant)
        knots = getattr(interpolant, "x", None) if step_ends is None else np.asarray(step_ends, dtype=float)
        if knots is None:
            self.step_ends.append(np.array([t_end]))
        elif knots.size and knots[0] > t_start and knots[-1] == t_end and (knots.size == 1 or knots[-2] < t_end):
            self.step_ends.append(knots)  # already so (a compiled call's steps)
        else:
            self.step_ends.append(np.append(knots[(knots > t_start) & (knots < t_end)], t_end))
        self.held_steps += self.step_ends[-1].size
        self._solution = None
        if self.stream is not None:
            self.stream(self)

    def cut(self, t: float) -> None:
        """End the trajectory at t [s] (t_start < t <= t_end): the pieces after it dropped, the last one ending at t,
        and the events and modes recorded after t (what a run found no longer valid beyond t is not reported)."""
        keep = max(1, int(np.searchsorted(self.piece_edges, t, side="left")))
        self.held_steps -= sum(ends.size for ends in self.step_ends[keep - 1 :])
        del self.interpolants[keep:], self.step_ends[keep:], self.piece_edges[keep + 1 :]
        self.piece_edges[-1] = t
        ends = self.step_ends[-1]
        self.step_ends[-1] = np.append(ends[ends < t], t)
        self.held_steps += self.step_ends[-1].size
        self.events[:] = [event for event in self.events if event[0] <= t]
        self.modes[:] = [mode for mode in self.modes if mode[0] <= t]
        self._solution = None

    def drop_front(self, count: int) -> None:
        """Drop the first count pieces (fewer than held; what a stream is done with): the trajectory then starts at
        t_kept, the end of the last piece dropped."""
        dropped = sum(ends.size for ends in self.step_ends[:count])
        del self.interpolants[:count], self.step_ends[:count], self.piece_edges[:count]
        self.held_steps -= dropped
        self.steps_dropped += dropped
        self._solution = None

    @property
    def t_kept(self) -> float:
        """The start [s] of what the trajectory holds: t_start, or where the pieces a stream dropped ended."""
        return self.piece_edges[0] if self.piece_edges else self.t_start

    @property
    def t_end(self) -> float:
        return self.piece_edges[-1] if self.piece_edges else self.t_start

    def __call__(self, t: float | np.ndarray) -> np.ndarray:
        """State at t: shape (n_states,) for a scalar, (n_states, n) for an array of times in [t_start, t_end]
        (EVALUATION_CHUNK of them at a time)."""
        if not self.interpolants:
            return self._start_only(t)
        t = np.asarray(t)  # once here: numpy's functions on t would convert it at each
        if self.steps_dropped and t.min() < self.piece_edges[0]:
            raise ValueError(f"t = {t.min()} s: the trajectory holds only t >= {self.piece_edges[0]} s (streamed)")
        if t.ndim == 1 and t.size > EVALUATION_CHUNK:
            first = self(t[:EVALUATION_CHUNK])
            states = np.empty((first.shape[0], t.size))
            states[:, :EVALUATION_CHUNK] = first
            for start in range(EVALUATION_CHUNK, t.size, EVALUATION_CHUNK):
                states[:, start : start + EVALUATION_CHUNK] = self(t[start : start + EVALUATION_CHUNK])
            return states
        if len(self.interpolants) == 1:  # what scipy's OdeSolution would call, without its sorting and grouping
            return self.interpolants[0](t)
        if self._solution is None:
            self._solution = OdeSolution(np.asarray(self.piece_edges), self.interpolants)
        return self._solution(t)

    def _start_only(self, t: float | np.ndarray) -> np.ndarray:
        """The state of a run that made no step: y_start at t_start, nothing elsewhere."""
        if self.y_start is None or np.any(np.asarray(t) != self.t_start):
            raise ValueError(
                f"the run made no step: it covers only t = {self.t_start} s"
                + (" and its initial state is unknown" if self.y_start is None else "")
            )
        if np.ndim(t) == 0:
            return np.array(self.y_start, dtype=float)
        return np.repeat(np.asarray(self.y_start, dtype=float)[:, None], np.size(t), axis=1)

    def samples(self, sample_rate: float) -> np.ndarray:
        """Uniform sample times [s] at sample_rate [Hz] from t_start to t_end, both ends included."""
        return sample_times(self.t_start, self.t_end, sample_rate)


def sample_times(t_start: float, t_end: float, sample_rate: float) -> np.ndarray:
    """Uniform sample times [s] at sample_rate [Hz] from t_start to t_end [s], both ends included (at least 2)."""
    return np.linspace(t_start, t_end, max(2, int(round((t_end - t_start) * sample_rate)) + 1))


def sample_times_within(t_start: float, t_end: float, sample_rate: float, low: float, high: float) -> np.ndarray:
    """The sample times [s] of sample_times(t_start, t_end, sample_rate) in [low, high], the same numbers, without
    the grid: a long run's grid (its planned duration x sample rate of times) is not built to read a stretch."""
    count = max(2, int(round((t_end - t_start) * sample_rate)) + 1)
    step = (t_end - t_start) / (count - 1)
    first = min(max(math.floor((low - t_start) / step) - 1, 0), count - 1)
    last = min(max(math.ceil((high - t_start) / step) + 1, first), count - 1)
    times = np.arange(first, last + 1, dtype=float) * step + t_start  # as np.linspace computes them
    if last == count - 1:
        times[-1] = t_end
    return times[(times >= low) & (times <= high)]


@dataclass
class SampledTrajectory(Trajectory):
    """A trajectory known only at sample times (a co-simulation's exchange times, a recording): the state
    between samples is interpolated linearly. times [s] ascending, states shape (n_states, n)."""

    times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    states: np.ndarray = field(default_factory=lambda: np.zeros((2, 0)))

    def __post_init__(self):
        if self.times.size:
            self.piece_edges = [float(self.times[0]), float(self.times[-1])]
            self.interpolants = [self]
            self.step_ends = [np.asarray(self.times[1:], dtype=float)]

    def __call__(self, t: float | np.ndarray) -> np.ndarray:
        """State at t by linear interpolation between samples."""
        if np.ndim(t) == 0:
            return np.array([np.interp(t, self.times, row) for row in self.states])
        return np.vstack([np.interp(t, self.times, row) for row in self.states])
