"""The scenario's answer to an exchange time (nodes/scenario.py ScenarioNode.on_joint_states) against a stand-in for
its node: no ROS node, no domain. The machine waits for the answer at a load event, so the answer goes out before
the line that logs the event (rclpy's logger costs about 0.4 ms a line: docs/speed.md, "Where an exchange's 1.4 ms
goes")."""

from types import SimpleNamespace

import pytest

pytest.importorskip("rclpy", reason="the ROS 2 tests need rclpy (pip install 'mech_regulator[ros]')")

from sensor_msgs.msg import JointState  # noqa: E402

from mech_regulator.model import build_model  # noqa: E402
from mech_regulator.nodes.scenario import ScenarioNode  # noqa: E402
from mech_regulator.scene import load_scene  # noqa: E402


def scenario_stand_in(calls: list[tuple[str, object]]) -> SimpleNamespace:
    """What ScenarioNode.on_joint_states reads of its node, in lockstep on engine_direct, before its first answer;
    its publisher and logger append ("publish", message) and ("log", line) to `calls`."""
    logger = SimpleNamespace(info=lambda line: calls.append(("log", line)))
    return SimpleNamespace(
        model=build_model(load_scene("engine_direct")),
        time_mode="lockstep",
        last_ns=-1,
        last_load=None,
        answered=(0, 0),
        stamped_publisher=SimpleNamespace(publish=lambda message: calls.append(("publish", message))),
        get_logger=lambda: logger,
    )


def test_the_scenario_answers_a_load_event_before_it_logs_it():
    calls: list[tuple[str, object]] = []
    exchange = JointState(name=["crank"], position=[0.0], velocity=[0.0], effort=[0.0])  # at t = 0: the first load
    ScenarioNode.on_joint_states(scenario_stand_in(calls), exchange)
    assert [kind for kind, _ in calls] == ["publish", "log"], calls
    assert "load" in calls[1][1]
