"""What goes out first in an exchange, against stand-ins for the nodes: no ROS node, no domain. The message a peer
waits for goes out before what nobody waits for: the scenario's answer before the line that logs a load event
(rclpy's logger costs about 0.4 ms a line), the machine's joint_states before /clock, which three nodes take in
Python (docs/speed.md, "Where an exchange's 1.4 ms goes")."""

from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="the ROS 2 tests need rclpy (pip install 'mech_regulator[ros]')")

from builtin_interfaces.msg import Time  # noqa: E402

from mech_regulator.model import build_model  # noqa: E402
from mech_regulator.nodes.common import JointMessage  # noqa: E402
from mech_regulator.nodes.machine import MachineNode  # noqa: E402
from mech_regulator.nodes.scenario import ScenarioNode  # noqa: E402
from mech_regulator.scene import load_scene  # noqa: E402


def recorder_of(calls: list[tuple[str, object]], kind: str):
    """A stand-in's publish (or log) that appends (kind, what) to `calls`."""
    return lambda what: calls.append((kind, what))


def test_the_scenario_answers_a_load_event_before_it_logs_it():
    calls: list[tuple[str, object]] = []
    logger = SimpleNamespace(info=recorder_of(calls, "log"))
    scenario = SimpleNamespace(  # what ScenarioNode.answer reads, in lockstep on engine_direct, at first
        model=build_model(load_scene("engine_direct")),
        time_mode="lockstep",
        last_load=None,
        stamped_publisher=SimpleNamespace(publish=recorder_of(calls, "publish")),
        get_logger=lambda: logger,
    )
    ScenarioNode.answer(scenario, 0, Time())  # the machine's request at t = 0: the first load
    assert [kind for kind, _ in calls] == ["publish", "log"], calls
    assert "load" in calls[1][1]


def test_the_machine_publishes_joint_states_before_clock():
    calls: list[tuple[str, object]] = []
    machine = SimpleNamespace(  # what MachineNode.publish_state reads, in lockstep on engine_direct, at t = 0
        model=build_model(load_scene("engine_direct")),
        time_mode="lockstep",
        now_ns=0,
        end_ns=16 * 10**9,
        last_clock=-np.inf,
        clock_period=0.02,
        clock_publisher=SimpleNamespace(publish=recorder_of(calls, "/clock")),
        joint_publisher=SimpleNamespace(publish=recorder_of(calls, "joint_states")),
        stepper=SimpleNamespace(message_outputs=lambda throttle, load: (0.0, []), state=np.array([0.0, 30.0])),
        throttle=1.0,
        load=0.0,
        omega_middle=None,
        corrected=None,
        predicted=None,
        state_message=JointMessage(),
        published_exchanges=0,
    )
    MachineNode.publish_state(machine)
    assert [kind for kind, _ in calls] == ["joint_states", "/clock"], calls
