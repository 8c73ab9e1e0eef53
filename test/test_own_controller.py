"""Your own controller in the loop (`mech-regulator run SCENE --controller external`, docs/ros.md "Your own
controller"): the example PI controller (examples/pid_governor.py) against a machine of constant inertia, compared with
the same machine and controller written here as one ODE; the run's bag read back with the mcap library's ROS 2 decoder;
and controllers that never come, answer too slowly, die or answer with a wrong stamp: each run ends with exit code 1
naming the controller, no traceback, and what was computed up to there recorded."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from ros_support import LISTEN_QOS, WAIT, domain_id, probe_on, processes, stamp_ns  # noqa: F401 (fixtures)
from scipy.integrate import solve_ivp
from sensor_msgs.msg import JointState  # (after ros_support, which skips this module when rclpy is missing)
from support import run_cli

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "pid_governor.py"
FAULTY = ROOT / "test" / "faulty_controller.py"

# The machine, independently of the core: J omega' = u M0 (1 - omega / omega0) - c omega - L(t) (a linear motor
# scaled by the throttle u, viscous friction, the external load L stepping at LOAD_STEP_TIME).
INERTIA = 0.5  # [kg m^2]
STALL_TORQUE, NO_LOAD_SPEED = 200.0, 150.0  # [N m], [rad/s]
VISCOUS = 0.3  # [N m s/rad]
LOAD_BEFORE, LOAD_AFTER, LOAD_STEP_TIME = 6.0, 16.0, 0.3  # [N m], [N m], [s]
DURATION = 1.0  # [s]
EXCHANGE_STEP = 0.002  # [s]
# The example's defaults: set speed [rad/s], kp [1/(rad/s)], ki [1/rad], bias [-] (the throttle that holds 100 rad/s
# at LOAD_BEFORE: 0.54)
SET_SPEED, KP, KI, BIAS = 100.0, 0.05, 0.2, 0.54
# docs/ros.md, "Your own controller": the speed of this loop at h = 2 ms within this of the continuous one [rad/s]
DOCUMENTED_ERROR = 0.01
PEER_TIMEOUT = 5.0  # [s] of wall time, for the faulty controllers (faulty_controller.SLOW_ANSWER is longer)


def write_scene(folder: Path) -> Path:
    """The machine above as a scene file (no governor: the controller drives the bare machine)."""
    scene = {
        "name": "constant_inertia",
        "machine": {
            "inertia": INERTIA,
            "drive": {"type": "linear_motor", "stall_torque": STALL_TORQUE, "no_load_speed": NO_LOAD_SPEED},
            "loads": [{"type": "viscous", "coefficient": VISCOUS}],
        },
        "scenario": {
            "initial": {"omega": SET_SPEED},
            "duration": DURATION,
            "external_load": LOAD_BEFORE,
            "load_events": [{"time": LOAD_STEP_TIME, "torque": LOAD_AFTER}],
        },
        "solver": {"method": "DOP853", "rtol": 1e-9, "atol": 1e-11, "path": "reference"},
    }
    path = folder / "scene.yaml"
    path.write_text(yaml.safe_dump(scene, sort_keys=False))
    return path


def continuous_loop(times: np.ndarray) -> np.ndarray:
    """omega [rad/s] at `times` of the machine above under the continuous PI controller u = BIAS + KP e + KI z,
    z' = e = SET_SPEED - omega (scipy's DOP853, in two pieces at the load step)."""

    def right_hand_side(load):
        def derivatives(t, y):
            omega, integral = y
            error = SET_SPEED - omega
            throttle = BIAS + KP * error + KI * integral
            return [(throttle * STALL_TORQUE * (1.0 - omega / NO_LOAD_SPEED) - VISCOUS * omega - load) / INERTIA, error]

        return derivatives

    before = solve_ivp(
        right_hand_side(LOAD_BEFORE),
        (0.0, LOAD_STEP_TIME),
        [SET_SPEED, 0.0],
        method="DOP853",
        rtol=1e-11,
        atol=1e-12,
        dense_output=True,
    )
    after = solve_ivp(
        right_hand_side(LOAD_AFTER),
        (LOAD_STEP_TIME, DURATION),
        before.y[:, -1],
        method="DOP853",
        rtol=1e-11,
        atol=1e-12,
        dense_output=True,
    )
    return np.where(
        times < LOAD_STEP_TIME,
        before.sol(np.minimum(times, LOAD_STEP_TIME))[0],
        after.sol(np.maximum(times, LOAD_STEP_TIME))[0],
    )


class ExternalRun:
    """`mech-regulator run SCENE --controller external` with a bag, and the controller (`command`, or none)."""

    def __init__(self, processes, folder: Path, domain: int, controller: list | None, *options: str):
        self.processes = processes
        self.rrd = folder / "run.rrd"
        self.csv, self.json, self.bag = self.rrd.with_suffix(".csv"), self.rrd.with_suffix(".json"), folder / "bag"
        self.launcher = processes.start(
            [
                sys.executable,
                "-m",
                "mech_regulator",
                "run",
                write_scene(folder),
                "--controller",
                "external",
                "--exchange-step",
                EXCHANGE_STEP,
                "--coupling",
                "hold",
                "--domain-id",
                domain,
                "--out",
                self.rrd,
                "--bag",
                self.bag,
                "--quiet",
                *options,
            ],
            "launcher",
        )
        self.controller = processes.start([sys.executable, *controller], "controller") if controller else None

    def finish(self) -> int:
        """Wait for the run to end; its exit code."""
        return self.processes.wait(self.launcher, 4 * WAIT)

    @property
    def log(self) -> str:
        """The launcher's output and the nodes' log."""
        nodes = self.rrd.with_suffix(".log")
        return self.processes.log(self.launcher) + (nodes.read_text(errors="replace") if nodes.exists() else "")


def bag_messages(folder: Path) -> dict[str, list]:
    """The bag's messages by topic, decoded by the mcap library's ROS 2 decoder (not the project's code)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    information = yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert information["storage_identifier"] == "mcap"
    (relative,) = information["relative_file_paths"]
    topics: dict[str, list] = {}
    with open(folder / relative, "rb") as stream:
        for _, channel, message, decoded in make_reader(
            stream, decoder_factories=[DecoderFactory()]
        ).iter_decoded_messages():
            topics.setdefault(channel.topic, []).append((message.log_time, decoded))
    counts = {
        item["topic_metadata"]["name"]: item["message_count"] for item in information["topics_with_message_count"]
    }
    assert counts == {topic: len(messages) for topic, messages in topics.items()}, "metadata.yaml's counts"
    return topics


def test_the_example_controller_in_lockstep_follows_the_continuous_loop(tmp_path, processes, domain_id):
    run = ExternalRun(processes, tmp_path, domain_id, [EXAMPLE])
    assert run.finish() == 0, processes.logs()
    assert "Traceback" not in run.log, run.log
    assert "waiting for your controller: a node that subscribes joint_states" in run.log
    csv = np.genfromtxt(run.csv, delimiter=",", names=True)
    assert csv.size == round(DURATION / EXCHANGE_STEP) + 1
    assert 0.0 < csv["throttle"].min() and csv["throttle"].max() < 1.0, "the throttle saturated: not the PI's ODE"
    expected = continuous_loop(csv["t"])
    assert expected.min() < SET_SPEED - 1.0, "the load step should move the speed"
    print(f"max |omega - continuous loop| = {np.abs(csv['omega'] - expected).max():.3g} rad/s")
    np.testing.assert_allclose(csv["omega"], expected, rtol=0.0, atol=DOCUMENTED_ERROR)
    dip = SET_SPEED - csv["omega"].min()
    assert SET_SPEED - csv["omega"][-1] < 0.5 * dip, "the integral action should bring the speed back"

    topics = bag_messages(run.bag)
    times = [when for when, _ in topics["/joint_states"]]
    np.testing.assert_array_equal(times, np.round(csv["t"] * 1e9).astype(np.int64))
    omega = [message.velocity[list(message.name).index("crank")] for _, message in topics["/joint_states"]]
    np.testing.assert_array_equal(omega, csv["omega"])
    np.testing.assert_array_equal([message.position[0] for _, message in topics["/throttle"]], csv["throttle"])
    np.testing.assert_array_equal(
        [message.wrench.torque.z for _, message in topics["/load_torque_stamped"]], -csv["M_external"]
    )
    drive = [message.effort[list(message.name).index("drive")] for _, message in topics["/machine/moments"]]
    np.testing.assert_array_equal(drive, csv["M_drive"])
    assert [message.clock.sec * 10**9 + message.clock.nanosec for _, message in topics["/clock"]] == times
    assert topics["/diagnostics"][-1][1].status[0].message == "complete"
    assert "/governor/state" not in topics  # no governor in the loop
    np.testing.assert_array_equal(recorded_throttle(run.rrd), csv["throttle"])  # the recording shows it too


def recorded_throttle(rrd: Path) -> np.ndarray:
    """The scalars at /throttle of a Rerun recording, in time order."""
    from rerun.chunk import RrdReader

    samples = []
    for chunk in RrdReader(str(rrd)).stream().to_chunks():
        batch = chunk.to_record_batch()
        if chunk.entity_path == "/throttle" and "Scalars:scalars" in batch.schema.names:
            samples += [
                (when, value[0])
                for when, value in zip(
                    batch.column("sim_time").cast("int64").to_pylist(), batch.column("Scalars:scalars").to_pylist()
                )
                if value is not None
            ]
    return np.array([value for _, value in sorted(samples)])


def test_a_controller_that_never_comes_ends_the_run_naming_what_is_missing(tmp_path, processes, domain_id):
    run = ExternalRun(processes, tmp_path, domain_id, None, "--peer-timeout", str(PEER_TIMEOUT))
    assert run.finish() == 1, run.log
    assert "Traceback" not in run.log, run.log
    assert f"no controller: nothing published throttle within {PEER_TIMEOUT:g} s (parameter peer_timeout)" in run.log


@pytest.mark.parametrize("fault", ["slow", "die", "wrong_stamp"])
def test_a_controller_that_stops_answering_ends_the_run_loudly(tmp_path, processes, domain_id, fault):
    run = ExternalRun(processes, tmp_path, domain_id, [FAULTY, fault], "--peer-timeout", str(PEER_TIMEOUT))
    assert run.finish() == 1, run.log
    assert "Traceback" not in run.log, run.log
    launcher = processes.log(run.launcher)
    assert (
        "the machine node ended with exit code 1: controller pid_governor gave no throttle for t = 0.1 s within "
        f"{PEER_TIMEOUT:g} s" in launcher
    ), launcher
    assert ("its last throttle was stamped" in launcher) == (fault == "wrong_stamp"), launcher
    summary = json.loads(run.json.read_text())
    assert summary["status"] == "interrupted" and summary["t_end"] == pytest.approx(0.1 - EXCHANGE_STEP), summary
    csv = np.genfromtxt(run.csv, delimiter=",", names=True)
    assert csv["t"][-1] == summary["t_end"]  # what was computed up to the silence is kept


def test_a_second_throttle_publisher_leaves_the_run_disturbed(tmp_path, processes, domain_id):
    # the machine takes the throttle of the node that published it first (the controller, once it has answered) and
    # refuses a second one's, but which of the two is the user's controller it cannot tell (docs/ros.md, "Who may
    # speak"): the run's numbers may be a stranger's
    run = ExternalRun(processes, tmp_path, domain_id, [EXAMPLE], "--duration", "5")
    with probe_on(domain_id, "stranger") as stranger:
        states = stranger.listen(JointState, "joint_states", LISTEN_QOS)
        # matched to the machine while the run starts and plays its 5 s (its 1 s could be over before a participant
        # that joined after it had found the machine's subscription)
        throttle = stranger.publisher(JointState, "throttle", describe=lambda: run.log)
        stranger.spin_until(
            lambda: any(stamp_ns(message.header.stamp) > 0 for message in states),
            "the controller's first answer taken",
            describe=lambda: run.log,
        )
        throttle.publish(JointState(name=["throttle"], position=[1.0]))
        assert run.finish() == 1, run.log
    assert "Traceback" not in run.log, run.log
    summary = json.loads(run.json.read_text())
    assert summary["status"] == "disturbed" and summary["foreign"] == {"/stranger": {"throttle": 1}}, summary
    assert summary["disturbances"] == [
        "machine: throttle from /stranger (second publisher): the machine takes the throttle of the node that "
        "published it first and cannot tell which of the two is your controller"
    ], summary


@pytest.mark.parametrize(
    "options, expected",
    [
        (["--time-mode", "realtime"], "--controller external: only with --time-mode lockstep"),
        (["--peer-timeout", "0"], "--peer-timeout 0: expected 0.01 to 3600 s"),
    ],
)
def test_run_refuses_what_an_external_controller_cannot_have(tmp_path, capsys, options, expected):
    code, _, err = run_cli(
        capsys,
        "run",
        str(write_scene(tmp_path)),
        "--controller",
        "external",
        *options,
        "--out",
        str(tmp_path / "run.rrd"),
        "--quiet",
    )
    assert code == 2 and expected in err, err
    assert not (tmp_path / "run.log").exists()  # refused before any node started
