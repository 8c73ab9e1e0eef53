#!/usr/bin/env python3
"""A PID speed controller for mech_regulator's machine_node, in lockstep (docs/ros.md, "Your own controller").

It answers every `joint_states` (joint "crank": velocity omega [rad/s]) with a `throttle` (joint "throttle": position
0..1) stamped with the same header.stamp; the machine waits for that answer, then holds it over the next exchange step.
throttle = bias + kp e + ki integral(e dt) - kd d(omega)/dt, e = set_speed - omega, times from the stamps (simulation
time); the integral stops while the throttle is at 0 or 1 (anti-windup) and starts again when time starts again at 0
(the machine's ~/reset). Run: `python examples/pid_governor.py --ros-args -p kp:=0.05`.
"""

import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState


class PidGovernor(Node):
    def __init__(self):
        super().__init__("pid_governor")
        for name, value, description in (
            ("set_speed", 100.0, "crank speed to hold [rad/s]"),
            ("kp", 0.05, "proportional gain [1/(rad/s)]"),
            ("ki", 0.2, "integral gain [1/rad]"),
            ("kd", 0.0, "derivative gain, on the measured speed [s/rad]"),
            ("bias", 0.54, "throttle at zero error and zero integral [-]"),
        ):
            self.declare_parameter(name, value, ParameterDescriptor(description=description))
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        self.publisher = self.create_publisher(JointState, "throttle", qos)
        self.subscription = self.create_subscription(JointState, "joint_states", self.on_joint_states, qos)
        self.last = None  # (time [s], omega [rad/s]) of the last answer
        self.integral = 0.0  # [rad]

    def on_joint_states(self, message):
        time = message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec
        omega = message.velocity[list(message.name).index("crank")]
        gain = {name: self.get_parameter(name).value for name in ("set_speed", "kp", "ki", "kd", "bias")}
        if self.last is None or time < self.last[0]:  # the first exchange, or time started again at 0
            self.last, self.integral = (time, omega), 0.0
        step = time - self.last[0]
        error = gain["set_speed"] - omega
        rate = (omega - self.last[1]) / step if step > 0.0 else 0.0
        integral = self.integral + error * step
        throttle = gain["bias"] + gain["kp"] * error + gain["ki"] * integral - gain["kd"] * rate
        if 0.0 <= throttle <= 1.0:  # anti-windup: integrate only while not saturated
            self.integral = integral
        self.last = (time, omega)
        answer = JointState(name=["throttle"], position=[min(max(throttle, 0.0), 1.0)])
        answer.header.stamp = message.header.stamp  # lockstep: the answer carries the question's time
        self.publisher.publish(answer)


def main(args=None):
    rclpy.init(args=args)
    node = PidGovernor()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
