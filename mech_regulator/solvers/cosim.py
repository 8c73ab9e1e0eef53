"""Co-simulation of a machine and its governor as two subsystems exchanging signals at fixed times.

This is what the ROS nodes do (machine_node and governor_node in separate processes), written once in
the core so that a node, the command line and a test compute the same numbers. Time advances in
exchange steps h on a grid of whole nanoseconds, t_k = k h (the stamps of ROS messages), with an exchange on each
load change of the scenario as well (ExchangeTimes):

- at t_k the machine gives its speed omega_k; the governor answers with its throttle u_k = u(g_k);
  the scenario gives the external load L(t_k);
- over [t_k, t_k+1] the machine integrates J(phi) omega' + 1/2 J' omega^2 = u_k M_d + M_c - L(t_k)
  with u_k and L(t_k) held, and the governor integrates its own equations with omega_k held
  (zero-order hold both ways, a Jacobi scheme: neither waits for the other's new value).

Each subsystem is the monolithic model with the other part taken out, integrated by the same solver
loop (modes, guards, switches), so the only difference from the monolithic simulation is how each side
sees the other over a step, the coupling:

- `hold` (zero-order hold both ways, above): the error is first order in h;
- `waveform`: the machine sends, with omega_k, its speed at the middle of the step it just integrated; the
  governor integrates [t_k-1, t_k] with omega(t) the quadratic through omega_k-1, that middle value and
  omega_k (the machine's own motion, not a held value) — a Gauss–Seidel order: the governor follows the
  machine — and the machine integrates [t_k, t_k+1] with the throttle extrapolated from the governor's last
  three answers (the quadratic through them, clamped to [0, 1]). The error is then of second order or better
  in h (docs/ros.md gives the measured orders), so a ten times longer exchange is as accurate as the hold's.
- `corrected` (predictor-corrector, one Gauss–Seidel iteration per step): the machine predicts [t_k, t_k+1] with the
  throttle extrapolated (as `waveform`); the governor integrates that step tentatively following the machine's speed
  sampled every h / (2 m) (m = speed_pieces(h): pieces of at most MAX_SPEED_PIECE, the quadratic through three
  samples on each, so that an engine's speed ripple is followed) and answers its own throttle over the step, piecewise
  quadratic with a break at every governor event inside it (a stop reached or left, stick/slip: a kink no polynomial
  follows); the machine does the step again from its saved state with that throttle (the corrector), and the governor
  does it again, for good, with the corrected speed. Pipelined, this is still one message each way per step: the
  machine sends at t_k the corrected samples of [t_k-1, t_k] with the predicted ones of [t_k, t_k+1], the governor
  answers its throttle at t_k with its tentative throttle over [t_k, t_k+1]. The machine predicts one step ahead
  (MachineStepper.predict_ahead): while the governor answers at t_k, it predicts [t_k+1, t_k+2] from the end of its
  prediction of [t_k, t_k+1] moved by how far the state at t_k now differs from where that prediction started, so
  that between its corrector and its next message there is no predictor to wait for (in the nodes the two run in
  parallel; a step whose load changed is predicted again from its start). A machine whose speed is periodic in its
  crank angle (an engine's firing cycle) and whose throttle the speed does not move directly predicts without
  integrating once it has run a cycle: its corrected speed one cycle of the crank back, moved to the speed now
  (MachineStepper._cycle_back; docs/speed.md, "A fifth sitting"). The governor's two passes at t_k, the
  one for good over [t_k-1, t_k] and the tentative one over [t_k, t_k+1], follow one sequence of speed pieces in the
  same compiled calls (GovernorStepper._follow_then_try; the same numbers as two calls).
- a governor whose throttle the crank speed moves directly (the PI law's proportional part, K_p (omega_s - omega) /
  omega_s: GovernorKind.throttle_command) would hand the predictor's miss of the firing ripple straight to the
  corrector's throttle; it answers instead its tentative command before the stops, in pieces of at most
  MAX_THROTTLE_PIECE, with the command's sensitivity to the speed k = d command / d omega (SpeedAction, an interface
  Jacobian), and the machine's corrector applies clip(command(t) + k (omega(t) - omega_p(t))) within the throttle's
  stops, omega its own speed and omega_p the predicted speed the governor answered to, so that inside its step the
  throttle follows the machine's speed as the monolithic law does; its predictor does the same with the command less
  k omega extrapolated (docs/ros.md, "The throttle's sensitivity to the speed"). For a sleeve-driven throttle k = 0
  and nothing changes.

The time of the governor's step enters the governor subsystem as an "external load" on its (unit, free)
inertia: omega' = -L(t) with L(t) = -(a + 2 b (t - t_k-1)) makes its omega state follow the quadratic
omega_k-1 + a s + b s^2 exactly (the integrators are exact on it). The scene's solver.path chooses
that loop's stepping: the reference path's, or the compiled fast path's (solvers/compiled/run.py), each
subsystem compiled once when its stepper is made.
"""

from __future__ import annotations

import bisect
import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np

from mech_regulator.governors import Mode
from mech_regulator.model import LoadPiece, MachineModel, crank_moments
from mech_regulator.model.joints import joint_values, output_joints
from mech_regulator.scene import SceneError
from mech_regulator.scene.limits import exchange_refusal, speed_beyond_limit
from mech_regulator.solvers.advice import rk4_stability_refusal, stiffness_refusal
from mech_regulator.solvers.cam_contact import check_contact
from mech_regulator.solvers.compiled import runs_compiled
from mech_regulator.solvers.quadratics import (
    quadratic_through,
    speed_load_line,
    speed_samples_times,
    speeds_one_cycle_back,
)
from mech_regulator.solvers.time_domain import _segment, fail_blown_up, state_text
from mech_regulator.solvers.trajectory import Progress, SampledTrajectory, SolverStats, Trajectory

NANOSECONDS = 1_000_000_000
_STATISTICS = tuple(item.name for item in dataclasses.fields(SolverStats))


def seconds(nanoseconds: float) -> float:
    """A grid time in seconds from whole nanoseconds, or math.inf from math.inf (a load held to the end: the one
    conversion every party uses, so that a time sent in a message stamp and the sender's own time are the same
    float)."""
    return nanoseconds / NANOSECONDS


def to_nanoseconds(time: float) -> int:
    """A time [s] rounded to whole nanoseconds."""
    return int(round(time * NANOSECONDS))


Samples = tuple  # (times [s], values) of a signal over one exchange step, two sequences of floats


@dataclass
class Prediction:
    """The machine's predictor over one exchange step (corrected coupling): its start time [s] and state, its end time
    [s], state and mode, the load it assumed (its value at the start [N m] and its rate [N m/s]), the integration's
    status, and the speed samples over the step (speed_samples)."""

    t_start: float
    start: np.ndarray
    t_end: float
    end: np.ndarray
    end_mode: object
    load_line: tuple[float, float]
    status: str
    samples: Samples


@dataclass(frozen=True)
class SpeedAction:
    """The crank speed's direct action on the governor's throttle over an exchange step (a PI law's proportional part:
    GovernorKind.throttle_command), sent with the governor's tentative command over the step: the command at the
    step's start [-] (the throttle before the stops) and its sensitivity to the crank speed, per_speed [s/rad]."""

    command: float
    per_speed: float


