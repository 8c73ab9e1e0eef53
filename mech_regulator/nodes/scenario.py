"""scenario_node: plays the load events of a scene in simulation time.

Listens to `joint_states` for the machine's exchange times. In `lockstep` it answers every exchange
time t with the scene's external load L(t) on `load_torque_stamped` (geometry_msgs/WrenchStamped,
torque.z [N m], stamped t, and in force.z the rate [N m/s] at which it changes then, a ramp's) — the machine
waits for it, so the run is reproducible. In `realtime` it
publishes each change of the load on `load_torque` (std_msgs/Float64 [N m]), as any other publisher
would. Either way it logs each load event. It ends by itself when the machine says the run is finished
(`machine/status`).
"""

from __future__ import annotations

import sys

from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from mech_regulator.nodes.common import (COMMAND_QOS, RunState, follow_run_state, nanoseconds, run, scene_model,
                                         text_parameter)
from mech_regulator.solvers.cosim import load_rate, seconds


class ScenarioNode(Node):
    """The load scenario of `scene_file` (see the module docstring)."""

    def __init__(self):
        super().__init__("scenario")
        self.model = scene_model(self)
        self.time_mode = text_parameter(self, "time_mode", "lockstep", "lockstep: answer every exchange time; "
                                        "realtime: publish load changes", ("lockstep", "realtime"))
        self.stamped_publisher = self.create_publisher(WrenchStamped, "load_torque_stamped", COMMAND_QOS)
        self.load_publisher = self.create_publisher(Float64, "load_torque", COMMAND_QOS)
        self.create_subscription(JointState, "joint_states", self.on_joint_states, COMMAND_QOS)
        self.last_load: float | None = None
        self.last_ns = -1
        self.done = False
        follow_run_state(self, self.on_run_state)
        self.get_logger().info(f"playing the load of scene '{self.model.scene.name}' ({self.time_mode})")  # (the first
        # log line takes up to a tenth of a second: not at t = 0)

    def on_run_state(self, state: dict) -> None:
        """End by itself when the machine has finished."""
        self.done = state["state"] == RunState.FINISHED

    def on_joint_states(self, message: JointState) -> None:
        """Give the load at the machine's exchange time (a time of 0 after later ones: the machine's ~/reset, the
        scenario starts again)."""
        when = nanoseconds(message.header.stamp)
        if when == 0 and self.last_ns > 0:
            self.last_load, self.last_ns = None, -1
        if when <= self.last_ns and self.time_mode == "realtime":
            return
        self.last_ns = max(when, self.last_ns)
        load = self.model.external_load(seconds(when))
        if load != self.last_load:
            self.get_logger().info(f"t = {seconds(when):.6g} s: load {load:g} N m")
        if self.time_mode == "lockstep":
            answer = WrenchStamped()
            answer.header.stamp = message.header.stamp
            answer.header.frame_id = "crank"
            answer.wrench.torque.z = load
            answer.wrench.force.z = load_rate(self.model, seconds(when))  # [N m/s]: a ramp, followed over the step
            self.stamped_publisher.publish(answer)
        elif load != self.last_load:
            self.load_publisher.publish(Float64(data=load))
        self.last_load = load


def main() -> int:
    """Entry point of scenario_node."""
    return run(ScenarioNode)


if __name__ == "__main__":
    sys.exit(main())
