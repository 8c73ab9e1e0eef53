"""A stand-in for the machine node that stops exchanging, for the test of the launcher's stall report
(test_launch_stall.py): `python test/stalling_machine.py GO_ON DONE`. It publishes the machine's /diagnostics with its
simulated time standing at STUCK_AT s until the file GO_ON exists, then at GONE_ON s until the file DONE exists, and
ends (exit code 0), as a machine that finished. No time is simulated: only what the launcher reads."""

import sys
import time
from pathlib import Path

import rclpy
from diagnostic_msgs.msg import DiagnosticArray

from mech_regulator.nodes.common import OK, diagnostics

STUCK_AT, GONE_ON = 1.0, 2.0  # [s] of simulated time
PUBLISH_EVERY = 0.05  # [s] of wall time


def main(go_on: Path, done: Path) -> None:
    rclpy.init()
    node = rclpy.create_node("machine")
    publisher = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
    for sim_time, until in ((STUCK_AT, go_on), (GONE_ON, done)):
        while not until.exists():
            publisher.publish(diagnostics(node, OK, "running", {"scene": "stalling", "sim_time": sim_time}))
            time.sleep(PUBLISH_EVERY)
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
