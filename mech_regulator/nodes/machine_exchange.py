"""The machine node's exchange, apart from its ROS plumbing (nodes/machine.py: parameters, topics, services, the run's
loop): a trial's bookkeeping from the scene's initial state, the inputs' messages checked and kept by the exchange
time they apply from (the throttle, its tentative waveform, the stamped load and how long it holds), which inputs an
exchange time still waits for, the throttle applied over a step (the governor's, or the fail-safe), the step itself
for each coupling (hold, waveform, corrected: the prediction and correction as solvers.cosim.cosimulate), the
machine/moments batch's contents and the diagnostics' values. MachineNode (nodes/machine.py) has these methods."""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING

import numpy as np

from mech_regulator.nodes.common import ERROR, OK, WARN, diagnostics, sent_samples
from mech_regulator.nodes.trust import BadMessage, bounded, in_order, joint_fields, not_ahead, stamp_of
from mech_regulator.solvers.cosim import (
    NANOSECONDS,
    ExchangeTimes,
    MachineStepper,
    Samples,
    SpeedAction,
    seconds,
    to_nanoseconds,
)

if TYPE_CHECKING:
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import WrenchStamped
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    from mech_regulator.nodes.machine import MachineNode


class MachineExchange:
    """MachineNode's exchange, mixed into it. Their self is the MachineNode (its parameters, publishers and
    stepper): mypy checks them against it but refuses a self type narrower than this class, hence the
    `type: ignore[misc]` on their first lines."""

    def start_trial(self: MachineNode) -> None:  # type: ignore[misc]
        """The scene's initial state at t = 0 with its initial inputs: at the start and at every ~/reset."""
        self.trial += 1
        self.stepper = MachineStepper(self.model, self.overspeed)
        self.exchanges = ExchangeTimes(self.model, self.end_ns, self.step_ns, self.exchange_tolerance)  # the machine
        # decides them and sends each with its state (the end of its predicted samples)
        self.throttle = self.model.governor.throttle(self.model.initial_state()) if self.model.governor else 1.0
        self.load = self.model.external_load(0.0)
        self.load_rate = 0.0  # [N m/s] the scenario's ramp over the next step (corrected coupling)
        self.throttle_stamp: int | None = None  # stamp [ns] of the newest throttle received
        self.stamped_throttle: dict[int, float] = {}
        self.stamped_load: dict[int, tuple[float, float]] = {}  # [ns] -> (load [N m], its rate [N m/s])
        self.load_holds: tuple[int, int | float, float, float] | None = None  # the newest stamped load that holds
        # over later exchange times: (from, until [ns], load [N m], rate [N m/s])
        self.last_stamped_load: float | None = None
        self.pending_load: float | None = None
        self.silent: set[str] = set()  # lockstep inputs that timed out and are no longer waited for
        self.wrong_stamp: int | None = None  # [ns] the last throttle stamped with no exchange time (external
        # controller)
        self.failing_safe = False
        self.now_ns = 0
        self.max_lag = 0.0  # realtime: [s] of simulation time the published state fell behind the wall clock, at most
        self.omega_middle: float | None = None  # [rad/s] at the middle of the last step (waveform coupling)
        self.corrected: Samples | None = None  # corrected coupling: the speed over the last step, as done for good,
        self.predicted: Samples | None = None  # and as predicted over the next one
        self.stamped_waveform: dict[int, tuple[Samples, SpeedAction | None]] = {}  # [ns] -> the governor's tentative
        # throttle over that step and the speed's direct action on it
        self.held: tuple | None = None  # the last exchange's (time [ns], time [s], state, throttle applied [-], load
        # [N m], wall-clock time [s] its joint_states went out) for its machine/moments (add_moments, complete_moments)
        self.published_at = 0.0  # [s] time.monotonic() when the last joint_states went out
        self.published_exchanges = 0  # exchange times published in this trial (the recorder counts what reached it)
        self.tentative = self.throttle  # [-] the governor's tentative throttle at the end of the last step

    # ---------------------------------------------------------------------------------------------
    # Inputs: every message is checked before it touches anything.

    def on_throttle(self: MachineNode, message: JointState) -> None:  # type: ignore[misc]
        """The throttle's answer (speakers: the governor node; with controller external, whichever node publishes it
        first): the throttle in 0..1 for an exchange time the machine has published, not behind the newest taken;
        with the corrected coupling, its tentative throttle over the step when it sends one, and the speed's direct
        action on it (speed_action). An external controller's answer stamped other than the exchange it answers is
        kept to be named when it times out."""
        names = joint_fields(message, "position")
        if "throttle" not in names:
            raise BadMessage("wrong joint name", f"JointState names {names}, expected a joint 'throttle'")
        value = bounded(message.position[names.index("throttle")], 0.0, 1.0, "throttle position (an opening)")
        if self.controller == "external" and self.time_mode == "lockstep":
            sent = message.header.stamp.sec * NANOSECONDS + message.header.stamp.nanosec
            if sent != self.now_ns:  # said when the controller times out (controller.silent), even a wall-clock one
                self.wrong_stamp = sent
        when = in_order(
            not_ahead(stamp_of(message.header.stamp), self.now_ns, "throttle"), self.throttle_stamp, "throttle"
        )
        action = speed_action(message, names)
        low, high = (0.0, 1.0) if action is None else (-MAX_THROTTLE_COMMAND, MAX_THROTTLE_COMMAND)
        waveform = sent_samples(message, "throttle_tentative", "position", low, high)
        self.throttle_stamp = when
        self.stamped_throttle[when] = value
        if self.corrects and waveform is not None:
            self.stamped_waveform[when] = (waveform, action)
        self.silent.discard("throttle")

    def on_load(self: MachineNode, message: Float64, speaker: str) -> None:  # type: ignore[misc]
        """A load from anyone (load_torque: the documented way to poke a run), within +-max_load_torque; from another
        node than the run's scenario (speaker: its node's name, '' when the graph does not name it in this namespace)
        a disturbance that alters the results, once per node: the run's loads are no longer the scene's."""
        self.pending_load = bounded(
            message.data, -self.max_load_torque, self.max_load_torque, "load_torque [N m] (parameter max_load_torque)"
        )
        if speaker != self.scenario_name:
            self.refusals.disturb(
                f"load_torque from {repr(speaker) if speaker else 'a node the graph does not name in this namespace'}:"
                " a load the scene does not have, applied from the next exchange time on",
                alters_results=True,
            )

    def on_stamped_load(self: MachineNode, message: WrenchStamped) -> None:  # type: ignore[misc]
        """The scenario's load (speakers: from the scenario node only) for an exchange time the machine has published,
        not behind the newest taken: within +-max_load_torque, and so at the end of the step its rate ramps over;
        held up to force.x (NaN refused, +inf or beyond the run's end: to the end)."""
        value, rate, until = message.wrench.torque.z, message.wrench.force.z, message.wrench.force.x
        bounds = (-self.max_load_torque, self.max_load_torque)
        bounded(value, *bounds, "load_torque_stamped torque.z [N m] (parameter max_load_torque)")
        bounded(
            value + rate * seconds(self.exchanges.largest),
            *bounds,
            "load_torque_stamped torque.z + force.z (its rate) * the longest exchange step [N m] (parameter "
            "max_load_torque)",
        )
        if math.isnan(until):
            raise BadMessage("not finite", "load_torque_stamped force.x (held until) = nan, expected a time [s] or inf")
        newest = max(self.stamped_load, default=None)
        when = in_order(
            not_ahead(stamp_of(message.header.stamp), self.now_ns, "load_torque_stamped"), newest, "load_torque_stamped"
        )
        self.stamped_load[when] = (value, rate)
        if until > seconds(when):  # beyond the run's end: to the end
            self.load_holds = (when, to_nanoseconds(until) if until <= seconds(self.end_ns) else math.inf, value, rate)
        self.silent.discard("load")

    def missing_inputs(self: MachineNode) -> list[str]:  # type: ignore[misc]
        """The lockstep inputs not yet received for the current exchange time (and not given up on)."""
        missing = []
        if (
            "throttle" in self.lockstep_inputs
            and "throttle" not in self.silent
            and self.now_ns not in self.stamped_throttle
        ):
            missing.append("throttle")
        if (
            "load" in self.lockstep_inputs
            and "load" not in self.silent
            and self.now_ns not in self.stamped_load
            and self.held_load() is None
        ):
            missing.append("load")
        return missing

    def held_load(self: MachineNode) -> tuple[float, float] | None:  # type: ignore[misc]
        """(load [N m], rate [N m/s]) of the newest stamped load that holds at the current exchange time (force.x of
        load_torque_stamped), None when none does."""
        if self.load_holds is not None and self.load_holds[0] <= self.now_ns < self.load_holds[1]:
            return self.load_holds[2:]
        return None

    def applied_throttle(self: MachineNode) -> float:  # type: ignore[misc]
        """The throttle held over the next step: the governor's for this exchange time (lockstep) or its
        newest (realtime); the fail-safe if the governor is silent."""
        if self.time_mode == "lockstep":
            fresh = self.stamped_throttle.get(self.now_ns)
        else:
            newest = self.throttle_stamp
            fresh = self.stamped_throttle.get(newest) if newest is not None else None
            if newest is not None and seconds(self.now_ns - newest) > self.throttle_timeout:
                fresh = None
        for when in [when for when in self.stamped_throttle if when < self.now_ns]:
            self.stamped_throttle.pop(when)
            self.stamped_waveform.pop(when, None)
        expects_governor = (
            "throttle" in self.lockstep_inputs or self.time_mode == "realtime" and self.model.governor is not None
        )
        if fresh is not None:
            self.throttle = fresh
        elif expects_governor:
            if not self.failing_safe:
                self.get_logger().error(
                    f"no throttle for t = {seconds(self.now_ns):.6g} s: fail-safe '{self.fail_safe}'"
                )
            if self.fail_safe == "close":
                self.throttle = 0.0
        failing_safe = fresh is None and expects_governor
        if failing_safe != self.failing_safe:
            self.failing_safe = failing_safe
            if failing_safe and self.throttle_stamp is not None:  # a governor that had answered fell silent (when:
                # in the log; listed once): in lockstep only once given up on (collect_inputs: that one alters the
                # results); in realtime the numbers follow the wall clock anyway, and a late answer under load is one
                self.refusals.disturb(f"the governor fell silent: fail-safe '{self.fail_safe}'", alters_results=False)
            self.report(force=True)
        return self.throttle

    # ---------------------------------------------------------------------------------------------
    # The step and the outputs

    def advance(self: MachineNode, next_ns: int, throttle: float) -> None:  # type: ignore[misc]
        """Integrate to the next exchange time with the load held and the throttle held (hold coupling) or
        extrapolated, noting the speed at the step's middle (waveform coupling; MachineStepper.advance_following), or
        following the governor's tentative throttle over the step (corrected coupling: MachineStepper.correct), as
        solvers.cosim.cosimulate."""
        if self.corrects:
            waveform, action = (
                self.stamped_waveform.get(self.now_ns, (None, None)) if not self.failing_safe else (None, None)
            )
            self.corrected = self.stepper.correct(throttle, waveform, self.load, self.load_rate, action)
            self.tentative = self.stepper.tentative
        elif self.waveform:
            self.omega_middle = self.stepper.advance_following(seconds(next_ns), throttle, self.load)
        else:  # corrected without a governor: only the load's ramp is followed
            self.stepper.advance(
                seconds(next_ns), throttle, self.load, load_rate=self.load_rate if self.follows_ramps else 0.0
            )

    def add_moments(self: MachineNode) -> None:  # type: ignore[misc]
        """machine/moments at the last exchange time, with the inputs that held from there (`held`: noted then), to the
        batch (common.Batch: sent after a later exchange's joint_states, with the wall-clock time that exchange's
        joint_states went out), deferred: complete_moments computes the batch's moments together when it goes out,
        while the peers answer an exchange (off the critical path of the lockstep). Nothing when they are in
        already."""
        if self.held is not None:
            self.moments.defer(self.held)
            self.held = None

    def complete_moments(self: MachineNode, held: list[tuple]) -> None:  # type: ignore[misc]
        """Add the deferred exchanges (add_moments' `held`) to machine/moments, their outputs computed in one call
        (MachineStepper.outputs_over): the moments on the crank by source and the external load applied [N m]
        (against the motion, where the scene applies it: on the crank, or on a two-mass machine's driven part, where
        the crank's `external` is 0), and the state as joint_states had it (crank phi, omega; a two-mass machine's
        twist and omega_driven)."""
        whens, held_times, states, throttles, loads, published = zip(*held)
        outputs = self.stepper.outputs_over(
            np.array(held_times), np.column_stack(states), np.array(throttles), np.array(loads)
        )
        names = ["drive", "resistance", "external", "net", "load", "crank", "throttle"]
        for index, (when, state, throttle, load, published_at) in enumerate(
            zip(whens, states, throttles, loads, published)
        ):
            efforts = [float(outputs[name][index]) for name in names[:4]] + [load, math.nan, math.nan]
            positions = [math.nan] * 5 + [float(state[0]), throttle]
            velocities = [math.nan] * 5 + [float(state[1]), math.nan]
            extra = []
            if self.model.coupling is not None:
                extra.append("coupling")
                positions.append(float(outputs["twist"][index]))
                velocities.append(math.nan)
                efforts.append(math.nan)
            if self.model.driven is not None:
                extra.append("driven")
                positions.append(math.nan)
                velocities.append(float(outputs["omega_driven"][index]))
                efforts.append(math.nan)
            self.moments.add(when, names + extra, positions, velocities, efforts, wall=published_at)

    def send_moments(self: MachineNode) -> None:  # type: ignore[misc]
        """Send machine/moments now (common.Batch.send), the last exchange's with them (add_moments): the run ends,
        pauses, holds or resets."""
        self.add_moments()
        self.moments.send()

    def diagnostics(self: MachineNode, finished: bool = False) -> DiagnosticArray:  # type: ignore[misc]
        """/diagnostics' contents: the run's level and message (the solver's failure, an overspeed trip, the
        fail-safe, the refusals; `finished` at the end) and its values (time, inputs, RHS evaluations, lag; at the end
        finished_at_ns and `exchanges`, the exchange times published in the trial, which the recorder counts)."""
        elapsed = max(time.monotonic() - self.wall_start, 1e-9)
        level, message = OK, "running"
        if self.stepper.status != "complete":
            level, message = ERROR, self.stepper.message
        elif self.stepper.tripped_at is not None:
            level, message = ERROR, f"overspeed trip at t = {self.stepper.tripped_at:.6g} s: throttle closed"
        elif self.failing_safe or self.silent:
            level, message = (
                WARN,
                f"fail-safe ({self.fail_safe}): no input from {', '.join(sorted(self.silent)) or 'the governor'}",
            )
        level, message = self.refusals.status(level, message)
        if finished and level == OK:
            message = "finished"
        values = {
            "scene": self.model.scene.name,
            "time_mode": self.time_mode,
            "sim_time": seconds(self.now_ns),
            "end_time": seconds(self.end_ns),
            "real_time_factor": f"{seconds(self.now_ns) / elapsed:.4g}",
            "throttle": self.throttle,
            "external_load": self.load,
            "rhs_evaluations": self.stepper.stats.nfev,
            "fail_safe_active": self.failing_safe,
            "tripped_at": self.stepper.tripped_at,
        }
        if self.time_mode == "realtime":
            values["max_lag_s"] = self.max_lag
        if finished:
            values["finished_at_ns"] = self.now_ns
            values["exchanges"] = self.published_exchanges
        array = diagnostics(self, level, message, values)
        array.status[0].values += self.refusals.key_values()
        return array


