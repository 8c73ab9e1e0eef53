"""Your own controller in the loop: what the machine tells a controller the user starts in place of governor_node, and
what it says when that controller does not come or stops answering (docs/ros.md, "Your own controller"). Nothing here
imports rclpy: the command line and the launcher read it too."""

from __future__ import annotations

CONTROLLERS = ("governor", "external")  # what gives the machine its throttle: the scene's governor (governor_node) or
# a node the user starts
THROTTLE_TOPIC = "throttle"
GUIDE = "docs/ros.md, 'Your own controller'"


def governor_left_out(scene) -> list[str]:
    """The scene changes (KEY=VALUE, as --set) that leave a scene's governor out for an external controller: the
    governor, and the initial governor states the scenario sets (none when the scene has no governor)."""
    if scene.governor is None:
        return []
    return [
        "governor=null",
        *(
            f"scenario.initial.{key}=null"
            for key in ("sleeve", "servo")
            if getattr(scene.scenario.initial, key) is not None
        ),
    ]


def contract(peer_timeout: float) -> str:
    """The one line that says what the machine waits for from an external controller."""
    return (
        f"waiting for your controller: a node that subscribes joint_states (sensor_msgs/JointState, joint 'crank': "
        f"velocity omega [rad/s]) and answers each message with {THROTTLE_TOPIC} (sensor_msgs/JointState, joint "
        f"'throttle': position 0..1) stamped with the same header.stamp, reliable QoS; the machine waits for that "
        f"answer at every exchange time, at most {peer_timeout:g} s (parameter peer_timeout) ({GUIDE})"
    )


def absent(peer_timeout: float) -> str:
    """Why the run ends when no controller has come within peer_timeout [s]."""
    return (
        f"no controller: nothing published {THROTTLE_TOPIC} within {peer_timeout:g} s (parameter peer_timeout); "
        f"start yours on this ROS domain (e.g. python examples/pid_governor.py; {GUIDE})"
    )


def silent(names: list[str], time: float, peer_timeout: float, wrong_stamp: float | None) -> str:
    """Why the run ends when the controller (node names `names`: those that publish or published throttle) gave no
    throttle for the exchange time `time` [s] within peer_timeout [s]; `wrong_stamp` [s]: the stamp of the last
    throttle that answered no exchange time (None: none did)."""
    who = f"controller {', '.join(names)}" if names else "the controller"
    why = (
        f"; its last throttle was stamped {wrong_stamp:.9g} s: answer each joint_states with its own header.stamp"
        if wrong_stamp is not None
        else ""
    )
    return (
        f"{who} gave no {THROTTLE_TOPIC} for t = {time:.9g} s within {peer_timeout:g} s (parameter peer_timeout)"
        f"{why}; the run ends at t = {time:.9g} s, recorded up to there ({GUIDE})"
    )


def publisher_names(node, topic: str = THROTTLE_TOPIC) -> list[str]:
    """The names of the nodes that publish `topic` in `node`'s namespace, as the ROS graph lists them, sorted."""
    namespace = node.get_namespace()
    return sorted(
        {
            info.node_name
            for info in node.get_publishers_info_by_topic(topic)
            if info.node_namespace == namespace and info.node_name != node.get_name()
        }
    )
