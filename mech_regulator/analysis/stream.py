"""A run's figures taken while it runs, so that its dense output is not kept whole (docs/hard_cases.md §4, memory).

RunDigest is a trajectory's stream (Trajectory.stream): once the trajectory holds RETAINED_STEPS solver steps and a
chunk of BALANCE_CHUNK_STEPS more, it hands the oldest chunk to what the summary and the CSV need of it and drops
the pieces no one needs any more. Each consumer reads the chunk as it would read the whole run, on the same sample
times and in the same chunks, so a complete run's figures are the same numbers:
- the energy balance's works (analysis/energy.py, WorksSoFar: the same chunks of steps, summed in the same order);
- the output samples at the scene's sample rate, on the grid of the run's planned duration, when the CSV, a recording
  or a bag is asked for
  (their states are kept: they are the product, duration x sample rate of them, a limit docs/scenes.md announces);
- each load change's window (analysis/load_response.py, ResponseWindow: its cycle-mean speed and throttle, read
  CYCLE_CHUNK times at a time), and the mode log's check (analysis/self_check.py, ModeLogSoFar);
- whether omega <= 0 after the last load change (the steady state's verdict on a machine that stops);
- a two-mass machine's largest coupling moment and twist range (analysis/two_mass.py, CouplingSoFar) and a drive
  train's largest section torque per branch (analysis/drivetrain.py, SectionsSoFar), on the grids the run kept whole
  reads them on.
The steady state and last period are judged on the tail the trajectory keeps (at least RETAINED_STEPS steps).
A machine with cams has its contacts checked on the steps before they come here (solvers/cam_contact.py's
ContactWatch, CHECK_CHUNK_STEPS at a time, fewer than RETAINED_STEPS).
A run that ends before its planned duration (failed, interrupted) after dropping pieces keeps the samples and windows
on the planned grid up to where it ended, and its end.
"""

from __future__ import annotations

import math

import numpy as np

from mech_regulator.analysis.drivetrain import SectionsSoFar, read_sections
from mech_regulator.analysis.energy import BALANCE_CHUNK_STEPS, WorksSoFar, add_works, step_chunks, step_edges
from mech_regulator.analysis.load_response import period_before, response_windows
from mech_regulator.analysis.periodic import steady_from
from mech_regulator.analysis.self_check import ModeLogSoFar, deepest_guard, mode_log_spacing
from mech_regulator.analysis.stability import is_periodic
from mech_regulator.analysis.two_mass import CouplingSoFar, read_coupling
from mech_regulator.model import MachineModel
from mech_regulator.solvers import simulate
from mech_regulator.solvers.trajectory import Progress, Trajectory, sample_times

RETAINED_STEPS = 50_000  # solver steps a streamed run's trajectory keeps at its end (the steady state's tail):
# about 70 s of engine_direct; a run streams once it has taken these and a chunk more (docs/speed.md, memory)


def simulate_streamed(
    model: MachineModel, progress: Progress | None = None, samples: bool = False
) -> tuple[Trajectory, RunDigest | None]:
    """The monolithic run of the model (solvers.simulate), streamed: its trajectory, and the digest of the dense output
    it dropped (None when it dropped none: the trajectory is then the whole run, as summarise reads it). samples:
    whether the digest keeps the output samples (a CSV, a plot, a recording or a bag reads them). Refusals raise
    SceneError, as simulate's."""
    digest = RunDigest(model, samples=samples)
    trajectory = simulate(model, progress, stream=digest.take)
    return trajectory, digest if trajectory.steps_dropped else None


