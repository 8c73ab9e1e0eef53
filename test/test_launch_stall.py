"""The launcher's report of a machine that stops exchanging (nodes/launch.py _follow, docs/ros.md): a stand-in machine
node (stalling_machine.py) whose simulated time stands still, then goes on; the report's interval is the launcher's
stall_report, here half a second of wall time instead of STALL_REPORT (30 s)."""

from __future__ import annotations

import io
import signal
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
        "has not advanced from t = 1 s for 0.5 s of wall time (paused through its ~/pause service, waiting for its "
        "recorder held back, or stuck); Ctrl-C ends the run with its summary"
    )
    assert stood < text.index("the machine goes on at t = 2 s"), text


def test_the_end_waits_for_a_recorder_writing_a_long_run_s_outputs_and_says_so(monkeypatch, capsys):
    """After the machine has finished, the nodes get END_TIMEOUT and CLOSE_TIME_PER_EXCHANGE for each exchange
    (end_timeout): a node still writing past END_TIMEOUT is waited for, said once, and not killed; one past the
    whole timeout is stopped as Ctrl-C stops it (SIGINT: the recorder writes its summary with what it has), and
    killed if it is still running `closing` s later. Before, the walking beam's recorder was killed 30 s after its 10 000-s run, its summary
    lost."""
    assert launch.end_timeout(10_000.0, 0.02) == launch.END_TIMEOUT + 500_001 * launch.CLOSE_TIME_PER_EXCHANGE
    monkeypatch.setattr(launch, "END_TIMEOUT", 0.2)
    writing = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(1.0)"])
    launch._wait_all({"recorder": writing}, 60.0, quiet=False)  # returns when it ends
    assert writing.returncode == 0  # ended by itself after 1 s: waited past END_TIMEOUT
    said = capsys.readouterr().err.splitlines()
    assert len(said) == 1 and said[0].startswith("mech-regulator: waiting for the recorder node to write its outputs")
    # The stand-in says when it is under way, and the launcher's timeout starts only then: a SIGINT while its
    # interpreter still imports the site module (0.4-0.7 s for this venv's Python at a load of 7, longer on a starved
    # core) ends it with "Fatal Python error: init_import_site" and exit code 1, not as Ctrl-C ends it.
    # Its SIGINT handler is Python's own even when this test runs with SIGINT ignored (a job started in the background
    # by a non-interactive shell: the child would inherit the ignoring and sleep its 60 s out).
    hung = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import signal, time; signal.signal(signal.SIGINT, signal.default_int_handler); print(flush=True); "
            "time.sleep(60.0)",
        ],
        stdout=subprocess.PIPE,
    )
    hung.stdout.readline()  # under way
    launch._wait_all({"recorder": hung}, 0.5)
    assert hung.returncode == -signal.SIGINT  # stopped at the timeout as Ctrl-C stops it (the recorder then closes)
    deaf = "import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN); print(flush=True); time.sleep(60.0)"
    deaf_node = subprocess.Popen([sys.executable, "-c", deaf], stdout=subprocess.PIPE)
    deaf_node.stdout.readline()  # its SIGINT handler is set
    launch._wait_all({"recorder": deaf_node}, 0.5, closing=0.5)
    assert deaf_node.returncode == -signal.SIGKILL  # still running `closing` s after the SIGINT: killed
    assert capsys.readouterr().err == ""  # quiet
