"""The ROS 2 layer: machine_node, governor_node, scenario_node, recorder_node and the main job
(`mech-regulator run`), checked against the in-process co-simulation of the core
(mech_regulator.solvers.cosim), which they promise to reproduce to the last bit in lockstep.

Every test that starts nodes has a ROS domain of its own (ros_support.next_domain_id) with discovery
on this machine only; its processes are stopped when it ends, pass or fail. A lockstep machine waits
for its subscribers before the first step, so the tests subscribe last (RunListener.open_gate) and
nothing depends on how fast the machine runs.
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

# after ros_support, which skips this module when rclpy is missing
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import WrenchStamped
from rcl_interfaces.msg import Parameter as ParameterMessage
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.duration import Duration
from ros_support import (  # noqa: F401 (fixtures)
    WAIT,
    Processes,
    RunListener,
    batch_groups,
    domain_id,
    next_domain_id,
    probe,
    probe_on,
    processes,
    processes_on,
    stamp_ns,
)
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Header
from std_srvs.srv import Trigger
from support import SMOOTH_DIRECT_GOVERNOR, SMOOTH_GOVERNED_MACHINE, run_cli
from test_recording import events, scalars

from mech_regulator.analysis import cycle_mean_speed, load_responses, operating_point
from mech_regulator.model import build_model
from mech_regulator.nodes import launch as launch_domains
from mech_regulator.nodes.launch import DOMAIN_IDS, DOMAIN_LOCKS, viewer_command
from mech_regulator.nodes.trust import BadMessage
from mech_regulator.scene import load_scene, validate_scene
from mech_regulator.scene.scenario_keys import DEFAULT_EXCHANGE_STEP
from mech_regulator.solvers import simulate
from mech_regulator.solvers.cosim import DEFAULT_COUPLING, GovernorStepper, cosimulate, seconds, to_nanoseconds
from mech_regulator.solvers.trajectory import SampledTrajectory

# engine_direct shortened to 1 s (6 -> 8 N m at 0.4 s, thrown off at 0.7 s): the main job's test scene
SHORT_ENGINE = ["scenario.duration=1", "scenario.load_events.0.time=0.4", "scenario.load_events.1.time=0.7"]
BASE_LOAD = 6.0  # [N m] of the constant-inertia scene below


# -------------------------------------------------------------------------------------------------
# Scenes


@functools.cache
def _steady_speed() -> float:
    """The constant-inertia scene's steady speed at BASE_LOAD (its operating point): the scene starts
    there, so that any change of speed comes from what a test does."""
    return operating_point(build_model(validate_scene(_constant_inertia_data(100.0))), BASE_LOAD).speed


def _constant_inertia_data(omega: float, **scenario) -> dict:
    """A governed machine of constant inertia (cheap per step) with a direct-action Porter governor."""
    return {
        "name": "constant_inertia",
        "machine": SMOOTH_GOVERNED_MACHINE,
        "governor": SMOOTH_DIRECT_GOVERNOR,
        "scenario": {
            "initial": {"omega": omega},
            "duration": 0.4,
            "external_load": BASE_LOAD,
            "load_events": [],
            **scenario,
        },
        "solver": {"method": "DOP853", "rtol": 1e-9, "atol": 1e-11},
    }


def constant_inertia_scene(folder: Path, name: str = "scene.yaml", **scenario):
    """Write the constant-inertia scene (scenario keys changed) to folder/name; returns (path, model)."""
    data = _constant_inertia_data(_steady_speed(), **scenario)
    path = folder / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path, build_model(validate_scene(data))


def machine_parameters(scene: Path, **changes) -> dict:
    """machine_node's parameters for a lockstep run of scene with the test node as one subscriber."""
    return {
        "scene_file": str(scene),
        "time_mode": "lockstep",
        "exchange_step": 0.002,
        "coupling": "hold",
        "lockstep_inputs": ["throttle", "load"],
        "peer_timeout": 60.0,
        **changes,
    }


# -------------------------------------------------------------------------------------------------
# What only the recorder reads travels in batches (nodes.common.Batch)


class _Published(list):
    """A stand-in publisher: keeps what is published."""

    def publish(self, message) -> None:
        self.append(message)


def test_a_batch_carries_each_exchange_time_and_its_joints_in_order():
    from mech_regulator.nodes.common import BATCH_SIZE, Batch

    published = _Published()
    batch = Batch(published, print)
    largest = 2**53  # [ns]: about 104 days, still exact in a double
    batch.add(0, ["drive", "load"], [], [], [1.5, -2.0], wall=12.5)  # wall: when the machine published t = 0 [s]
    batch.add(20_000_000, ["sleeve", "arm"], [0.03, 0.1], [0.0, -0.2], [])
    batch.add(largest, ["drive"], [], [], [7.0])
    batch.send()
    batch.send()  # nothing left: nothing sent
    assert len(published) == 1 and stamp_ns(published[0].header.stamp) == largest
    groups = batch_groups(published[0])
    assert [when for when, _ in groups] == [0, 20_000_000, largest]
    assert groups[0][1].pop("stamp")[:2] == (0.0, 12.5) and math.isnan(groups[1][1].pop("stamp")[1])
    assert {name: effort for name, (_, _, effort) in groups[0][1].items()} == {"drive": 1.5, "load": -2.0}
    assert groups[1][1]["arm"][:2] == (0.1, -0.2) and math.isnan(groups[1][1]["arm"][2])
    assert groups[2][1]["drive"][2] == 7.0 and math.isnan(groups[2][1]["drive"][0])
    for when in range(BATCH_SIZE):  # a full batch goes out when due, however little wall time has passed (and an
        batch.add(when, ["drive"], [], [], [float(when)])  # older group waiting 0.1 s sends it earlier)
        batch.send_when_due()
    assert batch.groups == 0 and [when for message in published[1:] for when, _ in batch_groups(message)] == list(
        range(BATCH_SIZE)
    )


def test_a_joint_message_is_built_once_per_layout_and_its_samples_read_back():
    from rclpy.serialization import deserialize_message

    from mech_regulator.nodes.common import JointMessage, samples, sent_samples
    from mech_regulator.nodes.wire import JointStateReader

    message = JointMessage()
    corrected = ([0.0, 0.01, 0.02], [100.0, 101.0, 102.5])
    first = deserialize_message(
        message.fill(1_500_000_000, ("crank",), [1.0], [100.0], [3.0], (("crank_corrected", "velocity", corrected),)),
        JointState,
    )  # the bytes a node publishes: rclpy's own serialization of the message
    codec = message.codec
    assert stamp_ns(first.header.stamp) == 1_500_000_000 and list(first.name) == ["crank"] + ["crank_corrected"] * 3
    assert list(first.effort) == [3.0, *corrected[0]] and list(first.velocity) == [100.0, *corrected[1]]
    assert all(math.isnan(value) for value in first.position[1:])
    again = ([0.02, 0.03, 0.04], [102.5, 103.0, 104.0])
    second = deserialize_message(
        message.fill(2_000_000, ("crank",), [2.0], [102.5], [4.0], (("crank_corrected", "velocity", again),)),
        JointState,
    )
    assert codec is not None and message.codec is codec  # the same layout: its bytes refilled in place
    assert stamp_ns(second.header.stamp) == 2_000_000 and list(second.position[:1]) == [2.0]
    assert samples(second, "crank_corrected", "velocity") == again
    third = deserialize_message(
        message.fill(4_000_000, ("crank",), [3.0], [104.0], [5.0], (("crank_corrected", "velocity", None),)),
        JointState,
    )
    assert message.codec is not codec and list(third.name) == ["crank"]  # another layout: a new message
    assert samples(third, "crank_corrected", "velocity") is None and sent_samples(third, "x", "position", 0, 1) is None
    for times, values in (([0.0, 0.0, 0.1], [1.0, 2.0, 3.0]), ([0.0, 0.1, 0.2], [1.0, math.nan, 3.0]), ([0.0], [1.0])):
        bad = JointStateReader()(
            JointMessage().fill(
                0, ("throttle",), [0.5], [math.nan], [math.nan], (("tentative", "position", (times, values)),)
            )
        )
        assert samples(bad, "tentative", "position") is None
        with pytest.raises(BadMessage, match="bad samples"):
            sent_samples(bad, "tentative", "position", 0.0, 1.0)
    short = JointState(name=["tentative", "tentative"], position=[0.5, 0.6])  # no efforts: no sample times
    assert samples(short, "tentative", "position") is None
    beyond = JointStateReader()(
        JointMessage().fill(0, (), [], [], [], (("tentative", "position", ([0.0, 0.1], [0.5, 1.5])),))
    )
    with pytest.raises(BadMessage, match="within"):
        sent_samples(beyond, "tentative", "position", 0.0, 1.0)


def test_the_speed_s_action_on_the_throttle_is_read_from_the_governor_s_answer_and_checked():
    """The governor's answer with the speed's direct action (a PI governor): the command at the stamp and its
    sensitivity to the speed, each a joint of its own, read back as sent; an answer without them has none; one of
    the two alone, or a value beyond its bound or not finite, is refused naming the joint."""
    from mech_regulator.nodes.common import JointMessage
    from mech_regulator.nodes.governor import ACTION_JOINTS
    from mech_regulator.nodes.machine_exchange import MAX_THROTTLE_PER_SPEED, speed_action
    from mech_regulator.nodes.wire import JointStateReader
    from mech_regulator.solvers.cosim import SpeedAction

    def answer(joints, positions):
        message = JointStateReader()(
            JointMessage().fill(0, joints, positions, [math.nan] * len(joints), [math.nan] * len(joints))
        )
        return speed_action(message, list(message.name))

    assert answer(ACTION_JOINTS, [1.0, 1.27, -3.0 / 224.0]) == SpeedAction(1.27, -3.0 / 224.0)
    assert answer(("throttle",), [0.5]) is None
    with pytest.raises(BadMessage, match="throttle_per_speed only"):
        answer(("throttle", "throttle_per_speed"), [0.5, -0.01])
    with pytest.raises(BadMessage, match="throttle_per_speed position"):
        answer(ACTION_JOINTS, [0.5, 0.5, -2.0 * MAX_THROTTLE_PER_SPEED])
    with pytest.raises(BadMessage, match="not finite: throttle_command"):
        answer(ACTION_JOINTS, [0.5, math.nan, -0.01])


def test_a_batch_completes_its_deferred_groups_together_when_it_goes_out():
    from mech_regulator.nodes.common import BATCH_SIZE, Batch

    published, completions = _Published(), []

    def complete(items):  # as the machine's moments: one call for all the deferred exchanges
        completions.append(list(items))
        for when, load in items:
            batch.add(when, ["load"], [], [], [load])

    batch = Batch(published, print, complete)
    for when in range(BATCH_SIZE - 1):
        batch.defer((when, 2.0 * when))
        batch.send_when_due()
    assert not published and not completions  # one short of a batch, and not yet BATCH_PERIOD old
    batch.defer((BATCH_SIZE - 1, 1.0))
    batch.send_when_due()
    assert len(completions) == 1 and len(completions[0]) == BATCH_SIZE and len(published) == 1
    groups = batch_groups(published[0])
    assert [when for when, _ in groups] == list(range(BATCH_SIZE)) and groups[3][1]["load"][2] == 6.0
    batch.defer((BATCH_SIZE, 5.0))
    batch.send()  # the run ends: what was deferred goes out at once
    assert len(completions) == 2 and [when for when, _ in batch_groups(published[1])] == [BATCH_SIZE]