class RunDigest:
    """What a streamed run (module docstring) took of its dropped dense output: works (WorksSoFar), the output samples
    when asked for (times [s] of the planned run and the states at the first samples_done; none kept without),
    windows (ResponseWindow, one per load change), mode_log (ModeLogSoFar) and stopped_at, the first quadrature node
    [s] after the last load change with omega <= 0 (None if none), coupling (CouplingSoFar, with a coupling) and
    sections (SectionsSoFar, with a drive train's branches)."""

    def __init__(self, model: MachineModel, samples: bool = True):
        self.model = model
        duration = model.scene.scenario.duration
        self.works = WorksSoFar()
        self.times = sample_times(0.0, duration, model.scene.solver.sample_rate) if samples else np.zeros(0)
        self.states: np.ndarray | None = None
        self.samples_done = 0
        self.windows = response_windows(model, duration) if model.governor is not None else []
        self.mode_log = ModeLogSoFar(mode_log_spacing(model, duration), 0.0)
        self.stopped_at: float | None = None
        self.coupling = CouplingSoFar() if model.coupling is not None else None
        self.sections = SectionsSoFar() if model.driven is not None and model.driven.branches else None

    def take(self, trajectory: Trajectory) -> None:
        """The trajectory's stream: hand its oldest chunk of steps not taken yet to the consumers once RETAINED_STEPS
        more follow it, then drop the pieces that end before what any consumer still needs."""
        first = self.works.steps - trajectory.steps_dropped
        if trajectory.held_steps - first < RETAINED_STEPS + BALANCE_CHUNK_STEPS:
            return
        model = self.model
        chunk, following = next(step_chunks(trajectory, step_edges(trajectory), self.works.steps))
        if self.works.start is None:
            self.works.start = trajectory(np.array([trajectory.t_start]))[:, 0]
        nodes, columns = add_works(model, trajectory, chunk, self.works.works)
        self.works.steps += BALANCE_CHUNK_STEPS
        t_done = float(chunk[-1])
        stops = (nodes > steady_from(model)) & (columns["omega"] <= 0.0)
        if self.stopped_at is None and np.any(stops):
            self.stopped_at = float(nodes[np.argmax(stops)])
        self._sample(trajectory, t_done)
        if self.coupling is not None:
            read_coupling(model, trajectory, chunk, following, self.coupling)
        if self.sections is not None:
            read_sections(model, trajectory, chunk, self.sections)
        for window in self.windows:
            window.read(model, trajectory, t_done)
        self.mode_log.worst = deepest_guard(model, trajectory, self.mode_log, t_done)
        self.mode_log.t_done = t_done
        needed = min([t_done] + [self._window_needs(trajectory, window) for window in self.windows])
        trajectory.drop_front(
            min(int(np.searchsorted(trajectory.piece_edges[1:], needed, side="left")), len(trajectory.interpolants) - 1)
        )

    def samples(self, trajectory: Trajectory) -> tuple[np.ndarray, np.ndarray]:
        """The output sample times [s] and states of the finished run: the planned grid up to its end (and the end,
        when the run stopped between two samples), the states not taken yet read off the trajectory."""
        times = self.times[: int(np.searchsorted(self.times, trajectory.t_end, side="right"))]
        self._sample(trajectory, trajectory.t_end)
        assert self.states is not None, "the samples of a streamed run: RunDigest.take took some"
        states = self.states[:, : times.size]
        if times[-1] < trajectory.t_end:
            times = np.append(times, trajectory.t_end)
            states = np.column_stack([states, trajectory(times[-1:])])
        return times, states

    def _sample(self, trajectory: Trajectory, t_until: float) -> None:
        """Take the states at the planned samples up to t_until [s] not taken yet."""
        last = int(np.searchsorted(self.times, t_until, side="right"))  # 0 when no samples are kept
        if last > self.samples_done:
            states = trajectory(self.times[self.samples_done : last])
            if self.states is None:
                self.states = np.empty((states.shape[0], self.times.size))
            self.states[:, self.samples_done : last] = states
            self.samples_done = last

    def _window_needs(self, trajectory: Trajectory, window) -> float:
        """The earliest time [s] the window's next chunk reads (its grid starts a dynamic period before it), inf for
        a window read whole."""
        if window.done >= window.times.size:
            return math.inf
        start = float(window.times[window.done])
        if start > trajectory.t_end or not is_periodic(self.model):
            return start
        return period_before(trajectory, start, self.model.dynamic_period())
