"""Who may speak (nodes/trust.py Speakers) against a stand-in for a node's view of the ROS graph: no ROS node, no
domain. The graph names a publisher's node a moment after the publisher's first messages can arrive (its
participant announces its nodes on a topic of its own); a peer's first message is not refused for that."""

from types import SimpleNamespace

import pytest

pytest.importorskip("rclpy", reason="the ROS 2 tests need rclpy (pip install 'mech_regulator[ros]')")

from mech_regulator.nodes.trust import UNKNOWN_NODE, BadMessage, Speakers  # noqa: E402

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
    with pytest.raises(BadMessage, match="a publisher the graph does not name"):
        speakers.check("/diagnostics", sent_by(MACHINE_GID))
    assert graph.looks == 1