class _Acknowledging(_Published):
    """A stand-in publisher whose readers acknowledge what it sent after the waits `acknowledged` says (True: within
    that wait, or every reader unacknowledged has gone), noting the length [s] of each wait asked for; `readers`: how
    many readers it has matched, one entry per look (the last one repeats)."""

    topic_name = "/machine/moments"

    def __init__(self, acknowledged: list[bool], readers: tuple[int, ...] = (1,)):
        super().__init__()
        self.acknowledged, self.waits, self.readers = acknowledged, [], list(readers)

    def wait_for_all_acked(self, timeout) -> bool:
        self.waits.append(timeout.nanoseconds * 1e-9)
        return self.acknowledged.pop(0)

    def get_subscription_count(self) -> int:
        return self.readers.pop(0) if len(self.readers) > 1 else self.readers[0]


def test_a_batch_waits_for_its_readers_and_says_so_once_they_are_late():
    """wait_for_readers: at once when the readers have acknowledged everything; past ACK_PATIENCE s it says that
    the run waits for the recorder and waits up to ACK_CATCH_UP in all, longer than the participants' lease (a reader
    stopped is waited for as long as it is taken for there); still unacknowledged (a reader there that takes nothing)
    it ends the node naming the topic (PeerError) rather than wait that long again and again; a reader that left
    during the wait (taken for gone once its lease ran out) is said, what it missed lost to it. Batch.deliver (the
    run's end) sends what waits, then waits."""
    from mech_regulator.nodes.common import (
        ACK_CATCH_UP,
        ACK_PATIENCE,
        PARTICIPANT_LEASE,
        Batch,
        PeerError,
        wait_for_readers,
    )

    assert ACK_CATCH_UP > PARTICIPANT_LEASE
    for acknowledged, readers, ends, said in (
        ([True], (1,), False, []),
        (
            [False, True],
            (1,),
            False,
            [
                f"waits for them as long as they are there (a reader that announces nothing for "
                f"{PARTICIPANT_LEASE:g} s is taken for gone), at most {PARTICIPANT_LEASE:g} s more"
            ],
        ),
        ([False, False], (1,), True, ["waits for them"]),
        ([False, True], (2, 1), False, ["waits for them", "1 reader(s) of /machine/moments left while the run waited"]),
    ):
        publisher, lines = _Acknowledging(list(acknowledged), readers), []
        if ends:
            with pytest.raises(PeerError, match=f"/machine/moments .* acknowledged nothing more .* {ACK_CATCH_UP:g} s"):
                wait_for_readers(publisher, lines.append)
        else:
            wait_for_readers(publisher, lines.append)
        assert publisher.waits == [ACK_PATIENCE, ACK_CATCH_UP - ACK_PATIENCE][: len(acknowledged)]
        assert len(lines) == len(said) and all(part in line for part, line in zip(said, lines)), lines
        assert all("/machine/moments (the recorder among them)" in line for line in lines[:1])
    publisher = _Acknowledging([True])
    batch = Batch(publisher, print)
    batch.add(0, ["load"], [], [], [1.0])
    batch.deliver()
    assert len(publisher) == 1 and publisher.waits == [ACK_PATIENCE]


class _EndReaders:
    """A stand-in publisher of the machine's end (machine/status or /diagnostics) with one matched reader, which
    acknowledges what it sent at the `acknowledged_at`-th wait for it (None: never, a node killed without leaving
    the graph); `waits` counts the waits."""

    def __init__(self, topic_name: str, acknowledged_at: int | None):
        self.topic_name, self.acknowledged_at, self.waits = topic_name, acknowledged_at, 0

    def get_subscription_count(self) -> int:
        return 1

    def wait_for_all_acked(self, timeout) -> bool:
        self.waits += 1
        return self.acknowledged_at is not None and self.waits >= self.acknowledged_at


@pytest.mark.parametrize(
    "status_acknowledged_at, recorder_looks, looks, warned",
    [
        (1, 5, 0, False),  # acknowledged at once: no look at the recorder
        (None, 3, 4, False),  # a reader that never answers (killed): waited for until the recorder has left
        (None, 0, 1, False),  # ... and not at all when no recorder follows the run
        (40, 100, 38, False),  # a recorder held back: waited for while it is there, past ACK_WAIT, until it answers
        (None, 10**9, None, True),  # a reader there that never answers: at most ACK_CATCH_UP (shortened), said
    ],
)
def test_the_machine_s_end_waits_for_its_readers_while_the_recorder_is_there(
    monkeypatch, status_acknowledged_at, recorder_looks, looks, warned
):
    """MachineNode.deliver_the_end: every reader of machine/status and /diagnostics gets ACK_WAIT s (deliver_all);
    one that has not acknowledged the end by then is waited for only while the recorder is subscribed to
    machine/status (it leaves once it has the end), at most ACK_CATCH_UP s: a recorder held back still gets the end
    its `complete` summary needs, and a node killed without leaving the graph (taken for there for the participants'
    lease, 300 s) does not hold the machine's end after the recorder has gone."""
    from types import SimpleNamespace

    from mech_regulator.nodes import machine as machine_module
    from mech_regulator.nodes.machine import MachineNode

    if warned:
        monkeypatch.setattr(machine_module, "ACK_CATCH_UP", 0.3)
        monkeypatch.setattr(machine_module, "ACK_PATIENCE", 0.1)
    machine = MachineNode.__new__(MachineNode)  # its end only: no ROS node
    machine.status_publisher = _EndReaders("/machine/status", status_acknowledged_at)
    machine.diagnostics_publisher = _EndReaders("/diagnostics", 1)
    machine.recorder_name, machine.get_namespace = "recorder", lambda: "/"
    machine.count_subscribers = lambda topic: 1
    recorder = SimpleNamespace(node_name="recorder", node_namespace="/")
    seen = {"looks": 0}

    def subscriptions(topic: str) -> list:
        assert topic == "/machine/status"
        seen["looks"] += 1
        return [recorder] if seen["looks"] <= recorder_looks else []

    machine.get_subscriptions_info_by_topic = subscriptions
    warnings: list[str] = []
    machine.get_logger = lambda: SimpleNamespace(warning=warnings.append)
    machine.deliver_the_end()
    if looks is not None:  # (one look after each wait in vain past deliver_all's)
        assert seen["looks"] == looks
    assert bool(warnings) is warned and all("waits while the recorder is there" in line for line in warnings), warnings


def test_take_waiting_hands_every_waiting_message_with_its_info_to_the_callback():
    """common.take_waiting takes what waits in a subscription's reader straight from it (the handle held while it
    takes), hands each (message, info) to the subscription's callback in order, and says how many: nothing when the
    reader is empty."""
    from unittest import mock

    from mech_regulator.nodes.common import take_waiting

    class Handle:
        def __init__(self, waiting: list):
            self.waiting, self.held, self.asked = waiting, 0, []

        def __enter__(self):
            self.held += 1

        def __exit__(self, *exception):
            self.held -= 1

        def take_message(self, message_type, raw):
            assert self.held == 1
            self.asked.append((message_type, raw))
            return self.waiting.pop(0) if self.waiting else None

    handed: list = []
    subscription = mock.Mock(
        msg_type=JointState, raw=False, callback=lambda message, info: handed.append((message, info))
    )
    subscription.handle = Handle([("first", {"sender": 1}), ("second", {"sender": 2})])
    assert take_waiting(subscription) == 2 and handed == [("first", {"sender": 1}), ("second", {"sender": 2})]
    assert subscription.handle.asked == [(JointState, False)] * 3
    assert take_waiting(subscription) == 0 and len(handed) == 2


@pytest.mark.parametrize("recorder_takes", [False, True])
def test_the_machine_keeps_pace_with_its_recorder_while_it_takes_and_ends_the_run_when_it_takes_nothing(
    monkeypatch, recorder_takes
):
    """MachineNode.keep_pace_with_the_recorder holds the run while the recorder is more than RECORDER_LEAD exchanges
    behind: until it catches up, and, should it be there and take nothing for ACK_CATCH_UP s (shortened here; a
    recorder resumed after a 90-s stop was seen to receive nothing more, and the hold had no other end), ends the run
    naming where the recorder stands (PeerError)."""
    from types import SimpleNamespace

    from mech_regulator.nodes import machine as machine_module
    from mech_regulator.nodes.common import RECORDER_LEAD, PeerError
    from mech_regulator.nodes.machine import MachineNode

    monkeypatch.setattr(machine_module, "ACK_CATCH_UP", 0.2)
    monkeypatch.setattr(machine_module, "spin_once", lambda node, timeout: None)
    monkeypatch.setattr(machine_module.rclpy, "ok", lambda: True)
    machine = MachineNode.__new__(MachineNode)  # its pace only: no ROS node
    machine.time_mode, machine.published_exchanges, machine.step_ns = "lockstep", 0, 20_000_000
    machine.now_ns, machine.recorded_ns = (RECORDER_LEAD + 500) * machine.step_ns, 0
    machine.recorder_progress = SimpleNamespace(get_publisher_count=lambda: 1)
    machine.moments = SimpleNamespace(send_when_due=lambda: None)
    machine.report = lambda: None
    machine.get_logger = lambda: SimpleNamespace(warning=print)
    looks = {"count": 0}

    def read_recorder_progress() -> None:  # the recorder takes 100 exchanges a look, or nothing
        looks["count"] += 1
        if recorder_takes:
            machine.recorded_ns += 100 * machine.step_ns

    machine.read_recorder_progress = read_recorder_progress
    if recorder_takes:
        machine.keep_pace_with_the_recorder()
        assert machine.now_ns - machine.recorded_ns <= RECORDER_LEAD * machine.step_ns and looks["count"] == 5
    else:
        with pytest.raises(PeerError, match=r"has taken nothing more for 0.2 s .* up to t = 0 s"):
            machine.keep_pace_with_the_recorder()


def test_the_run_s_fast_dds_profile_sets_the_participants_lease_the_nodes_wait_for():
    """The Fast DDS profile every node of a run reads (launch.fastdds_profile, set by launch.private_environment)
    gives the participants the lease nodes.common.PARTICIPANT_LEASE says (Fast DDS's default, 20 s, took a recorder
    stopped 20 s for gone: test_main_job_scenes' held recorder), and still announces them every 0.2 s."""
    import xml.etree.ElementTree as ElementTree

    from mech_regulator.nodes.common import PARTICIPANT_LEASE
    from mech_regulator.nodes.launch import FASTDDS_PROFILE_VARIABLE, fastdds_profile, private_environment

    profile = fastdds_profile()
    assert private_environment(0)[FASTDDS_PROFILE_VARIABLE] == str(profile) or FASTDDS_PROFILE_VARIABLE in os.environ
    space = {"dds": "http://www.eprosima.com"}
    discovery = ElementTree.parse(profile).find(".//dds:participant/dds:rtps/dds:builtin/dds:discovery_config", space)
    assert discovery is not None

    def duration(name: str) -> float:
        element = discovery.find(f"dds:{name}", space)
        assert element is not None, name
        return int(element.findtext("dds:sec", "0", space)) + 1e-9 * int(element.findtext("dds:nanosec", "0", space))

    assert duration("leaseDuration") == PARTICIPANT_LEASE and duration("leaseAnnouncement") == 0.2


# -------------------------------------------------------------------------------------------------
# Comparisons with the core


def received_run(listener: RunListener, end: int):
    """Exchange times [ns] and what the test node received there: state rows (phi, omega, arm angle,
    arm rate), governor throttle, moments by name."""
    joints, moments, governor = listener.joints, listener.moments, listener.governor
    times = sorted(joints)
    assert times[-1] == end and sorted(moments) == times and sorted(governor) == times, (
        "joint_states, machine/moments and governor/state have different exchange times"
    )
    rows = np.array([[joints[t].position[0], joints[t].velocity[0], *governor[t]["arm"][:2]] for t in times]).T
    throttle = np.array([governor[t]["throttle"][0] for t in times])
    return (
        times,
        rows,
        throttle,
        {name: np.array([moments[t][name] for t in times]) for name in ("drive", "resistance", "external", "net")},
    )