class MachineStepper:
    """The machine without its governor: (phi, omega) and a coupling's (twist, omega_driven) advanced over
    exchange steps with the throttle and the external load held, in the drive train's mode (a driven part
    held at rest, turning forwards or backwards; None without a coupling). overspeed_trip [rad/s] (0: none)
    bounds the speed both ways at the exchange times: beyond it forwards, it closes the throttle for good, as the
    trip valve of a real engine does; beyond it backwards (omega < -overspeed_trip), the run fails there, since a
    load that drives the machine backwards is one no closing of the throttle can stop."""

    def __init__(self, model: MachineModel, overspeed_trip: float = 0.0):
        self.plant = machine_subsystem(model)
        self._segment = segment_for(self.plant)
        self._state_names = self.plant.state_names()
        initial = model.initial_state()
        self.state = (
            np.concatenate([initial[:2], initial[model.coupling_index :]]) if model.driven is not None else initial[:2]
        )
        self.mode = self.plant.initial_mode(self.state)
        self.time = 0.0
        self.overspeed_trip = overspeed_trip
        self.throttle_range = model.governor.throttle_range if model.governor is not None else (0.0, 1.0)  # [-]
        acts = model.governor is not None and model.governor.speed_action  # the speed acts on the throttle directly
        self._prediction_piece = 0.5 * MAX_THROTTLE_PIECE if acts else math.inf  # [s] the predictor's speed samples'
        # longest piece: the governor's tentative command then follows the predicted firing ripple
        self.tripped_at: float | None = None
        self.stats = SolverStats()
        self.status, self.message = "complete", ""
        self._answers: list[tuple[float, float]] = []  # (time [s], throttle applied) of the last exchanges, or
        # with the speed's action on the throttle (corrected coupling, SpeedAction), its command less per_speed omega
        self._per_speed = 0.0  # [s/rad] that action's sensitivity (0: none)
        self.tentative = 1.0  # [-] the governor's tentative throttle at the end of the last step as _answers holds it
        self._step_end = 0.0  # [s] the end of the step `predict` did (corrected coupling)
        self._predicted: Samples | None = None  # the speed samples `predict` gave for that step
        self._prediction: Prediction | None = None  # the predictor's latest step (corrected coupling)
        self._load_line = (model.external_load(0.0), 0.0)  # the last step's load [N m] at its start and rate [N m/s]
        self._load_line_time = 0.0  # [s] that step's start
        cycles = not acts and (model.reduced is not None or "phi" in model.depends_on())  # a speed periodic in phi
        self._cycle = model.dynamic_period() if cycles else None  # [rad] the prediction's cycle (None: integrated)
        self._history = np.empty((2, 0))  # the corrected speed samples of the last steps, consecutive, oldest first,
        # as speeds_one_cycle_back takes them (times [s], speeds [rad/s]; each step's last repeated)
        self._history_columns: list[int] = []  # how many columns each of those steps has
        self._history_ends: list[float] = []  # [s] their ends
        self._speeds_one_cycle_back = one_cycle_back_for(self.plant)
        self._dense_speeds = dense_speeds_for(self.plant)
        self._history_angles: list[float] = []  # [rad] the crank angle phi at their ends
        self._rising = 0  # how many of the last consecutive pairs of those angles rise (the crank turning forwards)

    def applied_throttle(self, throttle: float) -> float:
        """The throttle [-] the machine applies now when given `throttle`: 0 once tripped. The trip is
        checked here, at the exchange times: the speed now above overspeed_trip trips the machine."""
        if self.overspeed_trip > 0.0 and self.tripped_at is None and abs(self.state[1]) > self.overspeed_trip:
            self.tripped_at = self.time
        return 0.0 if self.tripped_at is not None else throttle

    def advance(
        self,
        t_end: float,
        throttle: float,
        external_load: float,
        throttle_slope: float = 0.0,
        throttle_curvature: float = 0.0,
        load_rate: float = 0.0,
        throttle_per_speed: float = 0.0,
    ) -> Trajectory:
        """Integrate from the current time to t_end [s] with the external load [N m] held or, with a rate [N m/s],
        changing at that rate from now, and the throttle [-] (as applied_throttle gives it) held or, with a slope
        [1/s], curvature [1/s^2] and sensitivity to the crank's speed [s/rad], following that polynomial in the time
        since now plus throttle_per_speed omega (LoadPiece.throttle_at; none once tripped); returns that stretch's
        dense trajectory."""
        throttle = self.applied_throttle(throttle)
        if self.tripped_at is not None:
            throttle_slope = throttle_curvature = throttle_per_speed = 0.0
        return self._integrate(
            t_end, throttle, external_load, throttle_slope, throttle_curvature, load_rate, throttle_per_speed
        )

    def _integrate(
        self,
        t_end: float,
        throttle: float,
        external_load: float,
        throttle_slope: float,
        throttle_curvature: float,
        load_rate: float,
        throttle_per_speed: float = 0.0,
    ) -> Trajectory:
        """advance's integration, with the throttle [-] as given (no trip checked)."""
        stretch = Trajectory(method=self.plant.scene.solver.method, t_start=self.time)
        piece = LoadPiece(
            self.time,
            t_end,
            external_load - load_rate * self.time if load_rate else external_load,
            load_rate,
            throttle,
            throttle_slope,
            throttle_curvature,
            throttle_per_speed,
            *self.throttle_range,
        )
        self.state, self.mode = self._segment(self.plant, piece, self.time, t_end, self.state, self.mode, stretch, None)
        self.state = check_contact(self.plant, stretch, self.time, self.state)  # a cam follower's jump ends it
        self.time = stretch.t_end
        beyond = speed_beyond_limit(self._state_names, self.state.tolist()) if stretch.status == "complete" else None
        if beyond is not None:  # a blow-up (limits.py; the fast path's segment does not look at every step)
            fail_blown_up(self.plant, stretch, self.time, self.state, *beyond)
        elif stretch.status == "complete" and self.overspeed_trip > 0.0 and self.state[1] < -self.overspeed_trip:
            stretch.status = "failed"
            stretch.message = (
                f"driven backwards at t = {self.time:.6g} s: omega = {self.state[1]:.6g} rad/s, beyond "
                f"the trip speed {self.overspeed_trip:g} rad/s in reverse (the state: "
                f"{state_text(self.plant.state_names(), self.state)}); likely cause: a load larger than "
                "the machine can carry, which no closing of the throttle stops"
            )
        self.status, self.message = _accumulate(self.stats, stretch)
        return stretch

    def advance_following(self, t_end: float, throttle: float, external_load: float) -> float:
        """The waveform coupling's step: integrate to t_end [s] with the load [N m] held and the throttle [-] (this
        exchange's answer, as applied_throttle gives it) extrapolated through the last three answers
        (throttle_extrapolation); returns the speed omega [rad/s] at the step's middle, which the governor follows."""
        t_start = self.time
        self._answers = self._answers[-2:] + [(t_start, self.applied_throttle(throttle))]
        _, slope, curvature = throttle_extrapolation(self._answers)
        stretch = self.advance(t_end, throttle, external_load, slope, curvature)
        return float(stretch(0.5 * (t_start + t_end))[1])

    def predict(self, t_end: float, throttle_end: float) -> Samples:
        """The corrected coupling's predictor of the step from now to t_end [s]: the speed at its start, middle and end
        (speed_samples with one piece: the governor's tentative step follows the quadratic through them). The step
        predicted ahead for it (predict_ahead, while the governor answered the exchange before), its speeds shifted by
        the difference between the speed now and the speed that prediction started from; without one (the first step,
        a step other than the one expected, or a load other than the one it assumed: a load event came with the
        scenario's last answer), the step integrated now from the state now (_predicted_step, with the governor's tentative throttle
        for now, throttle_end [-])."""
        self._step_end = t_end
        cycle_back = self._cycle_back(t_end)
        if cycle_back is not None:
            self._prediction, self._predicted = None, cycle_back
            return cycle_back
        prediction = self._prediction
        load, load_rate = self._continued_load(self.time)
        if (
            prediction is None
            or prediction.t_start != self.time
            or prediction.t_end != t_end
            or prediction.load_line[1] != load_rate
            or not math.isclose(prediction.load_line[0], load, rel_tol=LOAD_LINE_TOLERANCE)
        ):
            prediction = self._prediction = self._predicted_step(self.state, self.mode, self.time, t_end, throttle_end)
        shift = float(self.state[1]) - float(prediction.start[1])
        times, speeds = prediction.samples
        self._predicted = (times, [speed + shift for speed in speeds])
        return self._predicted

    def predict_ahead(self, t_end: float, throttle_end: float) -> None:
        """The corrected coupling's predictor of the step after the current one (from the end of the step `predict`
        did to t_end [s]), made while the governor answers the current exchange (in the nodes: in parallel), so that
        no predictor stands between the machine's corrector and its next state: integrated from the end of the
        current step's prediction moved by the difference between the state now and the state that prediction
        started from (both steps are predicted from the same state, so this is the prediction re-synced with the
        corrected run to first order), with the throttle extrapolated through the last two answers and the
        governor's tentative throttle for now, throttle_end [-], on over both steps, and the last step's load
        continued. `predict` takes it at the next exchange; a failed prediction is dropped (predict then integrates
        that step itself)."""
        current = self._prediction
        if current is None or current.t_start != self.time:
            return
        prediction = self._predicted_step(
            current.end + (self.state - current.start), current.end_mode, current.t_end, t_end, throttle_end
        )
        self._prediction = prediction if prediction.status == "complete" else None

    def _cycle_back(self, t_end: float) -> Samples | None:
        """The prediction of the step from now to t_end [s] one cycle of the crank back, for a machine whose speed is
        periodic in phi and whose throttle the speed does not move directly: omega_p(t) = omega + omega_c(t - T) -
        omega_c(now - T) at the times speed_samples takes, omega [rad/s] the speed now, omega_c the corrected speed of
        the steps kept (the quadratic through three samples on each piece), T [s] the time since the crank angle was
        phi - the dynamic period (interpolated between the kept steps' ends, as np.interp; quadratics.speeds_one_cycle_back,
        compiled on the fast path). None where the kept steps do not reach back that far (the run's start), T is shorter
        than the step or the crank has not turned forwards all along (docs/speed.md, "A fifth sitting"); whether it has
        is counted as the steps are kept (_rising)."""
        omega = float(self.state[1])
        ends, angles = self._history_ends, self._history_angles
        if self._cycle is None or omega <= 0.0 or len(ends) < 2 or ends[-1] != self.time:
            return None
        target = float(self.state[0]) - self._cycle  # [rad]
        if angles[0] > target or target >= angles[-1] or self._rising < len(angles) - 1:
            return None  # (at or beyond the last angle T would be 0)
        below = bisect.bisect_right(angles, target) - 1  # np.interp's interval, and its operations
        slope = (ends[below + 1] - ends[below]) / (angles[below + 1] - angles[below])
        back = self.time - (slope * (target - angles[below]) + ends[below])  # [s] T
        if self.time - back < self._history[0, 0] or t_end - back > self.time:
            return None
        times, speeds = self._speeds_one_cycle_back(
            self._history, self.time, t_end, self._prediction_piece, back, omega
        )
        return times.tolist(), speeds.tolist()

    def _keep(self, samples: np.ndarray) -> Samples:
        """Keep a corrected step's speed samples (speed_sample_rows'), and the crank angle at its end (now), for
        _cycle_back (the last CYCLE_HISTORY steps; a step that does not start where the last one kept ended starts them
        anew); returns them as lists (speed_samples')."""
        if self._cycle is not None and samples.shape[1] >= 3 and samples[0, -1] == self.time:
            if self._history_ends and self._history_ends[-1] != samples[0, 0]:
                self._history, self._history_columns = np.empty((2, 0)), []
                self._history_ends, self._history_angles = [], []
            angle = float(self.state[0])
            self._rising = self._rising + 1 if self._history_angles and not angle <= self._history_angles[-1] else 0
            dropped = sum(self._history_columns[: -CYCLE_HISTORY + 1])  # the oldest step's, once CYCLE_HISTORY are kept
            self._history = np.concatenate((self._history[:, dropped:], samples, samples[:, -1:]), axis=1)
            self._history_columns = self._history_columns[1 - CYCLE_HISTORY :] + [samples.shape[1] + 1]
            self._history_ends = self._history_ends[1 - CYCLE_HISTORY :] + [self.time]
            self._history_angles = self._history_angles[1 - CYCLE_HISTORY :] + [angle]
        times, speeds = samples.tolist()
        return times, speeds

    def _continued_load(self, time: float) -> tuple[float, float]:
        """The last step's load continued to `time` [s]: (its value then [N m], its rate [N m/s])."""
        load, load_rate = self._load_line
        return load + load_rate * (time - self._load_line_time), load_rate

    def _predicted_step(self, state: np.ndarray, mode, t_start: float, t_end: float, throttle_end: float) -> Prediction:
        """Integrate from `state` in `mode` at t_start to t_end [s] with the throttle [-] extrapolated (the quadratic
        through the last two answers and throttle_end now: throttle_extrapolation, taken from t_start on; closed once
        tripped) and the last step's load continued (its value [N m] and rate [N m/s]: the new one comes with the
        scenario's answer), then go back to the machine's own state; returns the prediction."""
        before = (self.state, self.mode, self.time, self.status, self.message)
        throttle, slope, curvature = throttle_extrapolation(self._answers[-2:] + [(self.time, throttle_end)])
        ahead = t_start - self.time  # [s] from now to the predicted step's start
        throttle, slope = throttle + (slope + curvature * ahead) * ahead, slope + 2.0 * curvature * ahead
        per_speed = self._per_speed
        if self.tripped_at is not None:
            throttle = slope = curvature = per_speed = 0.0
        load_line = self._continued_load(t_start)
        self.state, self.mode, self.time = state.copy(), mode, t_start
        stretch = self._integrate(t_end, throttle, load_line[0], slope, curvature, load_line[1], per_speed)
        prediction = Prediction(
            t_start,
            np.array(state),
            t_end,
            self.state,
            self.mode,
            load_line,
            stretch.status,
            speed_samples([stretch], t_start, t_end, self._prediction_piece, self._dense_speeds),
        )
        self.state, self.mode, self.time, self.status, self.message = before
        return prediction

    def correct(
        self,
        throttle: float,
        waveform: Samples | None,
        external_load: float,
        load_rate: float = 0.0,
        action: SpeedAction | None = None,
    ) -> Samples:
        """The corrected coupling's corrector: integrate the step `predict` did again, from the same state, with the
        load [N m] changing at load_rate [N m/s] from now (a ramp of the scenario; held at 0) and the throttle the
        governor answered: `throttle` [-] at the step's start (as applied_throttle gives it), then its tentative
        throttle over the step, samples (times [s], throttle [-]) at the middle and the end of each piece
        (GovernorStepper.answer_corrected), the quadratic through a piece's start, middle and end; held without them
        or when they do not end at the step's end (a silent governor: the fail-safe). With the speed's action on the
        throttle (SpeedAction: the samples are then the governor's tentative command before the stops, starting from
        action.command), the throttle on each piece is that quadratic plus action.per_speed (omega(t) - omega_p(t))
        within throttle_range, omega the machine's own speed and omega_p the quadratic through the predicted speed
        (`predict`'s samples) at the piece's start, middle and end: the speed the governor's tentative command
        answered there (docs/ros.md, "The throttle's sensitivity to the speed"). Returns the step's speed samples
        (speed_samples)."""
        t_start, t_end = self.time, self._step_end
        predicted = self._predicted
        per_speed = 0.0 if action is None or self.tripped_at is not None else action.per_speed
        if predicted is None or predicted[0][0] != t_start or predicted[0][-1] != t_end:
            per_speed = 0.0  # no prediction of this step to correct against
        self._remember_answer(t_start, throttle, waveform, action, per_speed)
        self._load_line, self._load_line_time = (external_load, load_rate), t_start
        if waveform is None or len(waveform[0]) % 2 or waveform[0][-1] != t_end or self.tripped_at is not None:
            return self._keep(
                speed_sample_rows(
                    [self.advance(t_end, throttle, external_load, load_rate=load_rate)],
                    t_start,
                    t_end,
                    dense_speeds=self._dense_speeds,
                )
            )
        stretches, value = [], throttle  # the answer, within the stops; with the speed's action the command
        if per_speed != 0.0 and action is not None:
            value = action.command
        for index in range(0, len(waveform[0]) - 1, 2):
            end, middle_value, end_value = waveform[0][index + 1], waveform[1][index], waveform[1][index + 1]
            slope, curvature = quadratic_through(end - self.time, value, middle_value, end_value)
            offset = value
            if per_speed != 0.0 and predicted is not None:  # the command less per_speed omega_p: a quadratic in time
                speeds = piecewise_quadratic_at(predicted, [self.time, 0.5 * (self.time + end), end])
                speed_slope, speed_curvature = quadratic_through(end - self.time, *speeds)
                offset -= per_speed * speeds[0]
                slope -= per_speed * speed_slope
                curvature -= per_speed * speed_curvature
            load = external_load + load_rate * (self.time - t_start)
            stretches.append(self.advance(end, offset, load, slope, curvature, load_rate, per_speed))
            value = end_value
            if self.status != "complete":
                break
        return self._keep(speed_sample_rows(stretches, t_start, t_end, dense_speeds=self._dense_speeds))

    def _remember_answer(
        self, t_start: float, throttle: float, waveform: Samples | None, action: SpeedAction | None, per_speed: float
    ) -> None:
        """Note the governor's answer at the step's start t_start [s] for the predictor (_predicted_step): the throttle
        applied [-] and, as `tentative`, the tentative throttle's end (the answer without one); with the speed's
        action (per_speed [s/rad] not 0) the command less per_speed omega instead, at the start with the machine's
        speed there, at the end with the predicted one: a quadratic through them plus per_speed omega is then the
        predictor's throttle, which follows the machine's own speed as the corrector's does. A change of per_speed
        starts the answers anew."""
        if per_speed != self._per_speed:
            self._answers, self._per_speed = [], per_speed
        if per_speed == 0.0:
            self._answers = self._answers[-2:] + [(t_start, self.applied_throttle(throttle))]
            self.tentative = waveform[1][-1] if waveform is not None else throttle
            return
        assert action is not None and self._predicted is not None  # per_speed comes with both (correct)
        self._answers = self._answers[-2:] + [(t_start, action.command - per_speed * float(self.state[1]))]
        self.tentative = (
            waveform[1][-1] - per_speed * self._predicted[1][-1] if waveform is not None else self._answers[-1][1]
        )

    def message_outputs(self, throttle: float, external_load: float) -> tuple[float, list[tuple[str, float, float]]]:
        """What the machine node's joint_states carries at the current state with these inputs held (the throttle [-]
        as applied_throttle gives it, the external load [N m]), worked out for this one state only: the net moment on
        the crank M_d + M_c = J epsilon + 1/2 J' omega^2 [N m] (docs/theory.md §2.3, crank_moments' net), epsilon from
        the right-hand side the stepper integrates in its mode, and the joints besides the crank (model.joints:
        output_joints of joint_values). MachineModel.columns for the one row gave the same for 3-4 times the CPU
        (docs/speed.md, "The nodes' critical path trimmed (seventh sitting)")."""
        piece = LoadPiece(self.time, self.time, external_load, 0.0, self.applied_throttle(throttle))  # held
        epsilon = self.plant.rhs(piece, mode=self.mode)(self.time, self.state)[1]
        inertia, inertia_slope = self.plant.inertia(self.state[0])
        omega = float(self.state[1])
        net = float(inertia * epsilon + 0.5 * inertia_slope * omega**2)
        return net, output_joints(self.plant, joint_values(self.plant, self.state))

    def outputs_over(
        self, times: np.ndarray, states: np.ndarray, throttles: np.ndarray, external_loads: np.ndarray
    ) -> dict[str, np.ndarray]:
        """The machine's outputs at n times [s] in states (n_states x n), with the throttles [-] as applied (no trip
        checked here) and the external loads [N m] held, in one vectorised call: the columns of MachineModel.columns
        (omega, epsilon, J, M_drive as applied, M_load, x_slider, ...) and the moments on the crank by source (drive,
        resistance, external, net; see crank_moments), arrays of n."""
        columns = self.plant.columns(times, states, throttles, external_loads)
        columns.update(crank_moments(columns))
        return columns


