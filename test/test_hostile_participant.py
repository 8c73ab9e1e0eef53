"""A second participant on a run's ROS domain: a mistyped `ros2 topic pub`, a second run on the same domain, a stale
or hostile node. Whatever it sends, the run either refuses it (the same CSV as a clean run, bit for bit, and the
refusal counted in its summary) or ends loudly (exit code not 0, a status and a reason): never a traceback, never a
silent `complete` with other numbers (docs/ros.md, "Who may speak").

The attacker is a test node (ros_support.Probe) in this process. One clean `run` is the reference of the module; the
attacks of an outsider that do not interfere with one another share one run; an attacker that takes a peer's name
(the only way past the check of who speaks: then the message's own checks refuse it) meets the node it attacks alone.
"""

from __future__ import annotations

import json
import math
import signal
import time

import pytest

# after ros_support, which skips this module when rclpy is missing
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from rclpy.duration import Duration
from ros_support import (  # noqa: F401 (fixtures)
    LISTEN_QOS,
    SEND_QOS,
    WAIT,
    Processes,
    RunListener,
    diagnostic_values,
    domain_id,
    probe_on,
    processes,
    stamp_ns,
)
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Header, String
from std_srvs.srv import Trigger
from test_ros_nodes import (
    BASE_LOAD,
    MainJob,
    assert_equals_cosimulation,
    constant_inertia_scene,
    machine_parameters,
    played_main_job,
    without_rclpy_noise,
)

from mech_regulator.nodes.common import STATE_QOS, stamp
from mech_regulator.solvers.cosim import cosimulate

RESEND = 0.3  # [s] of wall time between two sendings of a message whose refusal a test waits for
STRANGER_PERIOD = 0.05  # [s] of wall time between two rounds of a stranger's messages (20 Hz)
# engine_direct shortened to 1.5 s (6 -> 8 N m at 0.4 s, thrown off at 0.7 s), exchanged every 1 ms (some seconds of
# wall time: a second run has time to start while the first runs)
SCENE = [
    "engine_direct",
    "--set",
    "scenario.duration=1.5",
    "--set",
    "scenario.load_events.0.time=0.4",
    "--set",
    "scenario.load_events.1.time=0.7",
    "--coupling",
    "hold",
    "--exchange-step",
    "1e-3",
]


def batch(when_ns: int, joints: dict[str, tuple[float, float, float]]) -> JointState:
    """A recorder-only batch (common.Batch) of one exchange time with `joints` (name: position, velocity, effort)."""
    message = JointState(name=["stamp", *joints], position=[float(when_ns)], velocity=[0.0], effort=[math.nan])
    for position, velocity, effort in joints.values():
        message.position.append(position)
        message.velocity.append(velocity)
        message.effort.append(effort)
    message.header.stamp = stamp(when_ns)
    return message


def forged_finish() -> String:
    """machine/status saying the run finished at 1.28 s."""
    return String(
        data=json.dumps(
            {
                "state": "finished",
                "time": 1.28,
                "trial": 1,
                "status": "complete",
                "tripped_at": None,
                "finished_at_ns": 1_280_000_000,
            }
        )
    )


def garbage_diagnostics(node: str) -> DiagnosticArray:
    """/diagnostics claiming to be `node`'s, with a value that is no number."""
    status = DiagnosticStatus(
        level=DiagnosticStatus.OK,
        name=f"mech_regulator: /{node}",
        message="running",
        values=[KeyValue(key="sim_time", value="garbage"), KeyValue(key="tripped_at", value="garbage")],
    )
    return DiagnosticArray(status=[status])


def load(when_ns: int, torque: float, rate: float = 0.0, until: float = 0.0) -> WrenchStamped:
    """load_torque_stamped: `torque` [N m] from `when_ns`, its rate [N m/s], held up to `until` [s]."""
    message = WrenchStamped()
    message.header.stamp = stamp(when_ns)
    message.wrench.torque.z, message.wrench.force.z, message.wrench.force.x = torque, rate, until
    return message


def speed(when_ns: int, omega: float, **extra: tuple[float, float]) -> JointState:
    """joint_states with the crank at `omega` [rad/s] and `extra` joints (name: position, velocity)."""
    message = JointState(
        name=["crank", *extra],
        position=[0.0, *(value[0] for value in extra.values())],
        velocity=[omega, *(value[1] for value in extra.values())],
        effort=[0.0] * (1 + len(extra)),
    )
    message.header.stamp = stamp(when_ns)
    return message