def assert_equals_cosimulation(listener: RunListener, end: int, model, run) -> None:
    """The received run is the in-process co-simulation to the last bit: same exchange times, states,
    throttle (the governor's; closed from an overspeed trip on), and moments on the crank."""
    times, rows, throttle, moments = received_run(listener, end)
    assert times == [to_nanoseconds(t) for t in run.times], "exchange times differ from the core's"
    np.testing.assert_array_equal(rows[1], run.states[1], err_msg="omega differs from cosimulate")
    np.testing.assert_array_equal(rows, run.states, err_msg="the state differs from cosimulate")
    if run.tripped_at is not None:
        throttle[run.times >= run.tripped_at] = 0.0
    np.testing.assert_array_equal(throttle, run.throttle, err_msg="the throttle differs from cosimulate")
    np.testing.assert_array_equal(
        -moments["external"], run.external_load, err_msg="the external load differs from cosimulate"
    )
    columns = model.columns(run.times, run.states, run.throttle, run.external_load)
    expected = {
        "drive": columns["M_drive"],
        "resistance": columns["M_load"] - columns["M_external"],
        "external": columns["M_external"],
        "net": columns["J"] * columns["epsilon"] + 0.5 * columns["dJ_dphi"] * columns["omega"] ** 2,
    }
    for name, values in expected.items():  # at t_k: with the inputs held from t_k on
        np.testing.assert_array_equal(moments[name], values, err_msg=f"machine/moments {name} differs from cosimulate")


# -------------------------------------------------------------------------------------------------
# 2. Lockstep against the monolithic simulation (in process: the error of the exchange step itself)


def test_lockstep_error_is_first_order_in_the_exchange_step():
    """docs/ros.md: errors about 120 h on omega, 45 h on the cycle-mean speed, 30 h on the peak deviation
    after a load change (measured on the whole engine_direct; checked here on its short version)."""
    model = build_model(load_scene("engine_direct", SHORT_ENGINE))
    monolithic = simulate(model)
    assert monolithic.status == "complete", monolithic.message
    expected_responses = load_responses(model, monolithic)
    assert len(expected_responses) == 2
    omega_error, mean_error, fair_mean_error = {}, {}, {}
    for step in (1e-3, 2e-3):
        run = cosimulate(model, step)
        assert run.status == "complete" and run.times[-1] == 1.0
        reference = monolithic(run.times)
        omega_error[step] = np.max(np.abs(run.states[1] - reference[1]))
        # the cycle-mean speed as a user reads it: the co-simulation (linear between exchange times)
        # against the dense monolithic run ...
        cosimulated_mean = cycle_mean_speed(model, run.trajectory(model), run.times)
        mean_error[step] = np.nanmax(np.abs(cosimulated_mean - cycle_mean_speed(model, monolithic, run.times)))
        # ... and against the monolithic run sampled at the same times (the interpolation, second order
        # in h, is then the same on both sides: what is left is the exchange's error)
        sampled = SampledTrajectory(
            method="monolithic sampled", t_start=0.0, times=run.times, states=reference, status="complete", message=""
        )
        fair_mean_error[step] = np.nanmax(np.abs(cosimulated_mean - cycle_mean_speed(model, sampled, run.times)))
        assert omega_error[step] <= 120.0 * step, f"h = {step}: omega error {omega_error[step]} > 120 h"
        assert mean_error[step] <= 45.0 * step, f"h = {step}: cycle-mean speed error {mean_error[step]} > 45 h"
        for response, exact in zip(load_responses(model, run.trajectory(model)), expected_responses):
            assert abs(response.peak_deviation - exact.peak_deviation) <= 30.0 * step, (step, response, exact)
        assert omega_error[step] > 0.0 and fair_mean_error[step] > 0.0
    assert 1.8 <= omega_error[2e-3] / omega_error[1e-3] <= 2.2, omega_error
    assert 1.8 <= fair_mean_error[2e-3] / fair_mean_error[1e-3] <= 2.2, fair_mean_error


def test_an_anticipating_governor_answers_as_one_that_does_not():
    """governor_node advances over the next step before it is asked (GovernorStepper.anticipate); a guess
    of the next exchange time that turns out wrong is undone: answers, states, mode changes and solver
    counts stay those of a governor that never anticipates."""
    model = build_model(load_scene("engine_direct"))
    plain, anticipating = GovernorStepper(model), GovernorStepper(model)
    step = to_nanoseconds(1e-3)
    speeds = np.concatenate([np.full(150, 400.0), np.full(150, 150.0)])  # [rad/s] up to the high stop and off it
    for k, omega in enumerate(speeds):
        now = seconds(k * step)
        assert anticipating.answer(now, omega) == plain.answer(now, omega), f"throttle at t = {now} s"
        np.testing.assert_array_equal(anticipating.state, plain.state, err_msg=f"state at t = {now} s")
        assert (anticipating.mode, anticipating.events, anticipating.stats) == (plain.mode, plain.events, plain.stats)
        anticipating.anticipate(seconds((k + (2 if k % 7 == 0 else 1)) * step))  # every 7th guess too far
    assert [event for _, event, _ in plain.events] == ["sleeve reaches the high stop", "sleeve leaves the high stop"]
    assert plain.stats.restarts >= 1


def test_columns_after_an_overspeed_trip_show_the_closed_throttle(tmp_path):
    # (once a bug: the run's throttle, and so the CSV's M_drive and epsilon, stayed the governor's)
    _, model = constant_inertia_scene(tmp_path, load_events=[{"time": 0.1, "torque": 0.0}])
    run = cosimulate(model, 0.002, overspeed_trip=_steady_speed() + 0.3)
    assert run.tripped_at is not None and 0.1 < run.tripped_at < 0.4
    columns = model.columns(run.times, run.states, run.throttle, run.external_load)
    after = run.times >= run.tripped_at
    np.testing.assert_array_equal(columns["M_drive"][after], 0.0)
    assert np.all(columns["M_drive"][~after] > 0.0)


# -------------------------------------------------------------------------------------------------
# 3. A load step published by the test node


def test_load_torque_from_any_publisher_applies_from_an_exchange_time(tmp_path, processes, probe):
    scene, _ = constant_inertia_scene(tmp_path, duration=0.6)
    # the test node is the machine's `load` input (the scenario's constant BASE_LOAD, stamped: the machine takes it
    # as its scenario's), so the machine waits for it at every exchange time; the step itself goes on load_torque
    # (Float64, from anyone)
    processes.node(
        "machine",
        machine_parameters(scene, peers=["governor", probe.node.get_name()], scenario_node=probe.node.get_name()),
    )
    processes.node("governor", {"scene_file": str(scene), "coupling": "hold"})
    stamped = probe.publisher(WrenchStamped, "load_torque_stamped", describe=processes.logs)
    load = probe.publisher(Float64, "load_torque", describe=processes.logs)
    listener = RunListener(probe, governed=True, diagnostics_publishers=2, describe=processes.logs)
    sent: list[int] = []

    def answer(message: JointState) -> None:
        when = stamp_ns(message.header.stamp)
        if not sent and when >= 300_000_000:
            load.publish(Float64(data=8.0))
            assert load.wait_for_all_acked(Duration(seconds=WAIT))
            sent.append(when)
        reply = WrenchStamped()
        reply.header.stamp = message.header.stamp
        reply.wrench.torque.z = BASE_LOAD
        stamped.publish(reply)

    listener.open_gate(answer)
    end = listener.wait_finished()
    assert end == to_nanoseconds(0.6)
    external = listener.moments
    stepped = [when for when in sorted(external) if external[when]["external"] == -8.0]
    assert stepped, f"the load 8 N m sent at {sent} was never applied"
    step = stepped[0]
    assert step >= sent[0], "the load applied before it was sent"
    assert all((external[when]["external"] == -8.0) == (when >= step) for when in external)
    # the same run in process, with the load event at that exchange time exactly
    _, stepped_model = constant_inertia_scene(
        tmp_path, "stepped.yaml", duration=0.6, load_events=[{"time": seconds(step), "torque": 8.0}]
    )
    run = cosimulate(stepped_model, 0.002)
    assert_equals_cosimulation(listener, end, stepped_model, run)
    # the governor lets the speed sag after the step (a direct governor's static error)
    speed = cycle_mean_speed(stepped_model, run.trajectory(stepped_model), run.times)
    at_step = speed[run.times == seconds(step)][0]
    assert speed[-1] < at_step - 0.1 and np.all(speed[run.times > seconds(step)] < at_step)
    assert listener.final_status()[0] == DiagnosticStatus.OK


def test_the_scenario_is_asked_for_the_load_only_where_no_answer_covers_the_exchange_time(tmp_path, processes, probe):
    # a step at 0.1 s (held up to the ramp's start), a ramp over 0.2-0.22 s (no answer covers the next exchange),
    # then held to the end: asked at 0 and 0.1 s and at every exchange time of the ramp up to its end, and at no other
    scene, model = constant_inertia_scene(
        tmp_path,
        duration=0.3,
        load_events=[{"time": 0.1, "torque": 8.0}, {"time": 0.2, "torque": 6.0, "ramp": 0.02}],
    )
    processes.node("machine", machine_parameters(scene, peers=["governor", "scenario", probe.node.get_name()]))
    processes.node("governor", {"scene_file": str(scene), "coupling": "hold"})
    processes.node("scenario", {"scene_file": str(scene)})
    asks = probe.other_node(f"{probe.node.get_name()}_asks")  # (a node the machine's gate of named peers ignores)
    requests = probe.listen(Header, "load_request", describe=processes.logs, node=asks)
    answers = probe.listen(WrenchStamped, "load_torque_stamped", publishers=1, describe=processes.logs)
    listener = RunListener(probe, governed=True, diagnostics_publishers=2, describe=processes.logs)

    def readers(topic: str) -> set[str]:
        return {info.node_name for info in probe.node.get_subscriptions_info_by_topic(topic)}

    # the scenario subscribes to machine/status last: a participant learns of another's subscriptions in the order
    # they were made, so once this one is known a joint_states subscription of the scenario would be too
    probe.spin_until(
        lambda: "scenario" in readers("/machine/status") and "governor" in readers("/joint_states"),
        "the scenario's and the governor's subscriptions",
        describe=processes.logs,
    )
    joint_state_readers = readers("/joint_states")
    listener.open_gate()
    end = listener.wait_finished()
    probe.spin_until(lambda: len(answers) >= len(requests), "an answer to every request", describe=processes.logs)
    asked = [stamp_ns(request.stamp) for request in requests]
    ramp = [to_nanoseconds(0.2) + k * to_nanoseconds(0.002) for k in range(11)]
    assert asked == [0, to_nanoseconds(0.1), *ramp], asked
    assert [stamp_ns(answer.header.stamp) for answer in answers] == asked
    assert [answer.wrench.force.x for answer in answers[:2]] == [0.1, 0.2]  # held up to the next event
    assert "scenario" not in joint_state_readers, joint_state_readers  # the scenario reads no joint_states
    assert_equals_cosimulation(listener, end, model, cosimulate(model, 0.002))


# -------------------------------------------------------------------------------------------------
# 4. Bad messages are counted and change nothing (more in test_hostile_participant.py)


