"""scenario_node: plays the load events of a scene in simulation time.

In `lockstep` it answers the machine's `load_request` (std_msgs/Header stamped with an exchange time t) with the
scene's external load L(t) on `load_torque_stamped` (geometry_msgs/WrenchStamped, torque.z [N m], stamped t, in
force.z the rate [N m/s] at which it changes then, a ramp's, and in force.x the time [s] up to which L stays that
number, the next load event's, +inf: to the end; 0 on a ramp) — the machine waits for it, so the run is reproducible.
An answer whose load is held covers the exchange times after it up to that time (solvers.cosim.held_load_until): the
machine asks again only at an exchange time no answer covers, so the scenario reads one message per load event (at
every exchange of a ramp), not every `joint_states` (taking each of those cost it 0.19 ms of CPU an exchange on the
two cores the run shares: docs/speed.md, "The scenario off joint_states"). In `realtime` it reads `joint_states` for
the machine's time and publishes each change of the load on `load_torque` (std_msgs/Float64 [N m]), as any other
publisher would. Either way it logs each load event. It takes `load_request`, `joint_states` and `machine/status`
from its machine only (parameter machine_node; docs/ros.md, "Who may speak") and says what it refused on
`/diagnostics`. It ends by itself when the machine says the run is finished (`machine/status`).
"""

from __future__ import annotations

import sys

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Header

from mech_regulator.nodes.common import (
    COMMAND_QOS,
    OK,
    RunState,
    SteadyNode,
    diagnostics,
    follow_run_state,
    peer_parameter,
    run,
    scene_model,
    text_parameter,
)
from mech_regulator.nodes.trust import Refusals, RunStateMessage, Speakers, in_order, joint_fields, receive, stamp_of
from mech_regulator.solvers.cosim import held_load_until, load_rate, seconds

DIAGNOSTICS_PERIOD = 1.0  # [s] of wall time between diagnostics


class ScenarioNode(SteadyNode):
    """The load scenario of `scene_file` (see the module docstring)."""

    def __init__(self):
        super().__init__("scenario")
        self.model = scene_model(self)
        self.time_mode = text_parameter(
            self,
            "time_mode",
            "lockstep",
            "lockstep: answer every exchange time; realtime: publish load changes",
            ("lockstep", "realtime"),
        )
        self.stamped_publisher = self.create_publisher(WrenchStamped, "load_torque_stamped", COMMAND_QOS)
        self.load_publisher = self.create_publisher(Float64, "load_torque", COMMAND_QOS)
        self.diagnostics_publisher = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.refusals = Refusals(self, self.report)
        self.speakers = Speakers(self)
        machine = peer_parameter(self, "machine")
        for topic in ("load_request", "joint_states", "machine/status"):
            self.speakers.allow(topic, machine)
        if self.time_mode == "lockstep":
            receive(self, Header, "load_request", self.on_load_request, COMMAND_QOS, self.refusals, self.speakers)
        else:
            receive(self, JointState, "joint_states", self.on_joint_states, COMMAND_QOS, self.refusals, self.speakers)
        self.create_timer(DIAGNOSTICS_PERIOD, self.report)
        self.last_load: float | None = None
        self.last_ns = -1
        self.answered: tuple[int, int | float] = (0, 0)  # [ns] the exchange time of the last answer and the time up
        # to which its load holds (held_load_until): the exchange times between are covered by it
        self.done = False
        follow_run_state(self, self.on_run_state, self.refusals, self.speakers)
        self.get_logger().info(f"playing the load of scene '{self.model.scene.name}' ({self.time_mode})")  # (the first
        # log line takes up to a tenth of a second: not at t = 0)

    def on_run_state(self, state: RunStateMessage) -> None:
        """End by itself when the machine has finished, with its last diagnostics."""
        self.done = state.state == RunState.FINISHED
        if self.done:
            self.report()

    def report(self) -> None:
        """Publish /diagnostics: the load last given, what was refused and what disturbed the run."""
        level, text = self.refusals.status(OK, "playing")
        values = {"scene": self.model.scene.name, "sim_time": seconds(max(self.last_ns, 0)), "load": self.last_load}
        array = diagnostics(self, level, text, values)
        array.status[0].values += self.refusals.key_values()
        self.diagnostics_publisher.publish(array)

    def on_load_request(self, message: Header) -> None:
        """Lockstep: answer the machine's request for the load at an exchange time (load_request). Every request is
        answered, a repeat too (the machine asks again when an answer has not reached it). Checked first:
        trust.BadMessage."""
        when = stamp_of(message.stamp)
        self.follow(when, "load_request")
        self.answer(when, message.stamp)

    def on_joint_states(self, message: JointState) -> None:
        """Realtime: the machine's time from joint_states, the load published when it changes (answer); nothing for a
        time seen already or one the last answer's load holds over. Checked first: trust.BadMessage."""
        joint_fields(message)
        when = stamp_of(message.header.stamp)
        if self.follow(when, "joint_states") or self.answered[0] < when < self.answered[1]:
            return
        self.answer(when, message.header.stamp)

    def follow(self, when: int, topic: str) -> bool:
        """Follow the machine's time `when` [ns] (a time of 0 after later ones: the machine's ~/reset, the scenario
        starts again; only the machine speaks on `topic`): BadMessage when it goes back; whether it repeats the newest
        time."""
        if when == 0 and self.last_ns > 0:
            self.last_load, self.last_ns, self.answered = None, -1, (0, 0)
        in_order(when, self.last_ns if self.last_ns >= 0 else None, topic)
        repeat = when == self.last_ns
        self.last_ns = max(when, self.last_ns)
        return repeat

    def answer(self, when: int, stamp) -> None:
        """The load at the machine's time `when` [ns] (stamp: the same, a builtin_interfaces/Time): in lockstep on
        load_torque_stamped, with its rate and the time up to which it holds (held_load_until); in realtime on
        load_torque when it changes."""
        until = held_load_until(self.model, seconds(when))
        self.answered = (when, until)
        load = self.model.external_load(seconds(when))
        if self.time_mode == "lockstep":
            answer = WrenchStamped()
            answer.header.stamp = stamp
            answer.header.frame_id = "crank"
            answer.wrench.torque.z = load
            answer.wrench.force.z = load_rate(self.model, seconds(when))  # [N m/s]: a ramp, followed over the step
            answer.wrench.force.x = seconds(until) if until > when else 0.0  # [s] the load holds up to then
            self.stamped_publisher.publish(answer)
        elif load != self.last_load:
            self.load_publisher.publish(Float64(data=load))
        if load != self.last_load:  # after the answer, which the machine waits for: rclpy's logger looks its caller's
            # source up at every line, about 0.4 ms of CPU (docs/speed.md, "Where an exchange's 1.4 ms goes")
            self.get_logger().info(f"t = {seconds(when):.6g} s: load {load:g} N m")
        self.last_load = load


def main() -> int:
    """Entry point of scenario_node."""
    return run(ScenarioNode)


if __name__ == "__main__":
    sys.exit(main())