def sim_times(arrays: list, suffix: str = "/machine") -> list[float]:
    """The sim_time values of the statuses of the node whose name ends with `suffix` (those that are numbers: an
    attacker's garbage is received too)."""
    times = []
    for array in arrays:
        for status in (status for status in array.status if status.name.endswith(suffix)):
            try:
                times.append(float(diagnostic_values(status).get("sim_time", "")))
            except ValueError:
                continue
    return [value for value in times if math.isfinite(value)]


def counted(arrays: list, suffix: str, keys: list[str]) -> bool:
    """Whether the latest diagnostics of the node whose name ends with `suffix` count each of `keys` at least once."""
    latest = [diagnostic_values(status) for array in arrays for status in array.status if status.name.endswith(suffix)]
    return bool(latest) and all(int(latest[-1].get(key, "0")) >= 1 for key in keys)


def until_counted(probe, publisher, message, arrays: list, suffix: str, key: str, describe) -> None:
    """Publish `message` (again every RESEND s of wall time) until the latest diagnostics of the node whose name ends
    with `suffix` count it under `key`: the node has then heard of the sender's name (a node learns the names of
    another's publishers a moment after their messages can reach it; it waits for them at most trust.NAME_WAIT, then
    refuses them as from no peer)."""
    sent = [-math.inf]

    def counted_yet() -> bool:
        if time.monotonic() - sent[0] > RESEND:
            publisher.publish(message)
            sent[0] = time.monotonic()
        return counted(arrays, suffix, [key])

    probe.spin_until(counted_yet, f"{suffix[1:]} counting {key}", describe=describe)


def assert_no_traceback(*logs: str) -> None:
    for log in logs:
        assert "Traceback" not in without_rclpy_noise(log), log[-3000:]


@pytest.fixture(scope="module")
def clean_run(tmp_path_factory) -> MainJob:
    """The reference: `run` on SCENE with nobody else on its domain."""
    job = played_main_job(tmp_path_factory.mktemp("clean"), SCENE, "clean")
    summary = json.loads(job.json.read_text())
    assert summary["status"] == "complete" and "refused" not in summary and "disturbances" not in summary, summary
    return job


# -------------------------------------------------------------------------------------------------
# An outsider: refused by who it is, whatever it says