def load_steppers(model: MachineModel, exchange_step: float) -> None:
    """Do one exchange step of the machine's stepper (and one answer of the governor's) on `model` and throw them
    away: what they load on first use (the scene's compiled modules, the compiled steppers of the fast path and the
    evaluation of their dense output, the first call's set-up of the reference path) is then in this process, and in
    processes forked from it (the launcher's nodes, nodes.launch), so that their first exchange does not wait for it."""
    duration = model.scene.scenario.duration
    step = min(exchange_step, duration)
    speed_samples([MachineStepper(model).advance(step, 1.0, model.external_load(0.0))], 0.0, step)
    if model.governor is not None:
        GovernorStepper(model).answer(step, model.initial_state()[1])


class GovernorStepper:
    """The governor without the machine: its states advanced over exchange steps with the crank speed
    held at the last value it was given (the machine's terms are absent, so omega' = 0 exactly)."""

    def __init__(self, model: MachineModel):
        if model.governor is None:
            raise ValueError(f"scene '{model.scene.name}' has no governor")
        self.regulator = governor_subsystem(model)
        self._segment = segment_for(self.regulator)
        self._follow_samples = pieces_for(self.regulator)
        self.governor = model.governor
        self.state = model.initial_state()[: model.coupling_index]
        self.mode = self.regulator.initial_mode(self.state)
        self.time = 0.0
        self.events: list[tuple[float, str, Mode]] = []
        self.stats = SolverStats()
        self.status, self.message = "complete", ""
        self._before_anticipation: tuple | None = None

    def answer(self, time: float, omega: float, omega_middle: float | None = None) -> float:
        """Take the crank speed omega [rad/s] measured at `time` [s]: first advance from the last exchange
        time to `time` with the previous speed held or, given omega_middle [rad/s] (the machine's speed at the
        middle of that step: the waveform coupling), with the speed following the quadratic through the
        previous speed, omega_middle and omega; then hold omega from here on; returns the throttle [-] at
        `time`. After `anticipate`, the stretch already done is kept if it ends at `time`, else undone and done
        again to `time`: the numbers never depend on anticipating."""
        if self._before_anticipation is not None:
            if time != self.time:
                (self.state, self.mode, self.time, events, self.stats, self.status, self.message) = (
                    self._before_anticipation
                )
                del self.events[events:]
            self._before_anticipation = None
        if time > self.time:
            self.follow(
                time,
                None
                if omega_middle is None
                else ([self.time, 0.5 * (self.time + time), time], [float(self.state[1]), omega_middle, omega]),
            )
        self.state = self.state.copy()
        self.state[1] = omega
        return self.throttle

    def follow(self, t_end: float, samples: Samples | None) -> Trajectory:
        """Integrate from now to t_end [s] with the speed held (samples None) or following the machine's speed
        samples (times [s] from now to t_end, omega [rad/s]; an odd number: the quadratic through three on each piece,
        speed_waveform); the mode changes go to `events`. Returns the stretch's dense trajectory."""
        stretch = Trajectory(method=self.regulator.scene.solver.method, t_start=self.time)
        if samples is None:
            self.state, self.mode = self._segment(
                self.regulator, None, self.time, t_end, self.state, self.mode, stretch, None
            )
        else:
            self.state, self.mode, _ = self._follow_samples(self.regulator, [samples], self.state, self.mode, stretch)
        self.time = stretch.t_end
        self._note(stretch, len(stretch.events))
        return stretch

    def _note(self, stretch: Trajectory, events: int) -> None:
        """Take a stretch's first `events` mode changes into `events`, its statistics into the totals and its status."""
        self.events += [
            (t, name, _governor_mode(mode)) for (t, name), (_, mode) in zip(stretch.events[:events], stretch.modes)
        ]
        self.status, self.message = _accumulate(self.stats, stretch)

    def _follow_then_try(self, corrected: Samples, predicted: Samples) -> Trajectory | None:
        """The governor's two passes of a corrected exchange in the same compiled calls: from now for good along the
        corrected speed samples to their end, where the predicted ones start, and on from there tentatively along the
        predicted samples; leaves the state, mode, time, events and statistics as `follow` along the corrected samples
        would (but for the speed, which answer_corrected sets) and returns the stretch over both, its part after the
        corrected samples' end the one `follow` along the predicted samples from there gives (the same numbers: the
        stepper starts each piece as a new call would, solvers/compiled/run.py). None when the pass for good did not
        reach the end of its samples or no step of the tentative pass was taken in the call that went on into it:
        then nothing is changed."""
        stretch = Trajectory(method=self.regulator.scene.solver.method, t_start=self.time)
        _, _, at_split = self._follow_samples(
            self.regulator, [corrected, predicted], self.state, self.mode, stretch, (len(corrected[0]) - 1) // 2
        )
        if at_split is None:
            return None
        self.state, self.mode, events = at_split
        self.time = corrected[0][-1]
        self._note(stretch, events)
        self.status, self.message = "complete", ""  # the pass for good's: it reached its end
        return stretch

    def answer_corrected(
        self, time: float, omega: float, corrected: Samples | None, predicted: Samples | None
    ) -> tuple[float, Samples | None, SpeedAction | None]:
        """The corrected coupling's answer to the crank speed omega [rad/s] at `time` [s]: integrate the step that
        ends there for good following the machine's corrected speed samples over it (times [s], omega [rad/s]; with the
        previous speed held when they do not span it: a missed exchange, realtime), hold omega from here on, then
        integrate the next step tentatively following the machine's predicted samples, and go back (the two passes in
        the same compiled calls where they can be: _follow_then_try). Returns the
        throttle [-] at `time`, the tentative throttle over the next step: samples (times [s], throttle [-]) at
        the middle and the end of each piece, the step split at every mode change inside it (a kink: a stop reached
        or left, the sleeve sticking or slipping); None without predicted samples (the run's end), and the speed's
        direct action on the throttle (SpeedAction, which the machine's corrector applies: MachineStepper.correct)
        when the governor's law has one at `time` (GovernorKind.throttle_command), the tentative samples then its
        command before the stops; else None and the throttle in 0..1."""
        stretch = None  # the tentative pass's (with the pass for good before it when both were made in one)
        if time > self.time:
            following = (
                corrected is not None
                and len(corrected[0]) >= 3
                and corrected[0][0] == self.time
                and corrected[0][-1] == time
            )
            if following and corrected is not None and predicted is not None and predicted[0][0] == time:
                stretch = self._follow_then_try(corrected, predicted) if len(predicted[0]) >= 3 else None
            if stretch is None:
                self.follow(time, corrected if following else None)
        self.state = self.state.copy()
        self.state[1] = omega
        throttle = self.throttle
        if predicted is None or len(predicted[0]) < 3 or predicted[0][0] != self.time:
            return throttle, None, None
        if stretch is None:
            before = (self.state.copy(), self.mode, self.time, len(self.events), self.status, self.message)
            stretch = self.follow(predicted[0][-1], predicted)
            (self.state, self.mode, self.time, events, self.status, self.message) = before
            del self.events[events:]
        if stretch.status != "complete":
            return throttle, None, None
        start, end = self.time, stretch.t_end
        edges = [start] + sorted({t for t, _ in stretch.events if start + MIN_PIECE < t < end - MIN_PIECE}) + [end]
        action = SpeedAction(*self.governor.throttle_command(self.state)) if self.governor.speed_action else None
        if action is not None and action.per_speed == 0.0:
            action = None
        if action is not None:  # pieces of at most MAX_THROTTLE_PIECE: the command's integral part follows the ripple
            edges = [
                float(t)
                for start, end in zip(edges[:-1], edges[1:])
                for t in np.linspace(start, end, math.ceil((end - start) / MAX_THROTTLE_PIECE - 1e-9) + 1)[:-1]
            ] + [end]
        times = [float(t) for start, end in zip(edges[:-1], edges[1:]) for t in (0.5 * (start + end), end)]
        states = stretch(np.array(times))  # at a stop the dense output may round past it (servo -3e-16): an opening
        if action is not None:  # the command before the stops, which the machine applies (MachineStepper.correct)
            return (
                throttle,
                (times, [self.governor.throttle_command(states[:, k])[0] for k in range(len(times))]),
                action,
            )
        return (
            throttle,
            (
                times,
                [
                    min(max(self.governor.throttle(states[:, index]), 0.0), 1.0)  # is 0..1, and the
                    for index in range(len(times))
                ],
            ),  # machine node refuses other samples
            None,
        )

    def anticipate(self, time: float) -> None:
        """Advance now, with the speed held, to `time` [s], the next exchange time as expected, so that the
        answer there is immediate (a governor node does this while the machine integrates the same
        step: the two run in parallel). Keeps the state before it for `answer` at another time."""
        before = (
            self.state.copy(),
            self.mode,
            self.time,
            len(self.events),
            dataclasses.replace(self.stats),
            self.status,
            self.message,
        )
        self.answer(time, float(self.state[1]))
        self._before_anticipation = before

    @property
    def throttle(self) -> float:
        """The throttle [-] the governor sets now."""
        return self.governor.throttle(self.state)

    def outputs(self) -> dict[str, float]:
        """The governor's state now: its signals (a centrifugal governor's sleeve z [m], sleeve_velocity z' [m/s],
        arm_angle [rad], arm_rate [rad/s] and, indirect, servo [-] (and feedback_shift [m]); a PI governor's integral
        part [-]) and the throttle [-]."""
        values = {name: float(value) for name, value in self.governor.signals(self.state).items()}
        values["throttle"] = self.throttle
        return values


