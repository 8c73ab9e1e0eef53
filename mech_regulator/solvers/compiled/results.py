"""What a call of a compiled stepper gives back: CompiledRun wraps its result tuple (integrators.py's docstring),
StepsDense is the dense output of all its steps, for Trajectory.add_piece."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.integrate import DenseOutput

from mech_regulator.solvers.compiled.dense import steps_dense
from mech_regulator.solvers.compiled.integrators import FAILED, FAILURES
from mech_regulator.solvers.compiled.pieces import sampled_speeds
from mech_regulator.solvers.compiled.steppers import entry_point


class StepsDense(DenseOutput):
    """The dense output of all the steps of one compiled call: y(t) = y_old[k] + h_k sum_j c[k, :, j-1]
    theta^j on step k (found by np.searchsorted over times), theta = (t - times[k]) / h_k, then phi plus the whole
    periods step_offsets[k] [rad] wrapped off it on that step (none by default). At the start of a step that begins a
    restart inside the call (restarted[k], a switch window's edge) the step before it answers, as between two pieces
    of a Trajectory (scipy's OdeSolution). Called with a scalar time [s] it gives shape (n_states,), with an array of
    m times shape (n_states, m)."""

    def __init__(
        self,
        times: np.ndarray,
        y_old: np.ndarray,
        coefficients: np.ndarray,
        step_offsets: np.ndarray | None = None,
        restarted: np.ndarray | None = None,
    ):
        super().__init__(times[0], times[-1])
        self.times, self.y_old, self.coefficients = times, y_old, coefficients
        self.step_offsets = np.empty(0) if step_offsets is None else step_offsets
        self.restarted = np.zeros(times.size - 1, dtype=np.bool_) if restarted is None else restarted

    def _call_impl(self, t: np.ndarray) -> np.ndarray:
        """The state at t [s] (an array, as scipy's DenseOutput.__call__ passes it)."""
        y = steps_dense(self.times, self.y_old, self.coefficients, self.step_offsets, self.restarted, t.reshape(-1))
        return y[:, 0] if t.ndim == 0 else y

    def speed_samples(self, t_start: float, t_end: float, longest: float) -> np.ndarray:
        """cosim.speed_samples over [t_start, t_end] [s] within this output, pieces no longer than `longest` [s]: the
        times [s] and the crank's speed [rad/s] there, the rows of one array, in one compiled call
        (pieces.sampled_speeds, by its entry: steppers.entry_point)."""
        return entry_point(sampled_speeds)(
            self.times, self.y_old, self.coefficients, self.step_offsets, self.restarted, t_start, t_end, longest
        )


class CompiledRun(NamedTuple):
    """One compiled call's result (the tuple of the module docstring, by name: a named tuple, made without copying
    the 23 fields one by one)."""

    status: int
    n_steps: int
    times: np.ndarray
    y_old: np.ndarray
    coefficients: np.ndarray
    event_guard: int
    event_time: float
    y_end: np.ndarray
    nfev: int
    njev: int
    nlu: int
    last_step: float
    failure: int
    wraps: int
    kinks: int
    step_offsets: np.ndarray
    restarted: np.ndarray
    offset: float
    window_lo: float
    window_hi: float
    pieces_done: int
    step_limit: float
    beyond: int

    @classmethod
    def from_result(cls, result: tuple) -> CompiledRun:
        """Name the fields of a stepper's result tuple."""
        return cls._make(result)

    @property
    def t_end(self) -> float:
        """Where the call stopped [s]: t_end, the event time, the first step end past the wrap limit or the
        last good step end of a failed call."""
        return float(self.times[-1])

    @property
    def dense(self) -> StepsDense | None:
        """The dense output over [times[0], times[-1]], phi with the whole periods wrapped off it added back (the
        kink offsets), None when no step was taken."""
        return (
            StepsDense(self.times, self.y_old, self.coefficients, self.step_offsets, self.restarted)
            if self.n_steps
            else None
        )

    @property
    def message(self) -> str:
        """Why a failed call (status 3) stopped, '' otherwise."""
        return FAILURES[self.failure] + f" at t = {self.t_end:.6g} s" if self.status == FAILED else ""