def test_an_outsiders_messages_are_refused_and_its_service_calls_recorded(clean_run, tmp_path, processes, domain_id):
    with probe_on(domain_id) as probe:
        job = MainJob(processes, tmp_path, SCENE, "attacked", domain_id)
        statuses = probe.listen(DiagnosticArray, "/diagnostics", LISTEN_QOS, describe=job.describe)
        # the run paused from outside at 0.2 s (so that it is still there, whatever the attacks take); the clients
        # made early: the machine names a caller from the graph, which learns of a new client a moment after it
        pause, resume = (probe.node.create_client(Trigger, f"/machine/{name}") for name in ("pause", "resume"))
        probe.spin_until(
            lambda: pause.service_is_ready() and resume.service_is_ready(),
            "the machine's services",
            describe=job.describe,
        )
        paused = []

        def pause_at(message: JointState) -> None:
            if not paused and stamp_ns(message.header.stamp) >= 200_000_000:
                paused.append(pause.call_async(Trigger.Request()))

        probe.listen(JointState, "joint_states", LISTEN_QOS, callback=pause_at)
        probe.spin_until(lambda: paused and paused[0].done(), "the run paused at 0.2 s", describe=job.describe)
        assert paused[0].result().success
        # (matched to each node that subscribes: the attacks below reach every one; joint_states: the governor and
        # this test node; /diagnostics: this test node and the launcher too)
        subscribers = {
            "throttle": 1,
            "joint_states": 2,
            "load_request": 1,
            "machine/status": 3,
            "governor/events": 1,
            "/diagnostics": 3,
            "machine/moments": 1,
            "governor/state": 1,
            "load_torque_stamped": 1,
        }
        types = {
            "throttle": JointState,
            "joint_states": JointState,
            "load_request": Header,
            "machine/status": String,
            "governor/events": String,
            "/diagnostics": DiagnosticArray,
            "machine/moments": JointState,
            "governor/state": JointState,
            "load_torque_stamped": WrenchStamped,
        }
        durable = {"machine/status", "governor/events", "machine/moments", "governor/state"}  # (as their readers)
        publishers = {
            topic: probe.publisher(
                types[topic], topic, count, **({"qos": STATE_QOS} if topic in durable else {}), describe=job.describe
            )
            for topic, count in subscribers.items()
        }
        at = 1_000_000_000 * 1000  # [ns] 1000 s: far beyond the run
        attacks = [
            (
                "throttle",
                JointState(
                    name=["throttle"],
                    position=[0.0],
                    velocity=[math.nan],
                    effort=[math.nan],
                    header=speed(at, 0.0).header,
                ),
            ),  # a future-stamped throttle, closed
            ("joint_states", speed(0, 0.0)),  # stamped 0 mid-run: a reset, were it the machine's
            ("joint_states", speed(200_000_000, -50.0)),  # a second joint_states publisher, other numbers
            (
                "joint_states",
                JointState(name=["crank", "crank_midstep"], position=[0.0], velocity=[200.0, 1.0], effort=[0.0]),
            ),  # crank_midstep: arrays shorter than the names
            ("load_request", Header()),  # the load at 0 mid-run: the scenario would start again, were it the machine's
            ("machine/status", forged_finish()),
            ("machine/status", String(data="{not json")),
            ("governor/events", String(data="{not json")),
            ("/diagnostics", garbage_diagnostics("machine")),
            ("machine/moments", batch(100_000_000, {"drive": (math.nan, math.nan, 1.0)})),  # without crank
            ("governor/state", batch(100_000_000, {"arm": (0.1, 0.0, math.nan)})),  # without sleeve
            ("load_torque_stamped", load(0, 6.0, rate=1e300)),
            ("load_torque_stamped", load(at, 0.0, until=2000.0)),  # held, stamped 1000 s ahead
        ]
        for topic, message in attacks:
            publishers[topic].publish(message)
        for publisher in publishers.values():
            assert publisher.wait_for_all_acked(Duration(seconds=WAIT))
        assert job.process.poll() is None and max(sim_times(statuses), default=0.0) < 1.5, job.describe()
        resumed = resume.call_async(Trigger.Request())
        probe.spin_until(resumed.done, "the run resumed", describe=job.describe)
        assert resumed.result().success
        processes.wait(job.process, 4 * WAIT)
    assert job.process.returncode == 0, job.describe()
    assert_no_traceback(job.log, job.node_log)
    assert job.csv.read_bytes() == clean_run.csv.read_bytes(), "the attacked run's CSV differs from the clean run's"
    summary = json.loads(job.json.read_text())
    assert summary["status"] == "complete", summary
    from_whom = {
        "throttle": "governor",
        "joint_states": "machine",
        "load_request": "machine",
        "machine/status": "machine",
        "governor/events": "governor",
        "machine/moments": "machine",
        "governor/state": "governor",
        "load_torque_stamped": "scenario",
    }
    for topic, peer in from_whom.items():
        assert summary["refused"].get(topic, {}).get(f"not from {peer}", 0) >= 1, (topic, summary["refused"])
    assert "/diagnostics" in summary["refused"], summary["refused"]
    calls = [
        text for text in summary["disturbances"] if "/machine/pause called" in text or "/machine/resume called" in text
    ]
    # each call recorded, by the probe's name, or (when the machine's graph did not list the probe's client yet:
    # rclpy does not tell a service who called) as a caller the graph does not name
    assert len(calls) == 2 and all(
        f"probe_{domain_id}" in text or "by a node the graph does not name" in text for text in calls
    ), summary["disturbances"]
    assert "refused on throttle: " in job.log and "disturbance: machine: /machine/pause called" in job.log