COUPLINGS = ("hold", "waveform", "corrected")
DEFAULT_COUPLING = "corrected"  # the nodes' default coupling, with the scene's exchange step (DEFAULT_EXCHANGE_STEP
# unless it sets solver.exchange_step; docs/ros.md, "Speed": within 1e-4 of the monolithic runs, the fastest that is)
MAX_SPEED_PIECE = 1.25e-3  # [s]: the corrected coupling samples the machine's speed at least every half of this, the
# quadratic through three samples on each piece (an engine's speed ripple is followed; docs/ros.md gives the numbers).
# Its error does not fall with the exchange step: at 2.5e-3 it kept engine_indirect_none 1.4e-5 off within 1 s, which
# the hunting grew to 4.8e-3 over 16 s whatever the step; at 6.25e-4, 1.2e-5 at 10 ms, but the nodes ~9 % slower
LOAD_LINE_TOLERANCE = 1e-9  # [-] a prediction made ahead is kept while the load it assumed is the last step's load
# continued within this (rounding along a ramp); a load event in between (a change) drops it
MAX_THROTTLE_PIECE = 5e-3  # [s]: a tentative command with the speed's action (SpeedAction) comes in pieces of at most
# this, the machine's predicted speed in pieces of half of it: the PI governor's integral part integrates the firing
# ripple, which one quadratic per step misses (engine_pi over 0.3 s at 20 ms: 0.012 rad/s off with one piece,
# 2.9e-4 with these; docs/ros.md, "The throttle's sensitivity to the speed")
CYCLE_HISTORY = 64  # the corrected steps the machine keeps for its prediction one cycle of the crank back
# (MachineStepper._cycle_back): 80 ms at the adaptive step's smallest of 1.25 ms, more than the bundled engines' cycle
MIN_PIECE = 1e-9  # [s]: a governor event closer than this to a step's end does not split its throttle waveform
ADAPTIVE_HALVINGS = 4  # the adaptive exchange step's smallest: the exchange step / 2^this
ADAPTIVE_DOUBLINGS = 2  # and its largest: the exchange step * 2^this
RESTART_HALVINGS = 2  # its first step and the step after a load change: the exchange step / 2^this
SAFETY = 0.9  # [-] the adaptive step aims at this share of the tolerance (to the power ERROR_ORDER)
ERROR_ORDER = 3  # the predictor's miss grows about as the step to this power (engine_direct: 1e-5 of the speed at
# 20 ms, 4-6e-5 at 40 ms; docs/speed.md, "The adaptive step tried again")