@pytest.fixture(scope="module")
def bad_messages_run(tmp_path_factory):
    """A lockstep run (machine, governor, scenario) that got bad messages on every input before it
    started (the load out of range, a throttle and a speed from the test node, which is neither the governor nor
    the machine): (listener, end [ns], model, the governor's last diagnostics values)."""
    folder = tmp_path_factory.mktemp("bad_messages")
    domain = next_domain_id()
    with processes_on(folder, domain) as processes, probe_on(domain) as probe:
        scene, model = constant_inertia_scene(folder, duration=0.3, load_events=[{"time": 0.1, "torque": 8.0}])
        processes.node(
            "machine",
            machine_parameters(scene, peers=["governor", "scenario", probe.node.get_name()], max_load_torque=1e3),
        )
        processes.node("governor", {"scene_file": str(scene), "coupling": "hold"})
        processes.node("scenario", {"scene_file": str(scene)})
        listener = RunListener(probe, governed=True, diagnostics_publishers=2, describe=processes.logs)
        load = probe.publisher(Float64, "load_torque", describe=processes.logs)
        throttle = probe.publisher(JointState, "throttle", describe=processes.logs)
        speed = probe.publisher(
            JointState, "joint_states", subscribers=1, describe=processes.logs
        )  # the governor (the scenario asks on load_request)
        request = probe.publisher(Header, "load_request", subscribers=1, describe=processes.logs)  # the scenario
        for value in (math.nan, math.inf, 1e9):
            load.publish(Float64(data=value))
        throttle.publish(JointState(name=["valve"], position=[0.5]))
        throttle.publish(JointState(name=["throttle"], position=[1.5]))
        speed.publish(JointState(name=["wheel"], position=[0.0], velocity=[100.0]))
        request.publish(Header())  # the load at t = 0, asked by another node than the machine
        for publisher in (load, throttle, speed, request):
            assert publisher.wait_for_all_acked(Duration(seconds=WAIT))
        probe.node.destroy_publisher(speed)  # (volatile: it would only warn of the test node's own listener)
        listener.open_gate()  # the machine's third subscriber: the run starts
        end = listener.wait_finished()
        governor = probe.spin_until(
            lambda: [
                values for _, _, values in listener.statuses("/governor") if values.get("refused_messages", "0") != "0"
            ],
            "the governor's diagnostics counting the bad message",
            describe=processes.logs,
        )
        scenario = probe.spin_until(
            lambda: [
                values for _, _, values in listener.statuses("/scenario") if values.get("refused_messages", "0") != "0"
            ],
            "the scenario's diagnostics counting the bad request",
            describe=processes.logs,
        )
    yield listener, end, model, governor[-1], scenario[-1]  # (the nodes are stopped: the listener keeps what it got)


def test_bad_messages_are_rejected_and_counted(bad_messages_run):
    listener, end, model, governor, scenario = bad_messages_run
    level, message, values = listener.final_status()
    assert level == DiagnosticStatus.WARN and message == "5 messages refused", (level, message)
    assert {key: value for key, value in values.items() if key.startswith("refused")} == {
        "refused_messages": "5",
        "refused: load_torque: not finite": "2",
        "refused: load_torque: out of range": "1",
        "refused: throttle: not from governor": "2",
    }
    assert governor["refused_messages"] == "1" and governor["refused: joint_states: not from machine"] == "1", governor
    assert scenario["refused_messages"] == "1", scenario
    assert scenario["refused: load_request: not from machine"] == "1", scenario
    # the state never saw them: the run is the in-process co-simulation to the last bit
    assert_equals_cosimulation(listener, end, model, cosimulate(model, 0.002))


# -------------------------------------------------------------------------------------------------
# 5. Fail-safe (realtime) and overspeed trip (lockstep)


def test_realtime_machine_closes_the_throttle_when_the_governor_dies(tmp_path, processes, probe):
    scene, _ = constant_inertia_scene(tmp_path, duration=120.0)  # ended by the test, long before that
    governor = processes.node("governor", {"scene_file": str(scene)})
    # the governor first (a realtime machine does not wait for anyone): it listens and can answer
    probe.spin_until(
        lambda: probe.node.count_subscribers("joint_states") >= 1 and probe.node.count_publishers("throttle") >= 1,
        "the governor node",
        describe=processes.logs,
    )
    listener = RunListener(probe, governed=False, diagnostics_publishers=1, describe=processes.logs)
    listener.open_gate()  # (a realtime machine waits for no one)
    # made for a loaded machine (two cores, a tenth of one per process; once failed at 1 x real time and a 0.05 s
    # timeout): at a quarter of real time with a 0.5 s throttle timeout the governor has 2 s of wall time to answer, so
    # a late answer does not keep the machine on its fail-safe, nor does a throttle still on its way when the governor
    # dies end it; the machine waits up to its peer timeout (60 s) for the governor's throttle publisher (not for a
    # load's: no scenario node here)
    processes.node(
        "machine",
        {
            "scene_file": str(scene),
            "time_mode": "realtime",
            "real_time_factor": 0.25,
            "exchange_step": 0.005,
            "throttle_timeout": 0.5,
            "fail_safe": "close",
            "peer_timeout": 60.0,
            "lockstep_inputs": ["throttle"],
        },
    )

    def governed_after(time_ns: int) -> bool:  # the governor's throttle drives the machine at time_ns
        return bool(listener.statuses()) and any(
            when >= time_ns and values["drive"] > 0.0 for when, values in listener.moments.items()
        )

    probe.spin_until(lambda: governed_after(500_000_000), "the governed machine at 0.5 s", describe=processes.logs)
    governor.kill()
    assert governor.wait(WAIT) == -signal.SIGKILL

    def closed_since() -> int | None:
        """Where the machine last went on its fail-safe [ns] (None while the governor drives): with the
        governor dead nothing ends it. (A governor answering late under load may have made the
        machine fail safe for a while before; the last change is the one that counts.)"""
        statuses = listener.statuses()
        if not statuses or statuses[-1][2]["fail_safe_active"] != "True":
            return None
        since = len(statuses) - 1
        while since > 0 and statuses[since - 1][2]["fail_safe_active"] == "True":
            since -= 1
        return to_nanoseconds(float(statuses[since][2]["sim_time"]))

    probe.spin_until(
        lambda: closed_since() is not None and max(listener.moments) >= closed_since() + 300_000_000,
        "the machine on its fail-safe for 0.3 s",
        describe=processes.logs,
    )
    since = closed_since()
    level, message, values = [
        status for status in listener.statuses() if to_nanoseconds(float(status[2]["sim_time"])) >= since
    ][0]
    assert level == DiagnosticStatus.WARN and message.startswith("fail-safe (close)"), (level, message)
    assert values["throttle"] == "0.0", values
    late = {when: values["drive"] for when, values in listener.moments.items() if when > since}
    assert len(late) >= 50 and all(drive == 0.0 for drive in late.values()), (
        f"the throttle did not stay closed after {since} ns: {late}"
    )


TRIP_STEP = 0.002


@pytest.fixture(scope="module")
def overspeed_run(tmp_path_factory):
    """A lockstep run (machine, governor, scenario, recorder) of a full load rejection with the trip just
    above the initial speed: (listener, end [ns], model, the in-process run, the recorder's files)."""
    folder = tmp_path_factory.mktemp("overspeed")
    domain = next_domain_id()
    with processes_on(folder, domain) as processes, probe_on(domain) as probe:
        scene, model = constant_inertia_scene(folder, duration=0.4, load_events=[{"time": 0.1, "torque": 0.0}])
        trip = _steady_speed() + 0.3  # the full load rejection reaches it
        run = cosimulate(model, TRIP_STEP, overspeed_trip=trip)
        assert run.tripped_at is not None and 0.1 < run.tripped_at < 0.4
        processes.node(
            "machine",
            machine_parameters(
                scene,
                peers=["governor", "scenario", "recorder", probe.node.get_name()],
                overspeed_trip=trip,
                exchange_step=TRIP_STEP,
            ),
        )
        processes.node("governor", {"scene_file": str(scene), "coupling": "hold"})
        processes.node("scenario", {"scene_file": str(scene)})
        output = folder / "trip.rrd"
        recorder = processes.node(
            "recorder",
            {"scene_file": str(scene), "output": str(output), "exchange_step": TRIP_STEP, "coupling": "hold"},
        )
        listener = RunListener(probe, governed=True, diagnostics_publishers=2, describe=processes.logs)
        listener.open_gate()
        end = listener.wait_finished()
        assert processes.wait(recorder) == 0, processes.logs()
    yield listener, end, model, run, output


def test_overspeed_trip_closes_the_throttle_for_good(overspeed_run):
    listener, end, model, run, output = overspeed_run
    level, message, values = listener.final_status()
    assert level == DiagnosticStatus.ERROR and message.startswith("overspeed trip"), (level, message)
    assert float(values["tripped_at"]) == run.tripped_at
    tripped = to_nanoseconds(run.tripped_at)
    drive = {when: values["drive"] for when, values in listener.moments.items()}
    assert all(value > 0.0 for when, value in drive.items() if when < tripped)
    assert all(value == 0.0 for when, value in drive.items() if when >= tripped)
    assert_equals_cosimulation(listener, end, model, run)
    # the recorder's CSV holds the same run
    csv = np.genfromtxt(output.with_suffix(".csv"), delimiter=",", names=True)
    np.testing.assert_array_equal(csv["omega"], run.states[1])
    np.testing.assert_array_equal(csv["t"], run.times)


def _in_process_summary(model, run) -> dict:
    from mech_regulator.analysis import summarise_cosimulation
    from mech_regulator.cli.report.data import to_json

    return json.loads(to_json(summarise_cosimulation(model, run, TRIP_STEP)))


def _without_pace(summary: dict) -> dict:
    """The recorder's summary less the nodes' pace (wall time of the exchanges and real-time factor, which only a
    ROS run has, and `run`'s start-up), after checking that the two agree with the simulated time (arithmetic, not a
    speed test)."""
    wall, pace = summary.pop("wall_time_s"), summary.pop("real_time_factor")
    assert wall > 0.0 and pace * wall == pytest.approx(summary["t_end"], rel=1e-12)  # exchanges from t = 0 to t_end
    start_up = summary.pop("start_up_s", None)  # `run`'s (the command's start came before the first exchange)
    assert start_up is None or start_up > 0.0
    return summary


def test_recorder_summary_of_a_tripped_run(overspeed_run):
    # (once a bug: the recorder's summary said tripped_at null; and then status complete)
    _, _, model, run, output = overspeed_run
    summary = json.loads(output.with_suffix(".json").read_text())
    assert summary.pop("recording") == str(output) and summary.pop("csv") == str(output.with_suffix(".csv"))
    assert _without_pace(summary) == _in_process_summary(model, run)
    assert summary["tripped_at"] == run.tripped_at
    assert (
        summary["status"] == "tripped"
        and summary["message"] == f"overspeed trip at t = {run.tripped_at:.6g} s: throttle closed from then on"
    )
    last_event = events(output)[-1]
    assert last_event[:2] == (to_nanoseconds(0.4), "WARN") and last_event[2].startswith("end: tripped at t = 0.400 s")


def _governor_batch(times_ns: list[int], throttle: float) -> JointState:
    """A governor/state batch (common.Batch) of the constant-inertia scene's governor at times_ns, one group each."""
    message = JointState()
    for when in times_ns:
        for name, position, velocity in (
            ("stamp", float(when), math.nan),
            ("sleeve", 0.01, 0.0),
            ("arm", 0.3, 0.0),
            ("throttle", throttle, 0.0),
        ):
            message.name.append(name)
            message.position.append(position)
            message.velocity.append(velocity)
            message.effort.append(math.nan)
    return message


def test_the_recorder_records_an_exchange_answered_twice_once(tmp_path):
    # (once a bug: a loaded machine publishes an exchange time again, its governor answers it twice, and the repeat
    # opening the next batch was recorded again: 1002 throttle samples for 1001 exchanges)
    from unittest import mock

    from mech_regulator.nodes.recorder import RecorderNode
    from mech_regulator.nodes.run_rows import RunRows

    recorder = RecorderNode.__new__(RecorderNode)  # its bookkeeping only: no ROS node, no recording file
    _, recorder.model = constant_inertia_scene(tmp_path)
    recorder.recording = mock.Mock()
    recorder.rows = RunRows(recorder.model, False, None, None, mock.Mock(), mock.Mock())
    recorder.on_governor(_governor_batch([0, 2_000_000, 2_000_000], throttle=0.5))  # the repeat in the batch
    recorder.on_governor(_governor_batch([2_000_000, 4_000_000], throttle=0.25))  # the repeat opening the next
    recorded = [when for call in recorder.recording.add_governors.call_args_list for when in call.args[0].tolist()]
    assert recorded == [0, 2_000_000, 4_000_000]
    assert list(recorder.rows.governor) == recorded and recorder.rows.governor[2_000_000]["throttle"] == 0.5  # first
    with pytest.raises(BadMessage, match="out of order"):  # before the newest: refused, as before
        recorder.on_governor(_governor_batch([2_000_000], throttle=0.5))


