"""`simulate --bag`: a run as a rosbag2 recording (MCAP and metadata.yaml, docs/ros.md "Bags") written without ROS,
read back with the mcap library's ROS 2 decoder (not the project's code): the same values as the CSV."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from support import run_cli

SHORT_ENGINE = [
    "engine_direct",
    "--set",
    "scenario.duration=0.3",
    "--set",
    "scenario.load_events.0.time=0.1",
    "--set",
    "scenario.load_events.1.time=0.2",
    "--set",
    "solver.path=reference",
]
TOPICS = {
    "/joint_states": "sensor_msgs/msg/JointState",
    "/throttle": "sensor_msgs/msg/JointState",
    "/load_torque_stamped": "geometry_msgs/msg/WrenchStamped",
    "/governor/state": "sensor_msgs/msg/JointState",
    "/machine/moments": "sensor_msgs/msg/JointState",
    "/clock": "rosgraph_msgs/msg/Clock",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
}


def read_bag(folder: Path) -> tuple[dict, dict[str, list]]:
    """metadata.yaml's information and the messages by topic as (log time [ns], decoded message), decoded by
    mcap_ros2's DecoderFactory from the schemas in the file."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    information = yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    topics: dict[str, list] = {}
    for relative in information["relative_file_paths"]:
        with open(folder / relative, "rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            assert reader.get_header().profile == "ros2"
            for schema, channel, message, decoded in reader.iter_decoded_messages():
                assert (schema.encoding, channel.message_encoding) == ("ros2msg", "cdr")
                assert schema.name == TOPICS[channel.topic]
                topics.setdefault(channel.topic, []).append((message.log_time, decoded))
    return information, topics


def joint(messages: list, name: str, field: str) -> np.ndarray:
    """`field` of joint `name` in each JointState."""
    return np.array([getattr(message, field)[list(message.name).index(name)] for _, message in messages])


@pytest.mark.parametrize(
    "exchange, digits",
    [(["--exchange-step", "2e-3", "--coupling", "hold"], 17), ([], 12)],
    ids=["co-simulated", "monolithic"],
)
def test_simulate_bag_holds_the_csv_values(tmp_path, capsys, exchange, digits):
    """The CSV has 17 significant digits (every bit of a double) for a co-simulated run, 12 for a monolithic one."""
    csv_path, bag = tmp_path / "run.csv", tmp_path / "run_bag"
    code, out, _ = run_cli(
        capsys, "simulate", *SHORT_ENGINE, *exchange, "--out", str(csv_path), "--bag", str(bag), "--quiet"
    )
    assert code == 0 and f"wrote {bag}" in out
    csv = np.genfromtxt(csv_path, delimiter=",", names=True)
    information, topics = read_bag(bag)
    assert information["storage_identifier"] == "mcap" and information["relative_file_paths"] == ["run_bag_0.mcap"]
    listed = {
        item["topic_metadata"]["name"]: (item["topic_metadata"]["type"], item["message_count"])
        for item in information["topics_with_message_count"]
    }
    assert listed == {topic: (TOPICS[topic], len(messages)) for topic, messages in topics.items()}
    assert set(topics) == set(TOPICS)
    assert information["message_count"] == sum(len(messages) for messages in topics.values())
    assert information["duration"]["nanoseconds"] == round(csv["t"][-1] * 1e9)

    def same(actual, expected):
        np.testing.assert_allclose(actual, expected, rtol=0.0 if digits == 17 else 10.0 ** (1 - digits), atol=0.0)

    times = np.round(csv["t"] * 1e9).astype(np.int64)
    states = topics["/joint_states"]
    np.testing.assert_array_equal([when for when, _ in states], times)  # log times: simulation time
    np.testing.assert_array_equal(
        [message.header.stamp.sec * 10**9 + message.header.stamp.nanosec for _, message in states], times
    )
    same(joint(states, "crank", "position"), csv["phi"])
    same(joint(states, "crank", "velocity"), csv["omega"])
    same(joint(states, "slider", "position"), csv["x_slider"])
    same(joint(topics["/throttle"], "throttle", "position"), csv["throttle"])
    same([message.wrench.torque.z for _, message in topics["/load_torque_stamped"]], -csv["M_external"])
    assert {message.wrench.torque.z for _, message in topics["/load_torque_stamped"]} == {6.0, 8.0, 0.0}
    same(joint(topics["/governor/state"], "sleeve", "position"), csv["sleeve"])
    same(joint(topics["/governor/state"], "arm", "position"), csv["arm_angle"])
    moments = topics["/machine/moments"]
    same(joint(moments, "drive", "effort"), csv["M_drive"])
    same(joint(moments, "external", "effort"), csv["M_external"])
    np.testing.assert_array_equal(
        [message.clock.sec * 10**9 + message.clock.nanosec for _, message in topics["/clock"]], times
    )
    (start, _), (end, last) = topics["/diagnostics"]
    assert start == 0 and end == times[-1] and last.status[0].message == "complete"


def test_a_bag_folder_that_exists_is_refused_before_the_run(tmp_path, capsys):
    (tmp_path / "taken").mkdir()
    code, _, err = run_cli(capsys, "simulate", *SHORT_ENGINE, "--bag", str(tmp_path / "taken"), "--quiet")
    assert code == 2 and f"cannot write the bag '{tmp_path / 'taken'}': it exists" in err
    code, _, err = run_cli(capsys, "simulate", *SHORT_ENGINE, "--bag", str(tmp_path / "no" / "bag"), "--quiet")
    assert code == 2 and f"the folder '{tmp_path / 'no'}' does not exist" in err


def test_a_bag_in_a_folder_where_nothing_can_be_made_is_refused_before_the_run(capsys):
    """/proc (the kernel's) takes no new folder, not even root's: refused at once with exit 2, before the run."""
    code, out, err = run_cli(capsys, "simulate", *SHORT_ENGINE, "--bag", "/proc/bag", "--quiet")
    assert code == 2 and "cannot write the bag '/proc/bag': no folder can be made in '/proc'" in err
    assert "Traceback" not in err and out == ""