def test_a_stranger_publishing_all_along_is_refused_counted_and_named(clean_run, tmp_path, processes, domain_id):
    # a node of another name on the run's domain, publishing at 20 Hz from before the nodes start to the run's end:
    # chatter, a fake ERROR status named "machine" (once passed over uncounted: not named "mech_regulator: ..."), a
    # forged finish (with a follower's history of one message it could take the place of the machine's: the run
    # never ended) and a speed
    with probe_on(domain_id, "stranger") as stranger:
        fake_error = DiagnosticArray(
            status=[DiagnosticStatus(level=DiagnosticStatus.ERROR, name="machine", message="overheated")]
        )
        rounds = [
            (stranger.node.create_publisher(message_type, topic, qos), message)
            for message_type, topic, qos, message in (
                (String, "/chatter", SEND_QOS, String(data="hello")),
                (DiagnosticArray, "/diagnostics", SEND_QOS, fake_error),
                (String, "machine/status", STATE_QOS, forged_finish()),
                (JointState, "joint_states", STATE_QOS, speed(0, 0.0)),
            )
        ]
        stranger.node.create_timer(
            STRANGER_PERIOD, lambda: [publisher.publish(message) for publisher, message in rounds]
        )
        job = MainJob(processes, tmp_path, SCENE, "strangered", domain_id)
        stranger.spin_until(lambda: job.process.poll() is not None, "the run's end", 4 * WAIT, job.describe)
    assert job.process.returncode == 0, job.describe()
    assert_no_traceback(job.log, job.node_log)
    assert job.csv.read_bytes() == clean_run.csv.read_bytes(), "the run's CSV differs from the clean run's"
    summary = json.loads(job.json.read_text())
    assert summary["status"] == "complete" and "disturbances" not in summary, summary
    everyone = "not from recorder or machine or governor or scenario"
    assert summary["refused"]["/diagnostics"][everyone] >= 1, summary["refused"]
    foreign = summary["foreign"]  # (the graph names the stranger long before the run: it started first)
    assert {"/diagnostics", "machine/status", "joint_states"} <= set(foreign["/stranger"]), foreign
    assert foreign["/stranger"]["/diagnostics"] == summary["refused"]["/diagnostics"][everyone], summary
    assert "refused from /stranger: " in job.log, job.log


def test_a_load_poked_from_outside_leaves_the_run_disturbed(tmp_path, processes, domain_id):
    # load_torque is open to anyone (the documented way to poke a run), but the run's numbers are then not the scene's
    with probe_on(domain_id, "stranger") as stranger:
        # in real time, 2 s at 10 ms: the poke, sent once the machine's subscription is matched, comes while the run
        # plays (a lockstep run of 0.3 s could end before the match was found; 1 ms is too short a step for real time)
        options = ["--duration", "2", "--time-mode", "realtime", "--exchange-step", "0.01"]
        job = MainJob(processes, tmp_path, [*SCENE, *options], "poked", domain_id)
        poke = stranger.publisher(Float64, "load_torque", describe=job.describe)  # (the machine subscribes at once)
        poke.publish(Float64(data=8.0))
        stranger.spin_until(lambda: job.process.poll() is not None, "the run's end", 4 * WAIT, job.describe)
    assert job.process.returncode == 1, job.describe()
    assert_no_traceback(job.log, job.node_log)
    summary = json.loads(job.json.read_text())
    assert summary["status"] == "disturbed", summary
    assert any(text.startswith("machine: load_torque from 'stranger'") for text in summary["disturbances"]), summary


# -------------------------------------------------------------------------------------------------
# An impostor with a peer's name: refused by what it says


def test_a_governor_refuses_what_its_machine_could_not_have_sent(tmp_path, processes, domain_id):
    scene, _ = constant_inertia_scene(tmp_path)
    governor = processes.node("governor", {"scene_file": str(scene), "coupling": "waveform"})
    with probe_on(domain_id, "machine") as machine, probe_on(domain_id, "machine") as second:
        statuses = machine.listen(DiagnosticArray, "/diagnostics", LISTEN_QOS, publishers=1, describe=processes.logs)
        answers = machine.listen(JointState, "throttle", LISTEN_QOS, publishers=1, describe=processes.logs)
        speeds = machine.publisher(JointState, "joint_states", describe=processes.logs)
        status = machine.publisher(String, "machine/status", qos=STATE_QOS, describe=processes.logs)
        until_counted(
            machine,
            status,
            String(data="{not json"),
            statuses,
            "/governor",
            "refused: machine/status: bad JSON",
            processes.logs,
        )  # (the governor knows the name now)
        speeds.publish(speed(0, 100.0))  # the first publisher named machine: pinned
        machine.spin_until(lambda: answers, "the governor's answer", describe=processes.logs)
        attacks = [
            JointState(name=["crank", "crank_midstep"], position=[0.0], velocity=[100.0], effort=[0.0]),
            speed(2_000_000, math.nan),
            speed(2_000_000, 100.0, crank_midstep=(math.nan, math.inf)),
        ]
        for message in attacks:
            speeds.publish(message)
        status.publish(String(data=json.dumps({"state": "finished", "time": "soon", "trial": 1})))
        intruder = second.publisher(JointState, "joint_states", describe=processes.logs)
        intruder.publish(speed(4_000_000, -100.0))  # a second node named machine
        for publisher in (speeds, status, intruder):
            assert publisher.wait_for_all_acked(Duration(seconds=WAIT))
        speeds.publish(speed(2_000_000, 100.0))  # still answered: nothing above reached its state
        machine.spin_until(lambda: len(answers) == 2, "the governor's second answer", describe=processes.logs)
        keys = [
            "refused: joint_states: array lengths",
            "refused: joint_states: not finite",
            "refused: machine/status: bad fields",
        ]
        machine.spin_until(
            lambda: counted(statuses, "/governor", keys),
            f"the governor's diagnostics counting {keys}",
            describe=processes.logs,
        )
        latest = [
            diagnostic_values(item) for array in statuses for item in array.status if item.name.endswith("/governor")
        ][-1]
        assert latest["refused: joint_states: not finite"] == "2", latest
        # the intruder: a second publisher, or (its name not yet heard of) not from the machine
        machine.spin_until(
            lambda: (
                counted(statuses, "/governor", ["refused: joint_states: second publisher"])
                or counted(statuses, "/governor", ["refused: joint_states: not from machine"])
            ),
            "the governor counting the intruder",
            describe=processes.logs,
        )
        assert governor.poll() is None, processes.logs()
        assert stamp_ns(answers[1].header.stamp) == 2_000_000
    assert_no_traceback(processes.log(governor))