def _joint_batch(groups: list[tuple[int, dict[str, tuple[float, float, float]]]]) -> JointState:
    """A Batch message (common.Batch) of `groups`: (exchange time [ns], {joint: (position, velocity, effort)})."""
    message = JointState()
    for when, joints in groups:
        for name, (position, velocity, effort) in {"stamp": (float(when), 0.0, math.nan), **joints}.items():
            message.name.append(name)
            message.position.append(position)
            message.velocity.append(velocity)
            message.effort.append(effort)
    return message


def _engine_groups(count: int) -> tuple[list, list]:
    """engine_direct's machine/moments and governor/state groups of `count` exchanges 20 ms apart, made up: the load
    6 N m, then 8 N m from the 13th exchange (index 12) on."""
    machine, governor = [], []
    for index in range(count):
        when, load = index * 20_000_000, 6.0 if index < 12 else 8.0
        drive, resistance = 10.0 + index, -5.0 - 0.01 * index
        machine.append(
            (
                when,
                {
                    "crank": (0.5 * index, 220.0 + 0.1 * index, math.nan),
                    **{
                        name: (math.nan, math.nan, effort)
                        for name, effort in (
                            ("drive", drive),
                            ("resistance", resistance),
                            ("external", -load),
                            ("net", drive + resistance - load),
                            ("load", load),
                        )
                    },
                    "throttle": (0.8, math.nan, math.nan),
                },
            )
        )
        governor.append(
            (
                when,
                {
                    "sleeve": (0.03 + 1e-4 * index, 0.001, math.nan),
                    "arm": (0.4 + 0.001 * index, 0.01, math.nan),
                    "throttle": (0.8 - 0.001 * index, math.nan, math.nan),
                },
            )
        )
    return machine, governor


def _bare_recorder(model, recording, csv: Path | None = None):
    """A RecorderNode's bookkeeping without ROS (no node): its model, `recording`, a RunRows writing `csv`."""
    from unittest import mock

    from mech_regulator.nodes.recorder import RecorderNode
    from mech_regulator.nodes.run_rows import RunRows

    recorder = RecorderNode.__new__(RecorderNode)
    recorder.model = model
    recorder.recording, recorder.controller, recorder.unsent = recording, "governor", 0
    recorder.rows = RunRows(model, False, csv, None, lambda what, path, write: write() or True, mock.Mock())
    recorder.state_walls, recorder.last_exchanges, recorder.progress_publisher = [], [], _Published()
    return recorder


def test_the_recorder_records_a_batch_as_its_groups_one_by_one(tmp_path):
    """engine_direct's streams, 30 exchanges: one batch each gives the recording (every entity's samples, the set
    point of the load before each sample, the load's step as one event) and the CSV that 30 batches of one give."""
    from test_recording import chunks

    from mech_regulator.viz.recording import RunRecording
    from mech_regulator.viz.recording_layout import recorded_series

    model = build_model(load_scene("engine_direct"))
    machine, governor = _engine_groups(30)
    fed = {"batches": ([machine], [governor]), "one_by_one": ([[g] for g in machine], [[g] for g in governor])}
    for name, (machine_batches, governor_batches) in fed.items():
        recorder = _bare_recorder(model, RunRecording(model, path=tmp_path / f"{name}.rrd"), tmp_path / f"{name}.csv")
        for groups in machine_batches:
            recorder.on_moments(_joint_batch(groups))
        for groups in governor_batches:
            recorder.on_governor(_joint_batch(groups))
        recorder.rows.write(math.inf, None)
        recorder.rows.close()
        recorder.recording.close("complete")
        assert recorder.rows.written == 30 and recorder.state_walls == [0.0, 0.0]
        assert recorder.last_exchanges == [560_000_000, 580_000_000] and recorder.unsent == 30
    assert (tmp_path / "batches.csv").read_bytes() == (tmp_path / "one_by_one.csv").read_bytes()
    for entity in [*recorded_series(model, False), "mechanism/rod", "governor/drawing/spindle_mark"]:
        contents = [
            [
                {column: values for column, values in batch.to_pydict().items() if column != "rerun.controls.RowId"}
                for batch in chunks(tmp_path / f"{name}.rrd", f"/{entity}")
            ]
            for name in fed
        ]
        assert contents[0] == contents[1] and contents[0], entity
    speeds = [operating_point(model, load).speed for load in (6.0, 8.0)]
    set_point = scalars(tmp_path / "batches.rrd", "/speed/set_point")[1]
    assert np.array_equal(set_point, [speeds[0]] * 13 + [speeds[1]] * 17)  # (the load of the sample before)
    assert events(tmp_path / "batches.rrd")[1] == (240_000_000, "INFO", "load step 6 -> 8 N m")


def test_the_recorder_refuses_a_batch_naming_its_first_bad_value(tmp_path):
    """A bad value in a batch's row k refuses the whole batch (nothing of it recorded), naming row k's exchange time
    and the field as a batch of that row alone would: rows first, then the fields in the order checked."""
    from unittest import mock

    model = build_model(load_scene("engine_direct"))
    machine, governor = _engine_groups(10)
    recorder = _bare_recorder(model, mock.Mock())
    machine[6][1]["crank"] = (0.5, math.nan, math.nan)  # row 6: the crank's speed, and further on its net moment
    machine[6][1]["net"] = (math.nan, math.nan, math.inf)
    machine[8][1]["crank"] = (math.nan, 1.0, math.nan)  # (a later row)
    expected = "machine/moments at 0.12 s: crank velocity [rad/s] = nan, expected a finite number in [-inf, inf]"
    for groups in (machine, machine[6:7]):
        with pytest.raises(BadMessage) as refused:
            recorder.on_moments(_joint_batch(groups))
        assert (refused.value.reason, refused.value.detail) == ("not finite", expected)
    governor[4][1]["throttle"] = (1.5, math.nan, math.nan)  # row 4: out of range
    governor[7][1]["sleeve"] = (math.nan, 0.0, math.nan)  # (a later row)
    with pytest.raises(BadMessage) as refused:
        recorder.on_governor(_joint_batch(governor))
    assert (refused.value.reason, refused.value.detail) == (
        "out of range",
        "governor/state at 0.08 s: throttle = 1.5, expected a finite number in [0, 1]",
    )
    governor[4][1]["arm"] = (0.4, math.inf, math.nan)  # the same row's arm rate: checked before its throttle
    with pytest.raises(BadMessage) as refused:
        recorder.on_governor(_joint_batch(governor))
    assert (refused.value.reason, refused.value.detail) == (
        "not finite",
        "governor/state at 0.08 s = inf, expected a finite number in [-inf, inf]",
    )
    assert recorder.rows.received == {"machine": 0, "governor": 0} and not recorder.recording.method_calls


def test_a_batch_read_as_columns_is_checked_in_the_order_of_the_message():
    """batch_columns: the later of a joint given twice in a group; the first bad stamp or stamp out of order, and the
    first group without a joint asked for, named as a reading group by group names them."""
    from mech_regulator.nodes.common import batch_columns

    message = _joint_batch([(0, {"a": (1.0, 2.0, 3.0), "b": (4.0, 5.0, 6.0)}), (5, {"b": (7.0, 8.0, 9.0)})])
    message.name.append("a")  # a second "a" in the second group
    for field, value in (("position", 10.0), ("velocity", 11.0), ("effort", 12.0)):
        getattr(message, field).append(value)
    with pytest.raises(BadMessage) as refused:
        batch_columns(
            _joint_batch([(0, {"a": (1.0, 2.0, 3.0), "b": (1.0, 2.0, 3.0)}), (5, {"b": (7.0, 8.0, 9.0)})]), ("b", "a")
        )
    assert (refused.value.reason, refused.value.detail) == (
        "missing joint",
        "the group at 5e-09 s has no a (it has stamp, b)",
    )
    columns = batch_columns(message, ("a", "b"))
    assert columns.times.tolist() == [0, 5] and columns.walls.tolist() == [0.0, 0.0]
    assert [field.tolist() for field in columns.joints["a"]] == [[1.0, 10.0], [2.0, 11.0], [3.0, 12.0]]
    assert columns.joints["b"].effort.tolist() == [6.0, 9.0]
    for stamps, reason, detail in (
        ([3.0, 1.0, 0.5], "out of order", "a batch's exchange time 1 ns after 3 ns"),
        ([3.0, 3.0, 1.0], "out of order", "a batch's exchange time 1 ns after 3 ns"),
        (
            [3.0, 2.5, 1.0],
            "bad stamp",
            "a batch's exchange time 2.5 ns, expected a whole number in 0..9007199254740992",
        ),
        (
            [-1.0, 1.0, 0.0],
            "bad stamp",
            "a batch's exchange time -1.0 ns, expected a whole number in 0..9007199254740992",
        ),
    ):
        bad = _joint_batch([(0, {"a": (1.0, 2.0, 3.0)})] * 3)
        for index, value in enumerate(stamps):
            bad.position[2 * index] = value
        with pytest.raises(BadMessage) as refused:
            batch_columns(bad, ("a",))
        assert (refused.value.reason, refused.value.detail) == (reason, detail), stamps


def test_the_recorder_counts_the_exchanges_the_machine_published_that_it_missed(tmp_path):
    # (a recorder stalled past the publishers' histories misses the oldest batches: its summary must say so)
    from unittest import mock

    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    from mech_regulator.nodes.recorder import RecorderNode

    recorder = RecorderNode.__new__(RecorderNode)  # its bookkeeping only: no ROS node, no recording file
    _, recorder.model = constant_inertia_scene(tmp_path)
    recorder.recording = mock.Mock()
    recorder.get_namespace = lambda: "/"
    recorder.own_name, recorder.peer_names = "recorder", {"machine": "machine"}
    recorder.reports, recorder.machine_status, recorder.tripped_at = {}, (DiagnosticStatus.OK, ""), None
    recorder.machine_reported_end, recorder.machine_exchanges = False, None
    recorder.untripped_until = -math.inf
    recorder.rows = mock.Mock(completed=3)  # complete exchanges at 0, 2 and 6 ms: the one at 4 ms never came whole
    assert recorder.missed() == 0  # the machine has not said yet

    def machine_says(values: dict[str, str]) -> None:
        status = DiagnosticStatus(
            name="mech_regulator: /machine", values=[KeyValue(key=key, value=value) for key, value in values.items()]
        )
        recorder.on_diagnostics(DiagnosticArray(status=[status]), "machine")

    machine_says({"sim_time": "0.004"})
    assert recorder.missed() == 0
    machine_says({"sim_time": "0.006", "finished_at_ns": "6000000", "exchanges": "4"})
    assert recorder.machine_reported_end and recorder.missed() == 1
    with pytest.raises(BadMessage, match="exchanges"):
        machine_says({"sim_time": "0.006", "exchanges": "nan"})


def test_the_recorder_says_how_long_it_was_held_back_when_its_run_is_interrupted():
    # (a recorder stopped past the participants' lease is taken for gone: its summary says it was held back, how long)
    from mech_regulator.nodes.common import PARTICIPANT_LEASE
    from mech_regulator.nodes.recorder import HELD_BACK, RecorderNode

    recorder = RecorderNode.__new__(RecorderNode)  # its bookkeeping only: no ROS node, no recording file
    recorder.longest_hold = HELD_BACK  # a wait for callbacks no longer than that: not held back
    assert recorder.held_back() == ""
    recorder.longest_hold = 42.4
    said = recorder.held_back()
    assert "held back (stopped or starved) for 42 s of wall time at once" in said, said
    assert f"the participants' lease, {PARTICIPANT_LEASE:g} s in the run's Fast DDS profile" in said, said


