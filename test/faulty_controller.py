"""The example controller (examples/pid_governor.py) with one fault from t = FAULT_TIME ns (0.1 s) of simulation time
on, for the tests of an external controller: `python test/faulty_controller.py slow|die|wrong_stamp [--ros-args ...]`.
slow: answers once after SLOW_ANSWER s of wall time (longer than the tests' peer_timeout); die: the process is killed
(SIGKILL: no goodbye to the ROS graph); wrong_stamp: answers stamped with the node's clock (wall time), a common
mistake."""

import importlib.util
import os
import signal
import sys
import time
from pathlib import Path

FAULT_TIME = 100_000_000  # [ns] of simulation time
SLOW_ANSWER = 20.0  # [s] of wall time

spec = importlib.util.spec_from_file_location(
    "pid_governor", Path(__file__).resolve().parents[1] / "examples" / "pid_governor.py"
)
example = importlib.util.module_from_spec(spec)
spec.loader.exec_module(example)


class FaultyGovernor(example.PidGovernor):
    """The example's controller with the fault `mode` (see the module docstring)."""

    def __init__(self, mode: str):
        super().__init__()
        self.mode = mode

    def on_joint_states(self, message):
        if message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec >= FAULT_TIME:
            if self.mode == "die":
                os.kill(os.getpid(), signal.SIGKILL)
            if self.mode == "slow":
                time.sleep(SLOW_ANSWER)
            if self.mode == "wrong_stamp":
                message.header.stamp = self.get_clock().now().to_msg()
        super().on_joint_states(message)


if __name__ == "__main__":
    example.rclpy.init(args=sys.argv)
    node = FaultyGovernor(sys.argv[1])
    try:
        example.rclpy.spin(node)
    except KeyboardInterrupt:
        pass