def test_a_recorder_refuses_what_its_peers_could_not_have_sent(tmp_path, processes, domain_id):
    scene, _ = constant_inertia_scene(tmp_path)
    output = tmp_path / "recorded.rrd"
    recorder = processes.node("recorder", {"scene_file": str(scene), "output": str(output)})
    with probe_on(domain_id, "machine") as machine, probe_on(domain_id, "governor") as governor:
        recorded = machine.listen(DiagnosticArray, "/diagnostics", LISTEN_QOS, publishers=1, describe=processes.logs)
        states = governor.publisher(JointState, "governor/state", qos=STATE_QOS, describe=processes.logs)
        events = governor.publisher(String, "governor/events", qos=STATE_QOS, describe=processes.logs)
        moments = machine.publisher(
            JointState, "machine/moments", qos=STATE_QOS, describe=processes.logs
        )  # (once the governor's
        # state has matched: subscribe_to_the_machine)
        status = machine.publisher(String, "machine/status", qos=STATE_QOS, describe=processes.logs)
        diagnostics = machine.publisher(DiagnosticArray, "/diagnostics", subscribers=2, describe=processes.logs)
        until_counted(
            machine,
            events,
            String(data="{not json"),
            recorded,
            "/recorder",
            "refused: governor/events: bad JSON",
            processes.logs,
        )  # (names heard of: see until_counted)
        until_counted(
            machine,
            status,
            String(data="[1, 2"),
            recorded,
            "/recorder",
            "refused: machine/status: bad JSON",
            processes.logs,
        )
        moments.publish(batch(0, {"drive": (math.nan, math.nan, 1.0)}))  # without crank
        states.publish(batch(0, {"arm": (0.1, 0.0, math.nan)}))  # without sleeve
        diagnostics.publish(garbage_diagnostics("machine"))
        for publisher in (states, moments, diagnostics):
            assert publisher.wait_for_all_acked(Duration(seconds=WAIT))
        keys = [
            "refused: machine/moments: missing joint",
            "refused: governor/state: missing joint",
            "refused: /diagnostics: bad value",
        ]
        machine.spin_until(
            lambda: counted(recorded, "/recorder", keys), f"the recorder counting {keys}", describe=processes.logs
        )
        recorder.send_signal(signal.SIGINT)
        code = processes.wait(recorder)
    assert code == 0, processes.logs()
    assert_no_traceback(processes.log(recorder))
    summary = json.loads(output.with_suffix(".json").read_text())
    assert summary["status"] == "interrupted" and summary["samples"] == 0, summary
    for topic, reason in (
        ("machine/moments", "missing joint"),
        ("governor/state", "missing joint"),
        ("governor/events", "bad JSON"),
        ("/diagnostics", "bad value"),
        ("machine/status", "bad JSON"),
    ):
        assert summary["refused"][topic][reason] >= 1, summary


