"""Who may speak (nodes/trust.py Speakers) against a stand-in for a node's view of the ROS graph: no ROS node, no
domain. The graph names a publisher's node a moment after the publisher's first messages can arrive (its
participant announces its nodes on a topic of its own); a peer's first message is not refused for that. What a node
refused, and from whom, as its diagnostics carry it to the recorder (Refusals, report_of)."""

from types import SimpleNamespace

import pytest

pytest.importorskip("rclpy", reason="the ROS 2 tests need rclpy (pip install 'mech_regulator[ros]')")

from mech_regulator.nodes.trust import (  # noqa: E402
    UNKNOWN_NODE,
    UNNAMED_SENDER,
    BadMessage,
    Refusals,
    Speakers,
    report_of,
)

MACHINE_GID = bytes(range(16))
OUTSIDER_GID = bytes(range(16, 32))


class LateGraph:
    """A node whose graph lists the publisher MACHINE_GID of node `machine` on every topic, its node unknown for the
    first `unknown_looks` looks (as a participant's announcement that comes after its first messages), and the
    publisher OUTSIDER_GID never with a node name; counts the looks."""

    def __init__(self, unknown_looks: int):
        self.unknown_looks, self.looks = unknown_looks, 0

    def get_namespace(self) -> str:
        return "/"

    def get_publishers_info_by_topic(self, topic: str) -> list[SimpleNamespace]:
        self.looks += 1
        machine = UNKNOWN_NODE if self.looks <= self.unknown_looks else "machine"
        return [
            SimpleNamespace(node_name=machine, node_namespace="/", endpoint_gid=list(MACHINE_GID)),
            SimpleNamespace(node_name=UNKNOWN_NODE, node_namespace="/", endpoint_gid=list(OUTSIDER_GID)),
        ]


def sent_by(gid: bytes) -> dict:
    """The message info rclpy hands a callback, of a message from publisher `gid`."""
    return {"publisher_gid": {"data": gid}}


def test_a_peer_s_first_message_waits_for_the_graph_to_name_its_publisher():
    # (once a flaky failure: the recorder refused the machine's first /diagnostics as "not from recorder or machine or
    # governor or scenario", its publisher not yet named by the graph)
    graph = LateGraph(unknown_looks=3)
    speakers = Speakers(graph, name_wait=60.0)  # the graph names it on the 4th look, long before that
    speakers.allow("/diagnostics", "recorder", "machine")
    assert speakers.check("/diagnostics", sent_by(MACHINE_GID)) == "machine"
    assert graph.looks == 4
    assert speakers.check("/diagnostics", sent_by(MACHINE_GID)) == "machine"  # known now: no look
    assert graph.looks == 4


def test_a_publisher_the_graph_never_names_is_refused_after_one_wait():
    graph = LateGraph(unknown_looks=0)
    speakers = Speakers(graph, name_wait=0.05)
    speakers.allow("/diagnostics", "recorder", "machine")
    with pytest.raises(BadMessage, match="a publisher the graph does not name") as refused:
        speakers.check("/diagnostics", sent_by(OUTSIDER_GID))
    assert refused.value.reason == "not from recorder or machine"
    waited = graph.looks
    with pytest.raises(BadMessage, match="a publisher the graph does not name"):
        speakers.check("/diagnostics", sent_by(OUTSIDER_GID))
    assert graph.looks == waited + 1  # its next message: one look, no second wait


def test_a_publisher_of_another_namespace_is_refused_without_waiting():
    graph = LateGraph(unknown_looks=0)
    graph.get_namespace = lambda: "/elsewhere"
    speakers = Speakers(graph, name_wait=60.0)
    speakers.allow("/diagnostics", "machine")
    with pytest.raises(BadMessage, match="sent by /machine") as refused:
        speakers.check("/diagnostics", sent_by(MACHINE_GID))
    assert graph.looks == 1
    assert refused.value.sender == "/machine"  # (the summary's `foreign` names it so)


class SilentLogger:
    """A node's logger that keeps what it is told (Refusals logs each refusal and disturbance)."""

    def __init__(self):
        self.lines: list[str] = []

    def warning(self, text: str, **throttle) -> None:
        self.lines.append(text)

    def error(self, text: str) -> None:
        self.lines.append(text)


def refusals_of_a_node() -> Refusals:
    logger = SilentLogger()
    return Refusals(SimpleNamespace(get_logger=lambda: logger))


def test_a_refusal_for_who_sent_it_is_counted_under_its_sender_too():
    refusals = refusals_of_a_node()
    speakers = Speakers(LateGraph(unknown_looks=0), name_wait=0.0)
    speakers.allow("/diagnostics", "recorder")
    for _ in range(3):
        with pytest.raises(BadMessage) as refused:
            speakers.check("/diagnostics", sent_by(MACHINE_GID))
        refusals.refuse("/diagnostics", refused.value.reason, refused.value.detail, refused.value.sender)
    refusals.refuse("throttle", "not finite", "throttle = nan")  # refused for what it says: no sender
    report = report_of({item.key: item.value for item in refusals.key_values()})
    assert report.counts == {"/diagnostics": {"not from recorder": 3}, "throttle": {"not finite": 1}}
    assert report.foreign == {"/machine": {"/diagnostics": 3}}
    assert not report.alters_results and report.disturbances == []


def test_a_refusal_that_cannot_keep_the_scene_s_numbers_alters_the_results():
    # an external controller's throttle: the machine takes the first publisher's and refuses a second one's, but
    # cannot tell which of the two is the user's controller
    refusals = refusals_of_a_node()
    refusals.alters_when_refused("throttle", "second publisher", "which is your controller the machine cannot tell")
    refusals.refuse("throttle", "not finite", "throttle = nan")
    assert not refusals.alters_results
    for _ in range(2):
        refusals.refuse("throttle", "second publisher", "a second publisher", "/stranger")
    report = report_of({item.key: item.value for item in refusals.key_values()})
    assert report.alters_results
    assert report.disturbances == [
        "throttle from /stranger (second publisher): which is your controller the machine cannot tell"
    ]


def test_a_recorded_stream_s_message_from_a_publisher_the_graph_never_named_alters_the_results():
    # the recorder once refused the governor's only batch of a short run, its publisher not named within NAME_WAIT
    # under load: the recording then lacks the governor's states, so the run cannot be `complete`
    refusals = refusals_of_a_node()
    refusals.alters_when_unnamed("governor/state", "its samples are then missing from the recording")
    speakers = Speakers(LateGraph(unknown_looks=0), name_wait=0.0)
    speakers.allow("governor/state", "governor")
    speakers.allow("/diagnostics", "governor")
    for topic, gid in (("governor/state", MACHINE_GID), ("/diagnostics", OUTSIDER_GID)):
        with pytest.raises(BadMessage) as refused:
            speakers.check(topic, sent_by(gid))
        refusals.refuse(topic, refused.value.reason, refused.value.detail, refused.value.sender)
    assert not refusals.alters_results  # a named stranger on it, an unnamed one on another topic: counted only
    with pytest.raises(BadMessage) as refused:
        speakers.check("governor/state", sent_by(OUTSIDER_GID))
    refusals.refuse("governor/state", refused.value.reason, refused.value.detail, refused.value.sender)
    report = report_of({item.key: item.value for item in refusals.key_values()})
    assert report.alters_results
    assert report.disturbances == [
        f"governor/state from {UNNAMED_SENDER} (not from governor): its samples are then missing from the recording"
    ]
