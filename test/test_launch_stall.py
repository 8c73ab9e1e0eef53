"""The launcher's report of a machine that stops exchanging (nodes/launch.py _follow, docs/ros.md): a stand-in machine
node (stalling_machine.py) whose simulated time stands still, then goes on; the report's interval is the launcher's
stall_report, here half a second of wall time instead of STALL_REPORT (30 s)."""

from __future__ import annotations

import io
import subprocess
import sys
import threading
import time
from pathlib import Path

from ros_support import next_domain_id  # skips this module when rclpy is missing

from mech_regulator.nodes import launch

WAIT = 60.0  # [s] of wall time at most for each thing awaited (a deadline that turns a hang into a failure)


def wait_for(condition, what: str) -> None:
    """Poll condition() until it holds; fail naming `what` after WAIT s."""
    deadline = time.monotonic() + WAIT
    while not condition():
        assert time.monotonic() < deadline, f"waited {WAIT:g} s for {what}"
        time.sleep(0.05)


def test_a_machine_that_stops_exchanging_is_reported_and_again_when_it_goes_on(tmp_path, monkeypatch):
    environment = launch.private_environment(next_domain_id())
    for key in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "AMENT_PREFIX_PATH"):
        monkeypatch.setenv(key, environment[key])  # (_follow sets them in this process; restored after the test)
    go_on, done = tmp_path / "go_on", tmp_path / "done"
    machine = subprocess.Popen(
        [sys.executable, str(Path(__file__).with_name("stalling_machine.py")), str(go_on), str(done)], env=environment
    )
    stderr = io.StringIO()
    monkeypatch.setattr(sys, "stderr", stderr)
    follower = threading.Thread(
        target=launch._follow,
        args=({"machine": machine}, environment, 10.0, True, "stall", time.monotonic()),
        kwargs={"stall_report": 0.5},
    )
    try:
        follower.start()
        wait_for(
            lambda: "has not advanced from t = 1 s for 0.5 s of wall time" in stderr.getvalue(),
            "the report of the machine standing at t = 1 s",
        )
        go_on.touch()
        wait_for(lambda: "the machine goes on at t = 2 s" in stderr.getvalue(), "the report that it goes on")
        done.touch()
        follower.join(WAIT)
        assert not follower.is_alive() and machine.wait(WAIT) == 0
    finally:
        done.touch()
        if machine.poll() is None:
            machine.kill()
    text = stderr.getvalue()
    stood = text.index(
        "has not advanced from t = 1 s for 0.5 s of wall time (paused through its ~/pause service, or "
        "stuck); Ctrl-C ends the run with its summary"
    )
    assert stood < text.index("the machine goes on at t = 2 s"), text