def test_a_machine_refuses_loads_its_scenario_could_not_have_sent(tmp_path, processes, domain_id):
    scene, model = constant_inertia_scene(tmp_path, duration=0.1)
    processes.node("machine", machine_parameters(scene, peers=["governor", "scenario"]))
    processes.node("governor", {"scene_file": str(scene), "coupling": "hold"})
    with probe_on(domain_id, "scenario") as scenario:
        loads = scenario.publisher(WrenchStamped, "load_torque_stamped", describe=processes.logs)
        listener = RunListener(scenario, governed=True, diagnostics_publishers=2, describe=processes.logs)
        attacked: list[int] = []

        def answer(message: JointState) -> None:  # the scene's constant load at every exchange time
            when = stamp_ns(message.header.stamp)
            if when >= 50_000_000 and not attacked:
                loads.publish(load(when, BASE_LOAD, rate=1e300))  # a finite rate that no step can ramp
                loads.publish(load(when + 1_000_000_000_000, 0.0, until=2000.0))  # held, 1000 s ahead
                attacked.append(when)
            loads.publish(load(when, BASE_LOAD))

        listener.open_gate(answer)
        end = listener.wait_finished()
        level, _, values = listener.final_status()
    assert attacked and level == DiagnosticStatus.WARN, (attacked, level, values)
    assert values["refused: load_torque_stamped: out of range"] == "1", values
    assert values["refused: load_torque_stamped: ahead of the machine"] == "1", values
    assert_equals_cosimulation(listener, end, model, cosimulate(model, 0.002))


# -------------------------------------------------------------------------------------------------
# A second run on the same domain; Ctrl-C before the nodes are up


def test_a_second_run_on_the_same_domain_is_refused_at_start(clean_run, tmp_path, processes, domain_id):
    """The second `run` on the first's --domain-id is refused by the run lock on the domain (nodes.launch.claim_run),
    before it starts a node, naming the domain and the first run's pid; the first run goes on undisturbed."""
    first = MainJob(processes, tmp_path, [*SCENE, "--duration", "30"], "first", domain_id)
    with probe_on(domain_id) as probe:
        listener = RunListener(probe, governed=False, diagnostics_publishers=0, describe=first.describe)
        probe.spin_until(
            lambda: any(float(values["sim_time"]) > 0.0 for _, _, values in listener.statuses()),
            "the first run under way",
            describe=first.describe,
        )
        second = MainJob(processes, tmp_path, SCENE, "second", domain_id)
        code = processes.wait(second.process, 4 * WAIT)
        assert code == 2, second.describe()
        refusal = f"another run on this machine is on ROS domain {domain_id} (pid {first.process.pid}; lock file "
        assert refusal in second.log and "running recorder" not in second.log, second.describe()
        assert first.process.poll() is None, first.describe()
        probe.spin_until(
            lambda: any(float(values["sim_time"]) > 1.5 for _, _, values in listener.statuses()),
            "the first run past the clean run's end",
            describe=first.describe,
        )
    first.process.send_signal(signal.SIGINT)
    assert processes.wait(first.process, 4 * WAIT) == 130, first.describe()
    assert_no_traceback(first.log, first.node_log, second.log, second.node_log)
    # the first run kept its own numbers: its rows up to the clean run's end are the clean run's
    clean = clean_run.csv.read_bytes().splitlines(keepends=True)
    assert first.csv.read_bytes().splitlines(keepends=True)[: len(clean)] == clean
    assert json.loads(first.json.read_text())["status"] == "interrupted"


def test_a_namesake_on_the_domain_ends_the_machine_at_start(tmp_path, processes, domain_id):
    """Another program's node named as the machine (not a `run`: no run lock) is seen in the graph at start: the
    machine ends with exit code 2 before its first exchange, naming it. (Its governor never comes, so the machine waits
    for its peers until it has seen the namesake, however late discovery finds it.)"""
    scene, _ = constant_inertia_scene(tmp_path)
    with probe_on(domain_id, "machine"):
        machine = processes.node("machine", machine_parameters(scene, peers=["governor"], peer_timeout=10 * WAIT))
        assert processes.wait(machine) == 2, processes.logs()
    log = processes.log(machine)
    assert "another node named 'machine' is on this ROS domain already" in log, log
    assert "run starts" not in log, log
    assert_no_traceback(log)