def _machine_batch(times_ns: list[int]) -> JointState:
    """A machine/moments batch (common.Batch) of the constant-inertia scene at times_ns, one group each."""
    message = JointState()
    joints = [("crank", 0.0, 10.0, 0.0), ("throttle", 0.5, 0.0, 0.0)]
    joints += [(name, 0.0, 0.0, 1.0) for name in ("drive", "resistance", "external", "net", "load")]
    for when in times_ns:
        for name, position, velocity, effort in [("stamp", float(when), 0.0, math.nan), *joints]:
            message.name.append(name)
            message.position.append(position)
            message.velocity.append(velocity)
            message.effort.append(effort)
    return message


@pytest.mark.parametrize(
    "machine_status, governor_times, governor_publishers, machine_reported_end, closes",
    [
        ("failed", [0, 2_000_000], 0, True, True),  # the governor refused the last state and ended
        ("failed", [0, 2_000_000], 1, True, False),  # it may still answer the last state: wait
        ("failed", [0, 2_000_000, 4_000_000], 1, True, True),  # it answered the last state too
        ("failed", [0], 0, True, False),  # an answered exchange is missing: wait (FINISH_GRACE)
        ("failed", [0, 2_000_000], 0, False, False),  # the machine's last diagnostics are not in
        ("complete", [0, 2_000_000], 0, True, False),  # a complete run: wait for every sample (FINISH_GRACE)
        ("failed", [], 0, True, True),  # failed at its first exchange, refused: no earlier answer to wait for
    ],
)
def test_the_recorder_closes_a_failed_run_once_all_that_can_still_come_is_in(
    tmp_path, machine_status, governor_times, governor_publishers, machine_reported_end, closes
):
    # (the governor never answers a state beyond its speed range, where a run driven backwards fails: the recorder
    # waited its FINISH_GRACE, 10 s, for that answer after every such run)
    from unittest import mock

    from mech_regulator.nodes.recorder import RecorderNode
    from mech_regulator.nodes.run_rows import RunRows

    recorder = RecorderNode.__new__(RecorderNode)  # its bookkeeping only: no ROS node, no recording file
    _, recorder.model = constant_inertia_scene(tmp_path)
    recorder.recording = mock.Mock()
    recorder.rows = RunRows(recorder.model, False, None, None, mock.Mock(), mock.Mock())
    recorder.controller, recorder.unsent, recorder.state_walls, recorder.last_exchanges = "governor", 0, [], []
    recorder.streams = [mock.Mock(**{"get_publisher_count.return_value": governor_publishers})]
    recorder.finished_at, recorder.machine_result = None, (machine_status, "")
    recorder.machine_reported_end = machine_reported_end
    recorder.progress_publisher = mock.Mock()
    machine_times = [0, 2_000_000, 4_000_000] if governor_times else [0]
    recorder.on_moments(_machine_batch(machine_times))
    assert not recorder.progress_publisher.publish.called  # no governor state yet: nothing taken of every stream
    if governor_times:
        recorder.on_governor(_governor_batch(governor_times, throttle=0.5))
        progress = recorder.progress_publisher.publish.call_args.args[0].stamp  # recorder/progress: both streams'
        assert progress.sec * 1_000_000_000 + progress.nanosec == min(machine_times[-1], governor_times[-1])
    assert not recorder.all_that_can_come()  # the machine has not finished
    recorder.finished_at = machine_times[-1]
    assert recorder.all_that_can_come() == closes


# -------------------------------------------------------------------------------------------------
# 6. Parameters


def _assert_bad_input(processes, cases: dict[str, tuple[str, list[str], list[str]]]) -> None:
    """Start each node with its bad `-p` arguments (side by side): each must end with exit code 2 and a
    message saying what is wrong, without a traceback."""
    started = {
        name: processes.start(
            [
                sys.executable,
                "-m",
                f"mech_regulator.nodes.{node}",
                "--ros-args",
                *[part for argument in arguments for part in ("-p", argument)],
            ],
            name,
        )
        for name, (node, arguments, _) in cases.items()
    }
    for name, process in started.items():
        code = processes.wait(process)
        output = processes.log(process)
        assert code == 2, f"{name}: exit {code}\n{output}"
        assert "Traceback" not in output, f"{name}:\n{output}"
        assert all(part in output for part in cases[name][2]), f"{name}: expected {cases[name][2]} in\n{output}"


def test_bad_scene_settings_end_the_node_with_a_message(tmp_path, processes):
    missing = tmp_path / "missing.yaml"
    _assert_bad_input(
        processes,
        {  # name: (node, arguments, what the message must say)
            "scene": ("machine", [f"scene_file:={missing}"], [str(missing), "no such file"]),
            "inputs": ("machine", ["lockstep_inputs:=[throttle,speed]"], ["lockstep_inputs", "speed"]),
            "ungoverned": ("governor", ["scene_file:=lathe"], ["lathe", "no governor"]),
        },
    )


def test_bad_parameters_end_the_node_with_a_message(processes):
    _assert_bad_input(
        processes,
        {
            "step": ("machine", ["exchange_step:=-1.0"], ["exchange_step", "out of range"]),
            "mode": ("machine", ["time_mode:=fast"], ["time_mode", "'fast'", "lockstep, realtime"]),
            "type": ("machine", ["duration:=abc"], ["duration", "DOUBLE"]),
        },
    )


def _parameter(name: str, value) -> ParameterMessage:
    if isinstance(value, float):
        return ParameterMessage(
            name=name, value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)
        )
    return ParameterMessage(name=name, value=ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value))


def _set_parameter(probe, name: str, value, describe):
    request = SetParameters.Request(parameters=[_parameter(name, value)])
    return probe.call(SetParameters, "/machine/set_parameters", request, describe=describe).results[0]


def _get_parameters(probe, names: list[str], describe) -> list:
    response = probe.call(
        GetParameters, "/machine/get_parameters", GetParameters.Request(names=names), describe=describe
    )
    return [
        value.double_value if value.type == ParameterType.PARAMETER_DOUBLE else value.string_value
        for value in response.values
    ]


def test_parameters_set_at_run_time_are_checked(tmp_path, processes, probe):
    scene, _ = constant_inertia_scene(tmp_path)
    # waiting for a peer that never comes: the node serves its parameters, nothing else happens
    processes.node("machine", machine_parameters(scene, peers=["never_started"]))
    describe = processes.logs
    accepted = _set_parameter(probe, "real_time_factor", 2.0, describe)
    assert accepted.successful, accepted.reason
    refused = _set_parameter(probe, "real_time_factor", 1e6, describe)
    assert not refused.successful and "real_time_factor" in refused.reason and "range" in refused.reason, refused.reason
    refused = _set_parameter(probe, "exchange_step", 0.01, describe)
    assert not refused.successful and "read-only" in refused.reason, refused.reason
    refused = _set_parameter(probe, "fail_safe", "open", describe)
    assert not refused.successful and "fail_safe" in refused.reason and "hold, close" in refused.reason, refused.reason
    assert _get_parameters(probe, ["real_time_factor", "exchange_step", "fail_safe"], describe) == [2.0, 0.002, "close"]


def test_a_refused_fail_safe_is_not_applied(tmp_path, processes, probe):
    # (once a bug: the node applied the value in an on-set callback that ran before the choice check)
    scene, _ = constant_inertia_scene(tmp_path, duration=0.05)
    # no governor: the machine waits peer_timeout for the throttle, then goes on fail-safe; it starts paused, so
    # that the parameter is refused before the first step
    listener = RunListener(probe, governed=False, diagnostics_publishers=0, describe=processes.logs)
    listener.open_gate()
    processes.node(
        "machine",
        machine_parameters(
            scene,
            lockstep_inputs=["throttle"],
            peers=[probe.node.get_name()],
            peer_timeout=5.0,
            exchange_step=0.01,
            start_paused=True,
        ),
    )
    refused = _set_parameter(probe, "fail_safe", "open", processes.logs)
    assert not refused.successful, "ROS accepted fail_safe = 'open'"
    resumed = probe.call(Trigger, "/machine/resume", Trigger.Request(), describe=processes.logs)
    assert resumed.success, resumed.message
    end = listener.wait_finished()
    level, message, values = listener.final_status()
    assert level == DiagnosticStatus.WARN and values["fail_safe_active"] == "True", (level, message)
    assert listener.moments[end]["drive"] == 0.0 and message.startswith("fail-safe (close)"), message


# -------------------------------------------------------------------------------------------------
# 1 and 7. The main job: `mech-regulator run`, its CSV, summary and recording; Ctrl-C


class MainJob:
    """A `mech-regulator run` (its process, log and output paths)."""

    def __init__(
        self, processes: Processes, folder: Path, scene_arguments: list[str], name: str, domain: int | None = None
    ):
        self.rrd = folder / name / "run.rrd"
        self.rrd.parent.mkdir()
        self.csv, self.json = self.rrd.with_suffix(".csv"), self.rrd.with_suffix(".json")
        self.domain_id = domain if domain is not None else next_domain_id()
        self.processes = processes
        self.process = processes.start(
            [
                sys.executable,
                "-m",
                "mech_regulator",
                "run",
                *scene_arguments,
                "--out",
                self.rrd,
                "--domain-id",
                self.domain_id,
                "--quiet",
            ],
            name,
        )

    @property
    def log(self) -> str:
        """The launcher's output."""
        return self.processes.log(self.process)

    @property
    def node_log(self) -> str:
        """The nodes' output (the launcher's <out>.log)."""
        path = self.rrd.with_suffix(".log")
        return path.read_text(errors="replace") if path.exists() else ""

    def describe(self) -> str:
        return f"--- launcher (exit {self.process.poll()})\n{self.log[-3000:]}\n--- nodes\n{self.node_log[-3000:]}"


def played_main_job(folder: Path, arguments: list, name: str) -> MainJob:
    """`run` with `arguments` (processes of its own, the domain MainJob picks) played to its end, exit 0 asserted."""
    started = Processes(folder, dict(os.environ, PYTHONUNBUFFERED="1"))
    try:
        job = MainJob(started, folder, arguments, name)
        started.wait(job.process, 4 * WAIT)
    finally:
        started.stop_all()
    assert job.process.returncode == 0, job.describe()
    return job


@pytest.mark.skipif(not Path("/proc/self/autogroup").exists(), reason="the kernel has no autogroups")
def test_a_node_s_own_session_keeps_the_niceness_it_was_started_with():
    # `nice mech-regulator run`: each node is forked into a session of its own, an autogroup, between which the
    # kernel shares the CPU before niceness counts inside one; the session gets the node's niceness
    script = (
        "import os; os.nice(7); os.setsid(); from mech_regulator.nodes.launch import keep_niceness_in_own_session; "
        "keep_niceness_in_own_session(); print(open('/proc/self/autogroup').read())"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout
    assert out.strip().endswith("nice 7"), out


def test_run_takes_a_domain_no_other_process_holds():
    # (once a cause of a failure: `run` without --domain-id took a random domain, one a test held at times)
    held = next_domain_id()  # held by this process until it ends, as a test's or another run's
    chosen = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys; from mech_regulator.nodes.launch import claim_domain; print(claim_domain(int(sys.argv[1])))",
            str(DOMAIN_IDS.index(held)),
        ],
        capture_output=True,
        text=True,
        timeout=WAIT,
        check=True,
    )
    assert int(chosen.stdout) in DOMAIN_IDS and int(chosen.stdout) != held, chosen


def rest_over(domain: int) -> None:
    """Date the lock file of `domain` back past the participants' lease: as if last used long ago (claim_domain)."""
    long_ago = time.time() - 2 * launch_domains.PARTICIPANT_LEASE
    os.utime(launch_domains.DOMAIN_LOCKS / f"{domain}.lock", (long_ago, long_ago))