def speed_samples(
    stretches: list[Trajectory],
    t_start: float,
    t_end: float,
    longest: float = MAX_SPEED_PIECE,
    dense_speeds=None,
) -> Samples:
    """The machine's speed omega [rad/s] over [t_start, t_end] [s] from the dense trajectories of the step's stretches
    (consecutive; the last ends at t_end unless the run failed in it), sampled at 2 m + 1 evenly spaced times, both
    ends included, m the fewest pieces no longer than `longest` [s] (speed_samples_times): speed_sample_rows' rows as
    lists."""
    times, speeds = speed_sample_rows(stretches, t_start, t_end, longest, dense_speeds).tolist()
    return times, speeds


def speed_sample_rows(
    stretches: list[Trajectory], t_start: float, t_end: float, longest: float = MAX_SPEED_PIECE, dense_speeds=None
) -> np.ndarray:
    """speed_samples' times [s] and speeds [rad/s], the rows of one array. dense_speeds: on the fast path what samples
    the dense output of one compiled call in one compiled call (dense_speeds_for), taken for a stretch of one such
    piece over the whole step (most steps)."""
    if len(stretches) == 1 and stretches[0].t_start <= t_start and stretches[0].t_end >= t_end:  # one stretch over
        if dense_speeds is not None and len(stretches[0].interpolants) == 1:  # the whole step (most steps): no masks
            return dense_speeds(stretches[0].interpolants[0], t_start, t_end, longest)
        times = speed_samples_times(t_start, t_end, longest)
        return np.vstack((times, stretches[0](times)[1]))
    times = speed_samples_times(t_start, t_end, longest)
    speeds = np.full(times.size, math.nan)  # NaN beyond a failed stretch's end
    for stretch in stretches:
        inside = (times >= stretch.t_start) & (times <= stretch.t_end)
        if inside.any():
            speeds[inside] = stretch(times[inside])[1]
    return np.vstack((times, speeds))