MAX_THROTTLE_PER_SPEED = 10.0  # [s/rad] the largest |d command / d omega| taken (a PI governor's K_p / omega_s: 3 /
# 224 on engine_pi; this one swings the throttle's whole travel over 0.1 rad/s)
MAX_THROTTLE_COMMAND = 1e3  # [-] the largest |command| taken in a tentative command (the throttle before its stops)


def speed_action(message: JointState, names: list[str]) -> SpeedAction | None:
    """The crank speed's direct action on the governor's throttle that a throttle message sends with its tentative
    throttle (solvers.cosim.SpeedAction: joints "throttle_command", the command at the stamp [-], and
    "throttle_per_speed", its sensitivity to the crank speed [s/rad], both in position), None without them; BadMessage
    for one without the other or a value beyond MAX_THROTTLE_COMMAND or MAX_THROTTLE_PER_SPEED."""
    given = [name for name in ("throttle_command", "throttle_per_speed") if name in names]
    if not given:
        return None
    if len(given) == 1:
        raise BadMessage(
            "missing joint", f"a throttle with {given[0]} only: expected both throttle_command and throttle_per_speed"
        )
    command = bounded(
        message.position[names.index("throttle_command")],
        -MAX_THROTTLE_COMMAND,
        MAX_THROTTLE_COMMAND,
        "throttle_command position [-] (the throttle before its stops)",
    )
    per_speed = bounded(
        message.position[names.index("throttle_per_speed")],
        -MAX_THROTTLE_PER_SPEED,
        MAX_THROTTLE_PER_SPEED,
        "throttle_per_speed position [s/rad] (d command / d omega)",
    )
    return SpeedAction(command, per_speed)
