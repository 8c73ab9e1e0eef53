"""governor_node: the scene's direct or indirect governor, simulated by the core, answering the
machine's speed with its throttle.

Subscribes `joint_states` (joint "crank", velocity omega [rad/s], stamped with the simulation time).
For each message it advances its own states to that time with the previous speed held, then publishes
`throttle` (sensor_msgs/JointState, joint "throttle", position 0..1) stamped with the same time,
`governor/state` (sensor_msgs/JointState: "sleeve" z [m] and z' [m/s], "arm" angle [rad] and rate
[rad/s], "throttle", and for indirect action "servo" [-] (and "feedback_shift" [m]); a PI governor's "throttle" and
"integral", its integral part [-]; several exchange times in one
message, each group opened by a joint "stamp": common.Batch, sent at least every common.BATCH_PERIOD s of wall
time and whenever the machine's run state changes) and each mode
change (a stop reached, the sleeve sticking or breaking away) on `governor/events` (std_msgs/String,
JSON: time [s], event, mode). The same code as mech_regulator.solvers.cosim.cosimulate. With the
`coupling` waveform it follows the speed at the step's middle ("crank_midstep"); with corrected it integrates
the step that ended for good following the machine's corrected speed samples ("crank_corrected" entries: the
speed in velocity, the sample's time in effort), then the next step tentatively following the predicted ones
("crank_predicted"), and sends its tentative throttle over that step with its answer ("throttle_tentative"
entries: the throttle in position, the time in effort; GovernorStepper.answer_corrected); a governor whose throttle the
crank speed moves directly (the PI law's proportional part) sends its command before the stops there instead, with
the command at the stamp ("throttle_command") and its sensitivity to the speed ("throttle_per_speed" [s/rad]), both in
position (solvers.cosim.SpeedAction). With hold, having
answered, it anticipates: it advances its states over the next step (as long as the last one), with
the speed just received held, while the machine integrates that step, so that its next answer is
immediate (GovernorStepper.anticipate: an exchange time other than the expected one is computed
afresh, so the numbers never depend on it). A speed stamped 0 after later ones starts a new trial (the
machine's ~/reset): the governor starts again from its initial state. It ends by itself when the machine
says the run is finished (`machine/status`).
"""

from __future__ import annotations

import json
import math
import sys

from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from mech_regulator.nodes.common import (
    BATCH_QOS,
    COMMAND_QOS,
    ERROR,
    OK,
    STATE_QOS,
    Batch,
    JointMessage,
    RunState,
    SteadyNode,
    coupling_parameter,
    diagnostics,
    float_parameter,
    follow_run_state,
    peer_parameter,
    run,
    scene_model,
    sent_samples,
)
from mech_regulator.nodes.trust import (
    BadMessage,
    Refusals,
    RunStateMessage,
    Speakers,
    bounded,
    in_order,
    joint_fields,
    receive,
    stamp_of,
)
from mech_regulator.nodes.wire import JointStateReader
from mech_regulator.scene import SceneError
from mech_regulator.solvers.cosim import GovernorStepper, seconds

DIAGNOSTICS_PERIOD = 1.0  # [s] of wall time
ACTION_JOINTS = ("throttle", "throttle_command", "throttle_per_speed")  # the answer's joints with the speed's action