def piecewise_quadratic_at(samples: Samples, times: list[float]) -> list[float]:
    """A signal's samples (times [s], values; an odd number, the quadratic through three on each piece, as the governor
    follows the machine's speed: speed_waveform) evaluated at `times` [s] within their span."""
    knots = samples[0][::2]
    values = []
    for time in times:
        index = min(max(bisect.bisect_right(knots, time) - 1, 0), len(knots) - 2)
        start, middle, end = samples[1][2 * index : 2 * index + 3]
        a, b = quadratic_through(knots[index + 1] - knots[index], start, middle, end)
        elapsed = time - knots[index]
        values.append(start + elapsed * (a + elapsed * b))
    return values


def speed_waveform(
    t_start: float, t_end: float, omega_start: float, omega_middle: float, omega_end: float
) -> LoadPiece:
    """The governor subsystem's input over [t_start, t_end] [s] that makes its omega state follow the quadratic
    through the machine's speeds [rad/s] at the start, the middle and the end (quadratic_through): the external load
    of quadratics.speed_load_line as a LoadPiece."""
    a, b = quadratic_through(t_end - t_start, omega_start, omega_middle, omega_end)
    return LoadPiece(t_start, t_end, *speed_load_line(a, b, t_start))


def speed_pieces(samples: Samples) -> list:
    """The governor subsystem's pieces along the machine's speed samples (times [s], omega [rad/s]; an odd number):
    (speed_waveform, t_start [s], t_end [s], omega at the start [rad/s]) for each three samples, follow_pieces'."""
    times, speeds = samples
    return [
        (speed_waveform(start, end, first, middle, last), start, end, first)
        for start, end, first, middle, last in zip(times[:-2:2], times[2::2], speeds[:-2:2], speeds[1::2], speeds[2::2])
    ]


def throttle_extrapolation(answers: list[tuple[float, float]]) -> tuple[float, float, float]:
    """The throttle over the next step from the governor's last answers (time [s], throttle [-]), oldest first:
    (u, slope [1/s], curvature [1/s^2]) of the quadratic through the last three (Newton's form, taken at the last
    answer's time), the line through two, the value held with one."""
    (t2, u2) = answers[-1]
    if len(answers) == 1:
        return u2, 0.0, 0.0
    (t1, u1) = answers[-2]
    rate = (u2 - u1) / (t2 - t1)
    if len(answers) == 2:
        return u2, rate, 0.0
    (t0, u0) = answers[-3]
    curvature = (rate - (u1 - u0) / (t1 - t0)) / (t2 - t0)
    # u(t) = u2 + rate (t - t2) + curvature (t - t2)(t - t1) = u2 + (rate + curvature (t2 - t1)) s + curvature s^2
    return u2, rate + curvature * (t2 - t1), curvature


def load_rate(model: MachineModel, time: float) -> float:
    """The rate [N m/s] at which the scenario's external load changes at `time` [s] (a ramp's; 0 when held)."""
    piece = model.piece_at(time)
    return 0.0 if piece is None else piece.slope


def held_load_until(model: MachineModel, time: float) -> int | float:
    """How long the scenario's external load at `time` [s] stays the same number: while it is held (a piece of slope
    0), the first whole nanosecond [ns] at which it may change, the next piece's start (for every whole nanosecond n
    from `time` below it, model.external_load(seconds(n)) is the same number), or math.inf when it is held to the end;
    on a ramp, `time` in nanoseconds (it holds for that instant only)."""
    piece = model.piece_at(time)
    if piece is not None and piece.slope != 0.0:
        return to_nanoseconds(time)
    later = [candidate.start for candidate in model.load_pieces if candidate.start > time]
    return first_nanosecond_at(later[0]) if later else math.inf


def first_nanosecond_at(time: float) -> int:
    """The smallest whole nanosecond [ns] whose time in seconds (`seconds`) reaches `time` [s]: the first exchange time
    at which a load piece starting then is in force."""
    nanoseconds = to_nanoseconds(time)
    while seconds(nanoseconds - 1) >= time:
        nanoseconds -= 1
    while seconds(nanoseconds) < time:
        nanoseconds += 1
    return nanoseconds


def machine_subsystem(model: MachineModel) -> MachineModel:
    """The machine without its governor and without the scenario's load pieces (the load comes as an input)."""
    return dataclasses.replace(model, governor=None, load_pieces=())


def governor_subsystem(model: MachineModel) -> MachineModel:
    """The governor without the machine: unit constant inertia and no moments, so that omega' = 0 exactly."""
    return dataclasses.replace(
        model,
        inertia_constant=1.0,
        reduced=None,
        has_weight=False,
        effects=(),
        load_pieces=(),
        coupling=None,
        clutch=None,
        joint_friction=None,
    )


