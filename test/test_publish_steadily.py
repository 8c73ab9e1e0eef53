"""A message the middleware refuses for a moment is published again (nodes.common.publish_steadily): on a loaded
machine Fast DDS's write sometimes fails at once and takes the same message a little later; the run's nodes must
not end there (docs/ros.md, "A message the middleware refuses")."""

from __future__ import annotations

import pytest

pytest.importorskip("rclpy", reason="the ROS 2 tests need rclpy (pip install 'mech_regulator[ros]')")

import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.impl.implementation_singleton import rclpy_implementation  # noqa: E402
from rclpy.publisher import Publisher  # noqa: E402
from rclpy.signals import SignalHandlerOptions  # noqa: E402
from ros_support import next_domain_id  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402

from mech_regulator.nodes import common  # noqa: E402
from mech_regulator.nodes.common import PeerError, SteadyNode, SteadyPublisher, publish_steadily  # noqa: E402


class RefusingSend:
    """A send that the middleware refuses `refusals` times (RCLError, as rclpy raises it), then takes."""

    def __init__(self, refusals: int):
        self.refusals = refusals
        self.tries = 0
        self.sent = 0

    def __call__(self) -> None:
        self.tries += 1
        if self.tries <= self.refusals:
            raise rclpy_implementation.RCLError("Failed to publish: cannot publish data")
        self.sent += 1


def test_a_message_refused_for_a_moment_is_sent_once_when_taken():
    send = RefusingSend(3)
    publish_steadily(send, "/joint_states", lambda: True)
    assert (send.tries, send.sent) == (4, 1)


def test_a_message_refused_past_the_limit_ends_the_node_naming_the_topic(monkeypatch):
    monkeypatch.setattr(common, "PUBLISH_RETRY_LIMIT", 0.02)
    send = RefusingSend(10**9)
    with pytest.raises(PeerError, match=r"refused every message on /joint_states for 0\.02 s.*cannot publish data"):
        publish_steadily(send, "/joint_states", lambda: True)
    assert send.sent == 0 and send.tries >= 2


def test_a_refusal_after_the_context_shut_down_is_raised_at_once():
    send = RefusingSend(1)
    with pytest.raises(rclpy_implementation.RCLError):
        publish_steadily(send, "/joint_states", lambda: False)
    assert send.tries == 1


def test_the_run_s_nodes_publish_steadily_and_a_refused_message_arrives_once(monkeypatch):
    context = Context()
    rclpy.init(context=context, domain_id=next_domain_id(), signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = SteadyNode("steady_probe", context=context)
        received: list[float] = []
        node.create_subscription(Float64, "probe", lambda message: received.append(message.data), 10)
        publisher = node.create_publisher(Float64, "probe", 10)
        assert isinstance(publisher, SteadyPublisher)
        plain_publish = Publisher.publish
        refusals = [2]

        def refused_twice(self, message):
            if refusals[0]:
                refusals[0] -= 1
                raise rclpy_implementation.RCLError("Failed to publish: cannot publish data")
            plain_publish(self, message)

        monkeypatch.setattr(Publisher, "publish", refused_twice)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        for _ in range(500):  # until the subscription has matched (discovery in this process)
            if publisher.get_subscription_count():
                break
            executor.spin_once(timeout_sec=0.01)
        publisher.publish(Float64(data=1.5))
        for _ in range(500):
            if received:
                break
            executor.spin_once(timeout_sec=0.01)
        executor.spin_once(timeout_sec=0.05)
        assert refusals == [0] and received == [1.5]
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