def test_a_released_domain_is_free_again_and_only_those_claimed_after_the_kept_ones():
    """release_domains(keep): the claims after the first `keep` released (the suite's autouse fixture after each
    test): a released domain rests for the participants' lease (another free one is taken from the same start: a
    node killed there is remembered that long), then is claimed again from the same start; one kept stays held."""
    kept = next_domain_id()
    claims = len(launch_domains._claimed_domains)
    used = next_domain_id()
    launch_domains.release_domains(keep=claims)
    assert launch_domains.claim_domain(DOMAIN_IDS.index(used)) != used  # resting
    rest_over(used)
    assert launch_domains.claim_domain(DOMAIN_IDS.index(used)) == used  # free again
    assert launch_domains.claim_domain(DOMAIN_IDS.index(kept)) != kept  # still held by this process


# A node's process after its work ended normally (end_if_stuck(0)), then stuck in a C call that holds the GIL (as
# Fast DDS's deadlock in destroying a participant): ctypes.PyDLL calls keep the GIL
HUNG_IN_TEARDOWN = """
import ctypes
from mech_regulator.nodes.common import end_if_stuck
end_if_stuck(0)
ctypes.PyDLL(None).sleep(120)
"""


def test_a_node_hung_in_its_teardown_holding_the_gil_is_ended_by_its_alarm():
    """The watchdog thread of end_if_stuck cannot run while a C call holds the GIL; SIGALRM ends the process (the
    launcher reads that exit as launch.TEARDOWN_HANG, a teardown hang after finished work, not a failure)."""
    hung = subprocess.run([sys.executable, "-c", HUNG_IN_TEARDOWN], capture_output=True, text=True, timeout=WAIT)
    assert hung.returncode == launch_domains.TEARDOWN_HANG == -signal.SIGALRM, hung


# A test node whose close is stuck in a C call that holds the GIL (as Fast DDS's deadlock, eProsima/Fast-DDS#6502):
# its destroy_node sleeps in ctypes.PyDLL, with the watchdog's limit cut to 1 s
PROBE_HUNG_IN_CLOSE = """
import ctypes, sys, types
sys.path.insert(0, sys.argv[1])
import ros_support
ros_support.CLOSE_LIMIT = 1.0
ros_support.wait_for_a_quiet_graph = lambda node, spin: None
probe = ros_support.Probe.__new__(ros_support.Probe)
probe.executor, probe.others = types.SimpleNamespace(shutdown=lambda: None), []
probe.node = types.SimpleNamespace(destroy_node=lambda: ctypes.PyDLL(None).sleep(120))
probe.close()
"""


def test_a_test_node_whose_close_hangs_holding_the_gil_ends_its_process():
    """Probe.close arms faulthandler's watchdog (no GIL needed): a close Fast DDS deadlocked ends the test worker after
    CLOSE_LIMIT, with every thread's stack, instead of hanging the suite."""
    hung = subprocess.run(
        [sys.executable, "-c", PROBE_HUNG_IN_CLOSE, str(Path(__file__).parent)],
        capture_output=True,
        text=True,
        timeout=WAIT,
    )
    assert hung.returncode == 1 and "Timeout (0:00:01)!" in hung.stderr and "in close" in hung.stderr, hung


# A run's process on a domain (its run lock held), until its stdin closes
RUN_STILL_ON = """
import sys
from mech_regulator.nodes import launch
launch.claim_run(int(sys.argv[1]))
print("on", flush=True)
sys.stdin.read()
"""


def test_a_domain_a_run_is_still_on_is_not_released_until_the_run_has_left():
    """A test's domain is not handed to the next test while a run it started is still on it (a run's nodes, forked,
    hold its run lock as long as they live, also after their launcher ended; seen as the next test's `run` refused)."""
    claims = len(launch_domains._claimed_domains)
    domain = next_domain_id()
    run = subprocess.Popen(
        [sys.executable, "-c", RUN_STILL_ON, str(domain)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        assert run.stdout.readline() == "on\n"
        launch_domains.release_domains(keep=claims)
        assert launch_domains.claim_domain(DOMAIN_IDS.index(domain)) != domain  # kept: the run is on it
    finally:
        run.communicate(timeout=WAIT)
    launch_domains.release_domains(keep=claims)
    rest_over(domain)
    assert launch_domains.claim_domain(DOMAIN_IDS.index(domain)) == domain  # the run has left: free


# A domain no process holds but a run with --domain-id is on (here this process), then the run lock of a run without
# --domain-id whose random choice starts there
RUN_ON_A_DOMAIN = """
import random
from mech_regulator.nodes import launch
import os, time
free = launch.claim_domain(0)
launch._claimed_domains.pop().close()  # released: no test holds it, as a domain a `run --domain-id` is on
long_ago = time.time() - 2 * launch.PARTICIPANT_LEASE
os.utime(launch.DOMAIN_LOCKS / f"{free}.lock", (long_ago, long_ago))  # rested: only the run lock keeps it
launch.claim_run(free)
random.randrange = lambda count: launch.DOMAIN_IDS.index(free)
print(free, launch.claim_run(None))
"""


def test_run_without_domain_id_takes_no_domain_another_run_is_on():
    chosen = subprocess.run(
        [sys.executable, "-c", RUN_ON_A_DOMAIN],
        capture_output=True,
        text=True,
        timeout=WAIT,
        check=True,
    )
    on, taken = (int(word) for word in chosen.stdout.split())
    assert taken in DOMAIN_IDS and taken != on, chosen


# A test process that claims a domain, starts a process on it and dies without stopping it (a timeout's kill)
ORPHAN = """
import os, sys
sys.path.insert(0, sys.argv[1])
from ros_support import Processes, next_domain_id, ros_environment
from pathlib import Path
domain = next_domain_id()
child = Processes(Path(sys.argv[2]), ros_environment(domain)).start(
    [sys.executable, "-c", "import time; time.sleep(600)"], "orphan"
)
print(domain, child.pid, flush=True)
os._exit(0)
"""


def test_a_domain_stays_claimed_while_a_process_started_on_it_runs(tmp_path):
    # (a gap: a test process killed by a timeout released its domains while the nodes it had started on them ran on,
    # for the next test run that claimed one to meet)
    started = subprocess.run(
        [sys.executable, "-c", ORPHAN, str(Path(__file__).parent), str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=WAIT,
        check=True,
    )
    domain, orphan = (int(word) for word in started.stdout.split())
    lock = open(DOMAIN_LOCKS / f"{domain}.lock", "a")
    try:
        with pytest.raises(BlockingIOError):
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)  # held by the orphan
        os.kill(orphan, signal.SIGKILL)
        deadline, free = time.monotonic() + WAIT, False
        while not free and time.monotonic() < deadline:  # free once it has ended
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
                free = True
            except BlockingIOError:
                time.sleep(0.05)
        assert free
    finally:
        lock.close()
        with contextlib.suppress(ProcessLookupError):
            os.kill(orphan, signal.SIGKILL)  # (should the test have failed before)


def _short_engine_arguments() -> list[str]:
    """The short engine_direct, exchanged every 1 ms with the hold coupling (not run's defaults: many exchanges)."""
    return ["engine_direct", *[part for change in SHORT_ENGINE for part in ("--set", change)], "--coupling", "hold"]


@pytest.fixture(scope="module")
def main_jobs(tmp_path_factory):
    """Two runs of the main job on the short engine_direct, side by side (each on its own domain)."""
    folder = tmp_path_factory.mktemp("main_job")
    started = Processes(folder, dict(os.environ, PYTHONUNBUFFERED="1"))  # each run sets its domain
    try:
        jobs = [
            MainJob(
                started,
                folder,
                [
                    *_short_engine_arguments(),
                    "--exchange-step",
                    "1e-3",
                    *(["--bag", folder / "first_bag"] if name == "first" else []),
                ],
                name,
            )
            for name in ("first", "second")
        ]
        for job in jobs:
            started.wait(job.process, 4 * WAIT)
    finally:
        started.stop_all()
    yield jobs


def test_main_job_reproduces_the_in_process_cosimulation(main_jobs, tmp_path, capsys):
    for job in main_jobs:
        assert job.process.returncode == 0, job.describe()
        assert "Traceback" not in job.log + job.node_log, job.describe()
    first, second = main_jobs
    csv = tmp_path / "in_process.csv"
    code, out, _ = run_cli(
        capsys,
        "simulate",
        *_short_engine_arguments(),
        "--exchange-step",
        "1e-3",
        "--out",
        str(csv),
        "--json",
        "--quiet",
    )
    assert code == 0
    expected = csv.read_bytes()
    assert expected.count(b"\n") == 1002  # the header and every exchange time
    assert first.csv.read_bytes() == expected, "the ROS run's CSV differs from simulate --exchange-step"
    assert second.csv.read_bytes() == expected, "a second ROS run gave another CSV"
    summary, in_process = json.loads(first.json.read_text()), json.loads(out)
    assert summary.pop("recording") == str(first.rrd) and summary.pop("csv") == str(first.csv)
    assert summary.pop("bag") == str(first.rrd.parent.parent / "first_bag")  # (test_main_job_bag_...)
    in_process.pop("csv")
    assert "x real time over the exchanges" in first.log
    assert _without_pace(summary) == in_process
    responses = summary["governor"]["load_responses"]
    assert [(item["time"], item["load_before"], item["load_after"]) for item in responses] == [
        (0.4, 6.0, 8.0),
        (0.7, 8.0, 0.0),
    ]
    assert responses[0]["static_error"] < 0.0 < responses[1]["static_error"]
    assert summary["status"] == "complete" and summary["samples"] == 1001 and summary["tripped_at"] is None
    assert f"open the recording with: {viewer_command(first.rrd)}" in first.log


@pytest.mark.parametrize(
    "timing",
    [["--exchange-step", "0.02", "--exchange-tolerance", "1e-6"], ["--exchange-step", "0.03"]],
    ids=["adaptive", "fixed-off-the-load-changes"],
)
def test_main_job_with_irregular_exchange_times_reproduces_the_in_process_cosimulation(tmp_path, capsys, timing):
    """Exchange times the machine decides (it sends each as the end of its predicted samples; the governor and the
    scenario answer whatever time it stamps): the adaptive step, or a fixed 30 ms step whose grid misses the load
    changes at 0.4 and 0.7 s (the step that would cross one ends on it): the nodes' CSV is the in-process
    co-simulation's byte for byte, and both summaries record the same steps."""
    arguments = [*_short_engine_arguments(), "--coupling", "corrected", *timing]
    job = played_main_job(tmp_path, arguments, "adaptive")
    csv = tmp_path / "in_process.csv"
    code, out, _ = run_cli(capsys, "simulate", *arguments, "--out", str(csv), "--json", "--quiet")
    assert code == 0
    assert job.csv.read_bytes() == csv.read_bytes(), "the ROS run's CSV differs from simulate --exchange-tolerance"
    summary, in_process = json.loads(job.json.read_text()), json.loads(out)
    assert summary["exchange_steps"] == in_process["exchange_steps"]
    assert in_process["exchange_steps"]["min"] < in_process["exchange_steps"]["max"]  # the steps did change
    assert summary["exchange_tolerance"] == in_process["exchange_tolerance"] == (1e-6 if len(timing) > 2 else None)
    times = [float(line.split(b",")[0]) for line in csv.read_bytes().splitlines()[1:]]
    assert {0.4, 0.7} <= set(times), times[:20]  # an exchange on each load change


def _rerun() -> str:
    rerun = shutil.which("rerun", path=str(Path(sys.executable).parent)) or shutil.which("rerun")
    assert rerun is not None, "no rerun executable next to this Python or on PATH (rerun-sdk installs it)"
    return rerun


def _verify(rrd: Path) -> None:
    result = subprocess.run([_rerun(), "rrd", "verify", str(rrd)], capture_output=True, text=True, timeout=WAIT)
    assert result.returncode == 0 and "1 file verified" in result.stdout + result.stderr, (
        f"rerun rrd verify {rrd}: exit {result.returncode}\n{result.stdout}\n{result.stderr}"
    )


def _recorded_scalars(rrd: Path) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], set[str], set[str]]:
    """The scalar series of a recording: entity -> (sim_time [ns], values), sorted by time; also every
    entity path and every timeline name."""
    from rerun.chunk import RrdReader

    series: dict[str, list[tuple[int, float]]] = {}
    entities, timelines = set(), set()
    for chunk in RrdReader(str(rrd)).stream().to_chunks():
        entities.add(chunk.entity_path)
        timelines.update(chunk.timeline_names)
        batch = chunk.to_record_batch()
        if "Scalars:scalars" not in batch.schema.names:
            continue
        assert "sim_time" in batch.schema.names, f"{chunk.entity_path}: scalars off the sim_time timeline"
        times = batch.column("sim_time").cast("int64").to_pylist()
        values = batch.column("Scalars:scalars").to_pylist()
        series.setdefault(chunk.entity_path, []).extend(
            (when, value[0]) for when, value in zip(times, values) if value is not None
        )
    return (
        {entity: tuple(np.array(column) for column in zip(*sorted(samples))) for entity, samples in series.items()},
        entities,
        timelines,
    )