def cosimulation_refusal(model: MachineModel) -> str | None:
    """Why a scene cannot be co-simulated (the nodes, simulate --exchange-step), naming the key, its value and what
    would do; None when it can. Checked before anything starts, so that a refusal comes at once: the energy method
    steps in phi, not in time; an RK4 step outside the stability region of a subsystem's coupling; a solver method
    the fast path has no stepper for on solver.path: fast."""
    solver = model.scene.solver
    if solver.method == "energy":
        return (
            "solver.method: 'energy' integrates in the crank angle, but the co-simulation exchanges signals at "
            "times; choose a method in time, e.g. --set solver.method=DOP853"
        )
    subsystems = [machine_subsystem(model)] + ([governor_subsystem(model)] if model.governor is not None else [])
    for subsystem in subsystems:
        reason = rk4_stability_refusal(subsystem) or stiffness_refusal(subsystem)
        if reason is not None:
            return reason
    if runs_compiled(solver):
        from mech_regulator.solvers.compiled import fast_path_refusal

        return fast_path_refusal(model)
    return None


def segment_for(subsystem: MachineModel):
    """What steps a subsystem over one exchange step (time_domain._segment's arguments and result): the reference
    path's _segment, or on solver.path: fast the subsystem's compiled twin (compiled here, once). A scene that cannot
    be co-simulated raises SceneError (cosimulation_refusal)."""
    reason = cosimulation_refusal(subsystem)
    if reason is not None:
        raise SceneError(reason)
    if not runs_compiled(subsystem.scene.solver):
        return _segment
    from mech_regulator.solvers.compiled.run import compiled_segment  # numba is imported only when needed

    return compiled_segment(subsystem)


def pieces_for(subsystem: MachineModel):
    """What steps a subsystem along the machine's speed samples, piece by piece, each piece started with the crank's
    speed set (follow_samples' arguments and result): follow_samples with the reference path's _segment, or on
    solver.path: fast its compiled twin, which works out the pieces in compiled code and goes on from piece to piece
    inside its compiled calls (solvers/compiled/run.compiled_pieces)."""
    if not runs_compiled(subsystem.scene.solver):
        return functools.partial(follow_samples, _segment)
    from mech_regulator.solvers.compiled.run import compiled_pieces  # numba is imported only when needed

    return compiled_pieces(subsystem)


def dense_speeds_for(subsystem: MachineModel):
    """What samples the speed of one compiled call's dense output in one compiled call (speed_samples' dense_speeds):
    None on the reference path, on solver.path: fast results.StepsDense.speed_samples."""
    if not runs_compiled(subsystem.scene.solver):
        return None
    from mech_regulator.solvers.compiled.results import StepsDense  # numba is imported only when needed

    return StepsDense.speed_samples


def one_cycle_back_for(subsystem: MachineModel):
    """What predicts the machine's speed one cycle of the crank back (quadratics.speeds_one_cycle_back's arguments and
    result): that function, or on solver.path: fast its compiled twin (solvers/compiled/pieces.py), by its entry
    (steppers.entry_point)."""
    if not runs_compiled(subsystem.scene.solver):
        return speeds_one_cycle_back
    from mech_regulator.solvers.compiled.pieces import compiled_speeds_one_cycle_back  # numba only when needed
    from mech_regulator.solvers.compiled.steppers import entry_point

    return entry_point(compiled_speeds_one_cycle_back)


def follow_samples(
    segment, subsystem: MachineModel, samples: list, y: np.ndarray, mode, trajectory: Trajectory, split: int = -1
):
    """follow_pieces along the pieces of the speed samples (a list of (times [s], omega [rad/s]), each following on
    where the one before ends; speed_pieces of each in turn); split: a piece's index in that sequence."""
    pieces = [piece for part in samples for piece in speed_pieces(part)]
    return follow_pieces(segment, subsystem, pieces, y, mode, trajectory, split)


def follow_pieces(
    segment, subsystem: MachineModel, pieces: list, y: np.ndarray, mode, trajectory: Trajectory, split: int = -1
):
    """Step a subsystem over pieces (LoadPiece, t_start [s], t_end [s], the crank's speed at its start [rad/s]) one
    after the other with segment (time_domain._segment's arguments and result), each from the state so far with
    y[1] set to its start speed, until one fails; returns the state and mode at the end and, given split (an index),
    how pieces[split] started: (the state there, its speed set, the mode before it, the trajectory's events so far),
    None when the run did not get there."""
    at_split = None
    for index, (piece, t_start, t_end, omega) in enumerate(pieces):
        y = y.copy()
        y[1] = omega
        if index == split:
            at_split = (y.copy(), mode, len(trajectory.events))
        y, mode = segment(subsystem, piece, t_start, t_end, y, mode, trajectory, None)
        if trajectory.status != "complete":
            break
    return y, mode, at_split


def _governor_mode(mode: tuple[str, ...]) -> Mode:
    """A mode of the governor's own trajectory as the governor's Mode, (sleeve's, servo's)."""
    sleeve, servo = mode
    return sleeve, servo


def _accumulate(stats: SolverStats, stretch: Trajectory) -> tuple[str, str]:
    """Add a stretch's solver statistics to the running totals; returns its status and message."""
    totals, added = vars(stats), vars(stretch.stats)
    for name in _STATISTICS:
        totals[name] += added[name]
    return stretch.status, stretch.message