class GovernorNode(SteadyNode):
    """The governor of `scene_file` (see the module docstring)."""

    def __init__(self):
        super().__init__("governor")
        model = scene_model(self)
        if model.governor is None:
            raise SceneError(
                f"scene '{model.scene.name}' has no governor: governor_node needs a scene with a 'governor:' section"
            )
        self.model = model
        self.coupling = coupling_parameter(self)
        self.max_speed = float_parameter(
            self, "max_speed", 1e4, "crank speeds beyond +- this [rad/s] are rejected", 0.0, 1e9
        )
        self.start_trial()
        self.done = False
        self.refusals = Refusals(self, self.report)
        self.speakers = Speakers(self)
        machine = peer_parameter(self, "machine")
        for topic in ("joint_states", "machine/status"):
            self.speakers.allow(topic, machine)
        self.throttle_publisher = self.create_publisher(JointState, "throttle", COMMAND_QOS)
        self.answer = JointMessage()  # throttle, refilled at every exchange
        self.states = Batch(self.create_publisher(JointState, "governor/state", BATCH_QOS), self.get_logger().warning)
        self.events_publisher = self.create_publisher(String, "governor/events", STATE_QOS)
        self.diagnostics_publisher = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        receive(
            self,
            JointState,
            "joint_states",
            self.on_joint_states,
            COMMAND_QOS,
            self.refusals,
            self.speakers,
            reader=JointStateReader(),  # the critical path's message as bytes (wire)
        )
        self.create_timer(DIAGNOSTICS_PERIOD, self.report)
        follow_run_state(self, self.on_run_state, self.refusals, self.speakers)

    def start_trial(self) -> None:
        """The governor's initial state: at the start and when the machine starts a new trial."""
        self.stepper = GovernorStepper(self.model)
        self.time_ns: int | None = None
        self.previous_ns: int | None = None  # the exchange time before time_ns [ns]
        self.throttle = self.stepper.throttle  # [-] the last answer
        self.reported_events = 0

    def on_run_state(self, state: RunStateMessage) -> None:
        """Send the states gathered so far (the machine stops, pauses or starts again), and end by itself when the
        machine has finished, once the recorder has them all (common.Batch.deliver), with its last diagnostics (what
        it rejected, even in a run shorter than their period)."""
        self.done = state.state == RunState.FINISHED
        if self.done:
            self.states.deliver()  # every state acknowledged by the recorder before the node ends
            self.report()
        else:
            self.states.send()

    def on_joint_states(self, message: JointState) -> None:
        """Answer the crank speed at a stamped time with the throttle at that time (speakers: from the machine only;
        every field read is checked first: trust.BadMessage)."""
        names = joint_fields(message, "velocity")
        if "crank" not in names:
            raise BadMessage("wrong joint name", f"JointState names {names}, expected a joint 'crank'")
        speed = (-self.max_speed, self.max_speed, "crank velocity [rad/s] (parameter max_speed)")
        omega = bounded(message.velocity[names.index("crank")], *speed)
        omega_middle = (
            bounded(message.velocity[names.index("crank_midstep")], *speed) if "crank_midstep" in names else None
        )
        corrected, predicted = (
            sent_samples(message, name, "velocity", -self.max_speed, self.max_speed)
            for name in ("crank_corrected", "crank_predicted")
        )
        when = stamp_of(message.header.stamp)
        if when == 0 and self.time_ns:  # the machine's ~/reset (only the machine speaks here): a new trial
            self.states.send()
            self.start_trial()
        when = in_order(when, self.time_ns, "joint_states")
        self.previous_ns, self.time_ns = self.time_ns, when
        waveform = action = None  # corrected coupling: the tentative throttle over the next step, the speed's action
        if self.coupling == "corrected":
            throttle, waveform, action = self.stepper.answer_corrected(seconds(when), omega, corrected, predicted)
        else:
            throttle = self.stepper.answer(seconds(when), omega, omega_middle)
        self.throttle = throttle
        answered: tuple[str, ...] = ("throttle",)
        positions = [throttle]
        if action is not None:
            answered, positions = ACTION_JOINTS, [throttle, action.command, action.per_speed]
        answer = self.answer.fill(
            when,
            answered,
            positions,
            [math.nan] * len(answered),
            [math.nan] * len(answered),
            (("throttle_tentative", "position", waveform),),
        )
        self.throttle_publisher.publish(answer)  # first: the machine waits for it
        for t, event, mode in self.stepper.events[self.reported_events :]:
            self.events_publisher.publish(String(data=json.dumps({"time": t, "event": event, "mode": list(mode)})))
        self.reported_events = len(self.stepper.events)
        values = self.stepper.outputs()
        joints = self.model.governor.joints()  # GovernorKind.joints
        self.states.add(
            when,
            [name for name, _, _ in joints],
            [values[position] for _, position, _ in joints],
            [0.0 if velocity is None else values[velocity] for _, _, velocity in joints],
            [],
        )
        self.states.send_when_due()  # after the answer, while the machine integrates
        if self.stepper.status != "complete":
            self.report()
        elif self.coupling == "hold" and self.previous_ns is not None and when > self.previous_ns:  # while the machine
            # does the same step (with the other couplings the governor's step needs the machine's speed over it)
            self.stepper.anticipate(seconds(2 * when - self.previous_ns))

    def report(self) -> None:
        level, text = OK, "running"
        if self.stepper.status != "complete":
            level, text = ERROR, self.stepper.message
        level, text = self.refusals.status(level, text)
        mode = self.stepper.mode
        assert mode is not None, "a governor's stepper has the governor's mode"
        values = {
            "scene": self.model.scene.name,
            "sim_time": seconds(self.time_ns or 0),
            "throttle": self.throttle,
            "mode": "/".join(part for part in mode if part),
            "events": len(self.stepper.events),
        }
        array = diagnostics(self, level, text, values)
        array.status[0].values += self.refusals.key_values()
        self.diagnostics_publisher.publish(array)


def main() -> int:
    """Entry point of governor_node."""
    return run(GovernorNode)


if __name__ == "__main__":
    sys.exit(main())