def test_main_job_recording_holds_every_exchange(main_jobs):
    first = main_jobs[0]
    assert first.process.returncode == 0, first.describe()
    _verify(first.rrd)
    scalars, entities, timelines = _recorded_scalars(first.rrd)
    assert "sim_time" in timelines
    for entity in (
        "/speed/omega",
        "/throttle",
        "/governor/sleeve",
        "/moments/drive",
        "/moments/resistance",
        "/moments/external",
        "/moments/net",
    ):
        assert entity in scalars, f"no scalars at {entity}; the recording has {sorted(entities)}"
    assert any(entity.startswith("/mechanism/") for entity in entities), sorted(entities)
    assert any(entity.startswith("/governor/drawing") for entity in entities), sorted(entities)
    csv = np.genfromtxt(first.csv, delimiter=",", names=True)
    times, omega = scalars["/speed/omega"]
    assert times.size == csv.size == 1001
    np.testing.assert_array_equal(times, [to_nanoseconds(t) for t in csv["t"]])
    np.testing.assert_array_equal(omega, csv["omega"])
    np.testing.assert_array_equal(scalars["/throttle"][1], csv["throttle"])
    np.testing.assert_array_equal(scalars["/governor/sleeve"][1], 1e3 * csv["sleeve"])  # in mm
    np.testing.assert_array_equal(scalars["/moments/external"][1], csv["M_external"])


def _bag_messages(folder: Path) -> dict[str, list[tuple[int, bytes]]]:
    """A rosbag2 folder's messages by topic: (log time [ns], CDR bytes), read with the mcap library."""
    from mcap.reader import make_reader

    information = yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    topics: dict[str, list[tuple[int, bytes]]] = {}
    for relative in information["relative_file_paths"]:
        with open(folder / relative, "rb") as stream:
            for _, channel, message in make_reader(stream).iter_messages():
                topics.setdefault(channel.topic, []).append((message.log_time, bytes(message.data)))
    return topics


def test_main_job_bag_holds_what_simulate_writes(main_jobs, tmp_path, capsys):
    first = main_jobs[0]
    assert first.process.returncode == 0, first.describe()
    bag = tmp_path / "in_process_bag"
    code, _, _ = run_cli(
        capsys, "simulate", *_short_engine_arguments(), "--exchange-step", "1e-3", "--bag", str(bag), "--quiet"
    )
    assert code == 0
    recorded, expected = _bag_messages(first.rrd.parent.parent / "first_bag"), _bag_messages(bag)
    assert set(recorded) == {
        "/joint_states",
        "/throttle",
        "/load_torque_stamped",
        "/governor/state",
        "/machine/moments",
        "/clock",
        "/diagnostics",
    }
    assert len(recorded["/joint_states"]) == 1001
    assert recorded == expected, "the ROS run's bag differs from simulate --bag"


def test_main_job_interrupted_keeps_a_valid_recording(tmp_path, processes, probe, domain_id):
    job = MainJob(processes, tmp_path, ["engine_direct"], "interrupted", domain_id)  # the whole 16 s scenario
    listener = RunListener(probe, governed=False, diagnostics_publishers=0, describe=job.describe)

    def running(after: float) -> bool:
        return (
            any(float(values["sim_time"]) >= after for _, _, values in listener.statuses())
            and job.rrd.exists()
            and job.rrd.stat().st_size > 0
        )

    def recorded(exchanges: int) -> bool:  # (once flaky: a Ctrl-C before the recorder had a complete exchange)
        return any(int(values["recorded_exchanges"]) >= exchanges for _, _, values in listener.statuses("/recorder"))

    probe.spin_until(lambda: running(0.5), "the main job running past 0.5 s", describe=job.describe)
    probe.spin_until(
        lambda: recorded(2), "the recorder's diagnostics counting 2 complete exchanges", describe=job.describe
    )
    size = job.rrd.stat().st_size
    probe.spin_until(lambda: job.rrd.stat().st_size > size, "the recording growing", describe=job.describe)
    assert job.process.poll() is None, job.describe()
    job.process.send_signal(signal.SIGINT)  # as Ctrl-C in a terminal (the nodes are in sessions of their own)
    code = processes.wait(job.process, 4 * WAIT)
    _verify(job.rrd)
    summary = json.loads(job.json.read_text())
    assert summary["status"] == "interrupted" and summary["message"].startswith("the recording stops at"), summary
    assert 0.0 < summary["t_end"] < 16.0 and f"open the recording with: {viewer_command(job.rrd)}" in job.log
    csv = np.genfromtxt(job.csv, delimiter=",", names=True)
    assert csv.size == summary["samples"] >= 2
    scalars, _, _ = _recorded_scalars(job.rrd)
    times, omega = scalars["/speed/omega"]
    assert times.size >= csv.size  # the recording may hold a sample or two more than the complete rows
    np.testing.assert_array_equal(omega[: csv.size], csv["omega"])
    # what was run is the co-simulation of the scene: its start, in process
    prefix = csv[csv["t"] <= 0.3]
    model = build_model(load_scene("engine_direct", ["scenario.duration=0.3", "scenario.load_events=[]"]))
    run = cosimulate(model, DEFAULT_EXCHANGE_STEP, coupling=DEFAULT_COUPLING)  # run's defaults
    np.testing.assert_array_equal(prefix["omega"], run.states[1, : prefix.size])
    np.testing.assert_array_equal(prefix["throttle"], run.throttle[: prefix.size])
    assert code == 130 and "Traceback" not in without_rclpy_noise(job.log + job.node_log), job.describe()
    assert "failed" not in job.log, job.describe()  # every node stopped on the interrupt, none was killed
    listing = subprocess.run(["ps", "-ww", "-eo", "args"], capture_output=True, text=True, check=True).stdout
    assert not [line for line in listing.splitlines() if "mech_regulator.nodes" in line and str(tmp_path) in line]


INTERRUPTED_AFTER_THE_CHECK = """
import sys
import rclpy
from mech_regulator.nodes import recorder

original_ok = rclpy.ok
checks = []

def ok_then_interrupted(*args, **kwargs):  # Ctrl-C right after the loop's third check of rclpy.ok()
    result = original_ok(*args, **kwargs)
    checks.append(result)
    if result and len(checks) == 3:
        rclpy.shutdown()  # what rclpy's SIGINT handler does
    return result

rclpy.ok = ok_then_interrupted
sys.exit(recorder.main())
"""


def test_ctrl_c_right_after_the_loop_check_is_a_normal_stop(tmp_path, processes):
    # (once a bug, about 1 interrupt of the main job in 6: a node ended with a traceback and exit 1)
    recorder = processes.start(
        [
            sys.executable,
            "-c",
            INTERRUPTED_AFTER_THE_CHECK,
            "--ros-args",
            "-p",
            "scene_file:=lathe",
            "-p",
            f"output:={tmp_path / 'lathe.rrd'}",
        ],
        "recorder",
    )
    code = processes.wait(recorder)
    output = processes.log(recorder)
    assert "recording to" in output, output  # it got as far as its loop
    assert code == 0 and "Traceback" not in without_rclpy_noise(output), output
    # no machine ever spoke: the summary says so, and there are no samples to write
    summary = json.loads((tmp_path / "lathe.json").read_text())
    assert (summary["status"], summary["samples"], summary["t_end"]) == ("interrupted", 0, 0.0), summary
    assert summary["message"] == "interrupted before the first complete exchange: nothing recorded yet", summary
    assert not (tmp_path / "lathe.csv").exists()


INTERRUPTED_IN_A_CONVERSION = """
import os, signal, sys, time
import rclpy
from mech_regulator.nodes import common, governor

original_ok, original_executor = rclpy.ok, common.EventsExecutor
state = {"context_still_up": False}

def ok(*args, **kwargs):  # rclpy shuts the context down on a thread of its own: not yet at the first look
    if state["context_still_up"]:
        state["context_still_up"] = False
        return True
    return original_ok(*args, **kwargs)

class InterruptedInTheThirdSpin:  # Ctrl-C while rclpy converts a message for a callback
    def __init__(self):
        self.executor, self.spins = original_executor(), 0

    def __getattr__(self, name):
        return getattr(self.executor, name)

    def spin_once(self, *args, **kwargs):
        self.spins += 1
        if self.spins == 3:
            try:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(5.0)
            except KeyboardInterrupt:
                print("interrupted in the third spin", flush=True)
                state["context_still_up"] = True
                raise RuntimeError("Unable to convert call argument '0' to Python object")  # as pybind11 does
        return self.executor.spin_once(*args, **kwargs)

rclpy.ok, common.EventsExecutor = ok, InterruptedInTheThirdSpin
sys.exit(governor.main())
"""


def test_ctrl_c_inside_a_call_into_rclpy_is_a_normal_stop(processes):
    # (once a flaky failure of the main job's interruption in CI: the governor ended with this traceback)
    node = processes.start(
        [sys.executable, "-c", INTERRUPTED_IN_A_CONVERSION, "--ros-args", "-p", "scene_file:=engine_direct"], "governor"
    )
    code = processes.wait(node)
    output = processes.log(node)
    assert "interrupted in the third spin" in output, output
    assert code == 0 and "Traceback" not in without_rclpy_noise(output), output


def without_rclpy_noise(output: str) -> str:
    """A log without what rclpy itself prints when a spin after shutdown fails to make its executor
    ("Exception ignored in: <function Executor.__del__ ...>" and its traceback: rclpy's, harmless)."""
    kept, skipping = [], False
    for line in output.splitlines():
        if line.startswith("Exception ignored in: <function Executor.__del__"):
            skipping = True
        elif skipping and not line.startswith((" ", "Traceback", "AttributeError")):
            skipping = False
        if not skipping:
            kept.append(line)
    return "\n".join(kept)


def test_ctrl_c_while_rclpy_starts_is_a_normal_stop(monkeypatch):
    """A node stopped while rclpy.init runs (the launcher stops the others when one refuses a second run on its
    domain, and a node still starting got the SIGINT inside rclpy's Context()): exit code 0, no traceback; the
    node's factory is never called."""
    from mech_regulator.nodes import common

    def interrupted_init(args=None):
        raise KeyboardInterrupt

    monkeypatch.setattr(common.rclpy, "init", interrupted_init)
    previous = signal.getsignal(signal.SIGINT)
    try:
        assert common.run(lambda: pytest.fail("a node built after the interrupt")) == 0
    finally:
        signal.signal(signal.SIGINT, previous)