class ExchangeTimes:
    """The exchange times [ns] of a co-simulation, which the machine decides and sends with its state (the end of its
    predicted samples: both sides agree on them; the governor and the scenario answer whatever time it stamps). With a
    fixed step [ns] t_k = k step, the last at the end, and each load change of the scenario (the step that would
    cross it ends on it; the bundled scenes' load changes lie on their grids). With a tolerance [-] (the corrected
    coupling) the step is adaptive (docs/speed.md, "The adaptive step tried again": it beats the fixed step on machines without a firing
    ripple, not on the bundled engines): after each step the machine's predictor miss, how far its predicted speed at
    the step's end lies from the corrected one relative to the largest speed so far, a local error estimate of the
    coupling of order ERROR_ORDER in the step, sets the next step, h * SAFETY * (tolerance /
    miss)^(1 / ERROR_ORDER) rounded down to the ladder step * 2^j (j from -ADAPTIVE_HALVINGS to ADAPTIVE_DOUBLINGS, so
    that the prediction the machine makes one step ahead is mostly for the step then taken); each load change of the
    scenario is an exchange time, and the step after it, as the first, starts RESTART_HALVINGS halvings small. A step
    whose miss is above the tolerance is not done again: the machine has sent the next time before it knows it."""

    def __init__(self, model: MachineModel, end: int, step: int, tolerance: float | None = None):
        self.end = end  # [ns]
        self.tolerance = tolerance
        self.smallest = step // 2**ADAPTIVE_HALVINGS if tolerance is not None else step  # [ns]
        self.largest = step * 2**ADAPTIVE_DOUBLINGS if tolerance is not None else step  # [ns]
        self._restart = step // 2**RESTART_HALVINGS if tolerance is not None else step  # [ns]
        self.step = step  # [ns] the fixed step, or the adaptive step's ladder
        self.events = sorted({first_nanosecond_at(start) for start in model.breakpoints()} - {0})  # [ns] the load
        # changes, each an exchange time
        self.nominal = self._restart  # [ns] the step as the error estimate sets it (before an event or the end cut it)
        self.scale = 0.0  # [rad/s] the largest speed so far
        self.now = 0  # [ns]
        self.next = self._step_end(0)  # [ns]

    def _step_end(self, start: int) -> int:
        """The exchange time [ns] after `start` [ns]: on the next load change or the end when it comes within the step;
        fixed, else the next time k step on the grid (a step cut by a load change ends on it and the grid goes on);
        adaptive, the nominal step, or halfway to the load change or the end when it would leave less than the
        smallest step after it."""
        stop = min([event for event in self.events if event > start] + [self.end])
        if self.tolerance is None:
            return min(stop, (start // self.step + 1) * self.step)
        if stop - start <= self.nominal:
            return stop
        if stop - start < self.nominal + self.smallest:
            return start + (stop - start) // 2
        return start + self.nominal

    def after_next(self) -> int:
        """The exchange time [ns] expected after the next one: the next step at the nominal step as it is now (the
        step the machine predicts ahead while the governor answers)."""
        return self._step_end(self.next) if self.next < self.end else self.next

    def move_on(self, predicted: Samples | None, corrected: Samples | None, omega: float) -> None:
        """The step to `next` done: move there and, adaptive, set the nominal step from the predictor's miss, the
        predicted speed samples' last value against the corrected ones' (corrected coupling; omega [rad/s] the speed
        there), or start small again on a load change."""
        landed_on_event = self.next in self.events
        self.now = self.next
        if self.tolerance is not None:
            self.scale = max(self.scale, abs(omega))
            miss = abs(predicted[1][-1] - corrected[1][-1]) / self.scale if predicted and corrected else math.inf
            if landed_on_event or not math.isfinite(miss):  # a step that failed, or a load change
                self.nominal = self._restart
            else:
                factor = min(max(SAFETY * (self.tolerance / max(miss, 1e-300)) ** (1.0 / ERROR_ORDER), 0.2), 2.0)
                nominal = self.smallest
                while nominal * 2 <= min(self.nominal * factor, self.largest):
                    nominal *= 2
                self.nominal = nominal
        self.next = self._step_end(self.now) if self.now < self.end else self.now


@dataclass
class CoSimulation:
    """A co-simulated run sampled at its exchange times: times [s], the full state there (machine
    (phi, omega), the governor's states, then a coupling's, as MachineModel.state_names; n_states x n), the throttle [-] and external load
    [N m] held from each time on, the governor's mode changes (time, what, new mode), and how it ended."""

    times: np.ndarray
    states: np.ndarray
    throttle: np.ndarray
    external_load: np.ndarray
    events: list[tuple[float, str, Mode]]
    status: str
    message: str
    tripped_at: float | None

    def trajectory(self, model: MachineModel) -> SampledTrajectory:
        """The run as a trajectory for the analysis functions (linear between exchange times)."""
        initial = model.initial_mode(model.initial_state())
        run = SampledTrajectory(
            method=f"co-simulation ({model.scene.solver.method})",
            t_start=float(self.times[0]),
            times=self.times,
            states=self.states,
            status=self.status,
            message=self.message,
        )
        run.modes = ([(0.0, initial)] if initial is not None else []) + [(t, mode) for t, _, mode in self.events]
        run.events = [(t, name) for t, name, _ in self.events]
        return run


def exchange_times_refusal(
    duration: float, exchange_step: float, exchange_tolerance: float | None, coupling: str
) -> str | None:
    """Why a co-simulation cannot exchange at these times, naming the option, its value and what would do (None when
    it can): too many exchanges over the scene's duration (at the adaptive step's smallest, with a tolerance), a
    tolerance that is not a number in (0, 1) or, since the adaptive step is set by the corrector's miss, a tolerance
    without the corrected coupling; duration [s] the run's."""
    if exchange_tolerance is None:
        return exchange_refusal("--exchange-step", exchange_step, duration)
    if not 0.0 < exchange_tolerance < 1.0:
        return f"--exchange-tolerance {exchange_tolerance:g}: expected a relative error between 0 and 1, e.g. 1e-6"
    if coupling != "corrected":
        return (
            f"--exchange-tolerance {exchange_tolerance:g} with --coupling {coupling}: the adaptive exchange step is "
            "set by the corrected coupling's predictor miss; expected --coupling corrected, or no tolerance"
        )
    return exchange_refusal(
        f"the adaptive exchange step's smallest (--exchange-step / {2**ADAPTIVE_HALVINGS})",
        exchange_step / 2**ADAPTIVE_HALVINGS,
        duration,
    )


def cosimulate(
    model: MachineModel,
    exchange_step: float,
    overspeed_trip: float = 0.0,
    progress: Progress | None = None,
    coupling: str = "hold",
    exchange_tolerance: float | None = None,
) -> CoSimulation:
    """Run the scene's scenario as the nodes do in lockstep: machine and governor exchange omega and the
    throttle, and the scenario's load is sampled, every exchange_step [s] (rounded to whole ns; and at each load
    change: ExchangeTimes) or, given exchange_tolerance [-] (corrected coupling), at the adaptive exchange times
    (ExchangeTimes), with the coupling `hold`, `waveform` or `corrected` (module docstring)."""
    step = to_nanoseconds(exchange_step)
    if step <= 0:
        raise ValueError(f"exchange_step = {exchange_step!r} s: expected at least 1 ns")
    if coupling not in COUPLINGS:
        raise ValueError(f"coupling = {coupling!r}: expected one of {', '.join(COUPLINGS)}")
    refusal = exchange_times_refusal(model.scene.scenario.duration, exchange_step, exchange_tolerance, coupling)
    if refusal is not None:
        raise SceneError(refusal)
    end = to_nanoseconds(model.scene.scenario.duration)
    exchanges = ExchangeTimes(model, end, step, exchange_tolerance)
    machine = MachineStepper(model, overspeed_trip)
    governor = GovernorStepper(model) if model.governor is not None else None
    rows, inputs = [], []
    omega_middle = None  # the machine's speed at the middle of the last step (waveform coupling)
    corrected = waveform = None  # the corrected coupling's speed samples of the last step, throttle samples of the next
    corrector = governor if coupling == "corrected" else None  # the governor answering the corrected coupling
    tentative = governor.throttle if governor is not None else 1.0
    action = None  # the speed's direct action on the governor's throttle over the next step (corrected coupling)
    predicted = None  # the corrected coupling's predicted speed samples over the next step
    try:
        while True:
            now = seconds(exchanges.now)
            if corrector is not None:
                predicted = machine.predict(seconds(exchanges.next), tentative) if exchanges.now < end else None
                if exchanges.next < end:  # the nodes' machine does this while the governor answers
                    machine.predict_ahead(seconds(exchanges.after_next()), tentative)
                throttle, waveform, action = corrector.answer_corrected(
                    now, float(machine.state[1]), corrected, predicted
                )
            else:
                throttle = governor.answer(now, float(machine.state[1]), omega_middle) if governor is not None else 1.0
            throttle = machine.applied_throttle(throttle)
            load = model.external_load(now)
            rows.append(
                np.concatenate([machine.state[:2], governor.state[2:], machine.state[2:]])
                if governor is not None
                else machine.state.copy()
            )
            inputs.append((now, throttle, load))
            if exchanges.now >= end or machine.status != "complete" or (governor and governor.status != "complete"):
                break
            following = seconds(exchanges.next)
            if corrector is not None:
                corrected = machine.correct(throttle, waveform, load, load_rate(model, now), action)
                tentative = machine.tentative
            elif coupling == "waveform" and governor is not None:
                omega_middle = machine.advance_following(following, throttle, load)
            else:  # corrected without a governor: only the load's ramp is followed
                machine.advance(
                    following, throttle, load, load_rate=load_rate(model, now) if coupling == "corrected" else 0.0
                )
            exchanges.move_on(predicted, corrected, float(machine.state[1]))
            if progress is not None:
                progress(machine.time)
        status, message = "complete", ""
    except KeyboardInterrupt:
        status, message = "interrupted", f"interrupted by the user at t = {machine.time:.6g} s"
    for part in (machine, governor):
        if part is not None and part.status != "complete":
            status, message = part.status, part.message
    times, throttles, loads = (np.array(column) for column in zip(*inputs))
    return CoSimulation(
        times=times,
        states=np.array(rows).T,
        throttle=throttles,
        external_load=loads,
        events=governor.events if governor is not None else [],
        status=status,
        message=message,
        tripped_at=machine.tripped_at,
    )