def test_ctrl_c_before_the_nodes_are_up_leaves_a_summary(tmp_path, monkeypatch, capsys):
    from mech_regulator import cli
    from mech_regulator.cli import main as cli_main

    def interrupted(argv):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli_main, "main", interrupted)  # Ctrl-C while the command or the scene loads
    output = tmp_path / "out" / "run.rrd"
    assert cli.run_command(["run", "engine_direct", "--out", str(output)]) == 130
    summary = json.loads(output.with_suffix(".json").read_text())
    assert (summary["status"], summary["samples"], summary["t_end"]) == ("interrupted", 0, 0.0), summary
    assert summary["message"] == "interrupted before the nodes were up: nothing was simulated"
    assert "nothing was simulated" in capsys.readouterr().err
    assert cli.run_command(["simulate", "engine_direct", "--out", str(tmp_path / "x.csv")]) == 130
    assert not (tmp_path / "x.json").exists()  # (only `run` has a summary to leave)


def test_ctrl_c_while_the_nodes_start_leaves_a_summary(tmp_path, processes):
    job = MainJob(processes, tmp_path, SCENE, "early")
    deadline = time.monotonic() + WAIT  # (turns a hang into a failure; nothing here is measured)
    while "running recorder" not in job.log:  # the launcher is forking the nodes: none is up yet
        assert job.process.poll() is None and time.monotonic() < deadline, job.describe()
        time.sleep(0.05)
    job.process.send_signal(signal.SIGINT)
    assert processes.wait(job.process, 4 * WAIT) == 130, job.describe()
    assert_no_traceback(job.log, job.node_log)
    summary = json.loads(job.json.read_text())
    assert summary["status"] == "interrupted", summary


# -------------------------------------------------------------------------------------------------
# What a run cannot refuse: a lost peer


def test_a_run_that_lost_a_peer_does_not_end_complete(tmp_path, processes, domain_id):
    # the scenario's first answer holds the load up to the load event at 1.5 s: killed then, it is missed there
    scene, _ = constant_inertia_scene(tmp_path, duration=2.0, load_events=[{"time": 1.5, "torque": 8.0}])
    output = tmp_path / "lost.rrd"
    recorder = processes.node(
        "recorder", {"scene_file": str(scene), "output": str(output), "coupling": "hold", "exchange_step": 0.002}
    )
    governor = processes.node("governor", {"scene_file": str(scene), "coupling": "hold"})
    scenario = processes.node("scenario", {"scene_file": str(scene)})
    with probe_on(domain_id) as probe:
        probe.spin_until(
            lambda: (
                probe.node.count_subscribers("joint_states") >= 1  # the governor; the scenario asks on load_request
                and probe.node.count_subscribers("load_request") >= 1
                and probe.node.count_subscribers("machine/moments") >= 1
            ),
            "the peers listening",
            describe=processes.logs,
        )  # (then the machine's short peer_timeout is for the run only)
        answers = probe.listen(WrenchStamped, "load_torque_stamped", LISTEN_QOS, publishers=1, describe=processes.logs)
        # the scenario's answers are volatile: its first is seen only if its publisher has matched this node's reader
        # before it. A participant learns of another's subscriptions in the order they were made, so the scenario's
        # diagnostics reaching a later subscription of this node mean that it has matched this one
        diagnostics = probe.listen(DiagnosticArray, "/diagnostics", LISTEN_QOS)
        probe.spin_until(
            lambda: any(status.name.endswith("/scenario") for array in diagnostics for status in array.status),
            "the scenario's diagnostics",
            describe=processes.logs,
        )
        machine = processes.node(
            "machine", machine_parameters(scene, peers=["governor", "scenario", "recorder"], peer_timeout=2.0)
        )
        probe.spin_until(lambda: answers, "the scenario's first answer", describe=processes.logs)
        scenario.kill()  # lost: no load at the event
        assert answers[0].wrench.force.x == 1.5 and stamp_ns(answers[0].header.stamp) == 0, answers
        for process in (machine, governor, recorder):
            assert processes.wait(process) == 0, processes.logs()
    assert_no_traceback(processes.log(machine), processes.log(recorder))
    summary = json.loads(output.with_suffix(".json").read_text())
    assert summary["status"] == "disturbed" and summary["t_end"] == 2.0, summary
    # (at the load event, or at once should the machine not have had the answer the test node saw before the kill)
    assert any(text.startswith("machine: no load for t = ") for text in summary["disturbances"]), summary[
        "disturbances"
    ]
    assert "no load for t = " in summary["message"], summary
