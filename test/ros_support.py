"""Helpers for the tests of the ROS 2 layer: a private ROS domain per test, node processes that are
always stopped, and a test node (`Probe`) in the pytest process with its own rclpy Context.

Nothing here measures wall-clock time: every wait polls for a condition, with a generous deadline
that only turns a hang into a failure.
"""

from __future__ import annotations

import contextlib
import faulthandler
import itertools
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml

rclpy = pytest.importorskip("rclpy", reason="the ROS 2 tests need rclpy (pip install 'mech_regulator[ros]')")

from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.signals import SignalHandlerOptions  # noqa: E402

from mech_regulator.nodes.launch import (  # noqa: E402
    DOMAIN_IDS,
    FASTDDS_PROFILE_VARIABLE,
    claim_domain,
    domain_lock_descriptor,
    fastdds_profile,
    private_environment,
    wait_for_a_quiet_graph,
)

WAIT = 90.0  # [s] of wall time: the failure limit of every wait (never what a test measures)
CLOSE_LIMIT = 60.0  # [s] of wall time a test node's close may take before its process is ended (Probe.close)
ANSWER_WAIT = 10.0  # [s] of wall time before a service request that got no answer is sent again
STOP_WAIT = 30.0  # [s] a process gets to end after SIGINT before it is killed

# A test run takes consecutive domains (nodes.launch.DOMAIN_IDS) from a base derived from its pid, each claimed with
# the lock file `run` claims its own with (nodes.launch.claim_domain) and held until the test has ended (conftest's
# ros_domains_released), so that two test runs side by side (two pytest processes, two xdist workers) and `run`
# without --domain-id never share a domain.
_domains = itertools.count((os.getpid() * 37) % len(DOMAIN_IDS))

# What the test node listens with: reliable, deep enough never to drop a sample of a short run. State
# streams (joint_states, machine/moments, governor/state) are transient local: the test node gets what
# was published before its subscription matched. /diagnostics is volatile (as its publishers).
LISTEN_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=20000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
STATE_LISTEN_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=20000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
# What the test node publishes commands with (the nodes' COMMAND_QOS).
SEND_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=100,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

NANOSECONDS = 1_000_000_000

# The test nodes' participants (Probe, in the pytest process) announce themselves as the nodes' do, with the run's Fast
# DDS profile (nodes.launch.fastdds_profile: every 0.2 s): with Fast DDS's default (every 3 s), a node started after the
# probe named it only 0-1.75 s after its start (6 tries; 0-0.34 s with the profile), and an announcement lost costs
# 3 s, longer than a short run. Fast DDS reads the variable once, when the process's first participant is made: so
# here, on import, before any test makes one (a profile the user set is kept, as `run` keeps it).
os.environ.setdefault(FASTDDS_PROFILE_VARIABLE, str(fastdds_profile()))


def next_domain_id() -> int:
    """A ROS domain no other test of this run, nor any other test run or `run` on this machine, uses."""
    return claim_domain(next(_domains))


def ros_environment(domain_id: int) -> dict[str, str]:
    """The environment of processes on a private domain, as the main job's (nodes.launch.private_environment), with
    unbuffered output for the logs."""
    return dict(private_environment(domain_id), PYTHONUNBUFFERED="1")


def stamp_ns(stamp) -> int:
    """Whole nanoseconds of a builtin_interfaces/Time."""
    return stamp.sec * NANOSECONDS + stamp.nanosec


def batch_groups(message) -> list[tuple[int, dict[str, tuple[float, float, float]]]]:
    """A Batch message (nodes.common.Batch) group by group, for the tests that compare groups with different joints:
    (exchange time [ns], {joint: (position, velocity, effort)}), in order, the "stamp" joint among them. Unchecked:
    the recorder reads batches with nodes.common.batch_columns, which checks them."""
    groups: list[tuple[int, dict[str, tuple[float, float, float]]]] = []
    for name, *fields in zip(message.name, message.position, message.velocity, message.effort):
        if name == "stamp":
            groups.append((int(fields[0]), {}))
        groups[-1][1][name] = (fields[0], fields[1], fields[2])
    return groups


def diagnostic_values(status) -> dict[str, str]:
    """The KeyValues of a DiagnosticStatus as a dict."""
    return {item.key: item.value for item in status.values}


# -------------------------------------------------------------------------------------------------
# Processes


def _children(pid: int) -> list[int]:
    """The live descendants of a process (Linux /proc), found through their parent pids."""
    parents: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        parents.setdefault(int(fields[1]), []).append(int(entry.name))
    found, todo = [], [pid]
    while todo:
        for child in parents.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return found


def _start_time(pid: int) -> str | None:
    """A process's start time (field 22 of /proc/pid/stat), to tell it from a later one with its pid."""
    try:
        return (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[19]
    except (OSError, IndexError):
        return None


def _signal(pid: int, number: int) -> None:
    try:
        os.kill(pid, number)
    except ProcessLookupError:
        pass


class Processes:
    """The processes a test starts (each in a session of its own), stopped at the end of the test by
    `stop_all`: SIGINT to each and its descendants (the main job's nodes), then SIGKILL if they linger."""

    def __init__(self, folder: Path, environment: dict[str, str]):
        self.folder = folder
        self.environment = environment
        self.started: list[tuple[subprocess.Popen, Path]] = []

    def start(self, command: list[str], name: str, **kwargs) -> subprocess.Popen:
        """Start a command with the private environment; its output goes to <folder>/<name>.log. The process holds
        the lock on its domain that this one claimed (launch.domain_lock_descriptor), so that the domain stays
        claimed until it ends, also if this test process dies first (killed by a timeout: no fixture stops it)."""
        log_path = self.folder / f"{name}.log"
        domain = self.environment.get("ROS_DOMAIN_ID")
        lock = domain_lock_descriptor(int(domain)) if domain is not None else None
        # A process inherits an ignored SIGINT (pytest started as a background job of a script): it could
        # then not be stopped as by Ctrl-C. A handled signal is reset to its default by exec.
        ignored = signal.getsignal(signal.SIGINT) == signal.SIG_IGN
        if ignored:
            signal.signal(signal.SIGINT, signal.default_int_handler)
        try:
            with open(log_path, "w") as log:
                process = subprocess.Popen(
                    [str(part) for part in command],
                    env=self.environment,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    stdin=subprocess.DEVNULL,
                    start_new_session=True,
                    pass_fds=() if lock is None else (lock,),
                    cwd=kwargs.pop("cwd", self.folder),
                    **kwargs,
                )
        finally:
            if ignored:
                signal.signal(signal.SIGINT, signal.SIG_IGN)
        self.started.append((process, log_path))
        return process

    def node(self, module: str, parameters: dict, name: str | None = None) -> subprocess.Popen:
        """Start `python -m mech_regulator.nodes.<module>` with parameters (a dict, written as a
        ros__parameters file so that YAML gives the types)."""
        name = name or module
        parameter_file = self.folder / f"{name}.params.yaml"
        parameter_file.write_text(yaml.safe_dump({"/**": {"ros__parameters": parameters}}))
        return self.start(
            [sys.executable, "-m", f"mech_regulator.nodes.{module}", "--ros-args", "--params-file", parameter_file],
            name,
        )

    def log(self, process: subprocess.Popen) -> str:
        """What a process wrote so far."""
        for started, path in self.started:
            if started is process:
                return path.read_text(errors="replace")
        raise KeyError(process)

    def logs(self) -> str:
        """The last lines of every log, for failure messages."""
        parts = []
        for process, path in self.started:
            text = path.read_text(errors="replace") if path.exists() else ""
            parts.append(f"--- {path.name} (exit {process.poll()})\n" + "".join(text.splitlines(True)[-30:]))
        return "\n".join(parts)

    def wait(self, process: subprocess.Popen, timeout: float = WAIT) -> int:
        """Wait for a process to end; a hang is a failure (with the logs)."""
        try:
            return process.wait(timeout)
        except subprocess.TimeoutExpired:
            pytest.fail(f"a process did not end within {timeout} s: {process.args}\n{self.logs()}")

    def stop_all(self) -> None:
        """SIGINT every process still running and its descendants; SIGKILL what is left after STOP_WAIT."""
        targets: list[tuple[int, str | None]] = []
        for process, _ in self.started:
            if process.poll() is None:
                targets += [(pid, _start_time(pid)) for pid in _children(process.pid)]
        for process, _ in self.started:
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        deadline = time.monotonic() + STOP_WAIT
        for process, _ in self.started:
            try:
                process.wait(max(deadline - time.monotonic(), 0.1))
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        for pid, started in targets:  # the main job's nodes (sessions of their own): same pid, same process
            if started is not None and _start_time(pid) == started:
                _signal(pid, signal.SIGINT)
        while (
            any(started is not None and _start_time(pid) == started for pid, started in targets)
            and time.monotonic() < deadline
        ):
            time.sleep(0.1)
        for pid, started in targets:
            if started is not None and _start_time(pid) == started:
                _signal(pid, signal.SIGKILL)


@pytest.fixture
def domain_id() -> int:
    return next_domain_id()


@contextlib.contextmanager
def processes_on(folder: Path, domain: int):
    """Processes on a private domain, always stopped at the end."""
    started = Processes(folder, ros_environment(domain))
    try:
        yield started
    finally:
        started.stop_all()


@pytest.fixture
def processes(tmp_path, domain_id):
    """Processes of this test on its private domain."""
    with processes_on(tmp_path, domain_id) as started:
        yield started


# -------------------------------------------------------------------------------------------------
# The test node


class Probe:
    """A node in the pytest process on the test's domain, with an rclpy Context of its own. Spinning
    happens only inside `spin_until`, in this thread: callbacks never race the test's asserts."""

    def __init__(self, domain_id: int, name: str = "probe"):
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.others: list = []  # nodes of this participant besides `node` (other_node)

    def other_node(self, name: str):
        """A second node of this test node's participant (its Context), named `name`, spun and closed with it: what it
        subscribes to does not count as the test node's (a machine's `peers` gate names nodes)."""
        node = rclpy.create_node(name, context=self.context)
        self.executor.add_node(node)
        self.others.append(node)
        return node

    def spin_until(
        self,
        condition: Callable[[], object],
        what: str,
        timeout: float = WAIT,
        describe: Callable[[], str] = lambda: "",
    ):
        """Spin until condition() is true (returns its value); failing after timeout [s] of wall time."""
        deadline = time.monotonic() + timeout
        while True:
            value = condition()
            if value:
                return value
            if time.monotonic() > deadline:
                pytest.fail(f"timed out after {timeout} s waiting for {what}\n{describe()}")
            self.executor.spin_once(timeout_sec=0.05)

    def listen(
        self,
        message_type,
        topic: str,
        qos=LISTEN_QOS,
        callback: Callable | None = None,
        publishers: int = 0,
        describe=lambda: "",
        node=None,
    ) -> list:
        """Subscribe to topic (with `node`, default the test node); returns the list every received message is appended
        to (and passed to callback). With publishers > 0, first wait until that many publishers have matched."""
        received: list = []

        def on_message(message) -> None:
            received.append(message)
            if callback is not None:
                callback(message)

        subscription = (node or self.node).create_subscription(message_type, topic, on_message, qos)
        if publishers:
            self.spin_until(
                lambda: subscription.get_publisher_count() >= publishers,
                f"{publishers} publisher(s) of {topic}",
                describe=describe,
            )
        return received

    def call(self, service_type, name: str, request, describe=lambda: ""):
        """Call a service (waiting for it first) and return its response. A request not answered within
        ANSWER_WAIT is sent again until WAIT has passed: Fast DDS drops an answer whose client reader the server
        has not matched yet ("failed to send response (timeout)" in the server's log; seen under load), and the
        requests the tests send (parameter changes) may be repeated."""
        client = self.node.create_client(service_type, name)
        self.spin_until(client.service_is_ready, f"the service {name}", describe=describe)
        deadline = time.monotonic() + WAIT
        while True:
            future = client.call_async(request)
            answer_by = min(time.monotonic() + ANSWER_WAIT, deadline)
            self.spin_until(
                lambda: future.done() or time.monotonic() > answer_by, f"the answer of {name}", describe=describe
            )
            if future.done():
                break
            client.remove_pending_request(future)
            if time.monotonic() > deadline:
                pytest.fail(f"timed out after {WAIT} s waiting for the answer of {name}\n{describe()}")
        self.node.destroy_client(client)
        return future.result()

    def publisher(self, message_type, topic: str, subscribers: int = 1, qos=SEND_QOS, describe=lambda: ""):
        """A publisher on topic, once it has matched `subscribers` subscriptions (so nothing is lost)."""
        publisher = self.node.create_publisher(message_type, topic, qos)
        self.spin_until(
            lambda: publisher.get_subscription_count() >= subscribers,
            f"{subscribers} subscriber(s) of {topic}",
            describe=describe,
        )
        return publisher

    def close(self) -> None:
        """Destroy the node once the graph is quiet (nodes.launch.wait_for_a_quiet_graph: a Fast DDS deadlock). A
        participant Fast DDS has deadlocked all the same (seen once in a suite run: its receive thread, handling
        another participant's leaving under the discovery lock, waits for its event thread, which waits for that
        lock; eProsima/Fast-DDS#6502, open) cannot be destroyed, and the call that tries never returns: faulthandler's
        watchdog, a thread of its own outside Python that needs no GIL, prints every thread's stack and ends this process after
        CLOSE_LIMIT s, so that pytest-xdist reports the test's worker as crashed and goes on, where the suite hung
        until its time limit."""
        faulthandler.dump_traceback_later(CLOSE_LIMIT, exit=True)
        try:
            wait_for_a_quiet_graph(self.node, lambda timeout: self.executor.spin_once(timeout_sec=timeout))
            self.executor.shutdown()
            for node in self.others:
                node.destroy_node()
            self.node.destroy_node()
            rclpy.shutdown(context=self.context)
        finally:
            faulthandler.cancel_dump_traceback_later()


@contextlib.contextmanager
def probe_on(domain: int, name: str | None = None):
    """A test node on a domain (discovery on this machine only, as the nodes), named `name` (default probe_<domain>),
    closed at the end."""
    with pytest.MonkeyPatch.context() as patch:
        for key, value in ros_environment(domain).items():
            if key.startswith(("ROS_", "RMW_", "AMENT_")):
                patch.setenv(key, value)
        node = Probe(domain, name or f"probe_{domain}")
        try:
            yield node
        finally:
            node.close()


@pytest.fixture
def probe(domain_id):
    """The test node on the test's domain."""
    with probe_on(domain_id) as node:
        yield node


class RunListener:
    """What the machine (and governor) publish, as the test node receives it. `open_gate` subscribes
    to the machine's streams (joint_states, machine/moments) last: a lockstep machine waiting for the test node as a
    peer (subscribed to either) starts only then.

    The machine and the governor end by themselves after the run, and what they published goes with them: the test
    node gets it only if their writers have matched its subscriptions by then. So every subscription is made before
    an event that shows the writer's node knows it. Fast DDS's discovery hands a participant the other's
    subscriptions reliably and in the order they were made, and a writer matches a subscription as its node learns
    of it: the governor's /diagnostics reaching the test node show that the governor has taken the subscriptions made
    before it, governor/state among them; the machine starts only once it names the test node on joint_states,
    subscribed last, and once its writers have matched every subscription it knows (machine.matched_every_subscription),
    machine/moments among them, subscribed before by a second node of the test node's participant (which the machine's
    gate of named peers does not count)."""

    def __init__(self, probe: Probe, governed: bool, diagnostics_publishers: int = 1, describe=lambda: ""):
        from diagnostic_msgs.msg import DiagnosticArray
        from sensor_msgs.msg import JointState

        self.probe, self.describe = probe, describe
        self.JointState = JointState
        self.governor_messages = probe.listen(JointState, "governor/state", STATE_LISTEN_QOS) if governed else None
        self.diagnostics = probe.listen(
            DiagnosticArray, "/diagnostics", LISTEN_QOS, publishers=diagnostics_publishers, describe=describe
        )
        self.moment_messages: list = []
        self.joint_messages: list = []

    def open_gate(self, callback: Callable | None = None) -> None:
        """With a governor, wait for its diagnostics (it has then matched governor/state); subscribe to machine/moments
        with a second node of the participant, then to joint_states with the test node (`callback` gets each
        message): the machine waiting for the test node as a peer starts now."""
        if self.governor_messages is not None:
            self.probe.spin_until(
                lambda: self.statuses("/governor"), "the governor's diagnostics", describe=self.describe
            )
        streams = self.probe.other_node(f"{self.probe.node.get_name()}_streams")
        self.moment_messages = self.probe.listen(self.JointState, "machine/moments", STATE_LISTEN_QOS, node=streams)
        self.joint_messages = self.probe.listen(self.JointState, "joint_states", STATE_LISTEN_QOS, callback=callback)

    def statuses(self, suffix: str = "/machine") -> list[tuple[bytes, str, dict[str, str]]]:
        """(level, message, values) of every status received from the node whose name ends with suffix."""
        return [
            (status.level, status.message, diagnostic_values(status))
            for array in self.diagnostics
            for status in array.status
            if status.name.endswith(suffix)
        ]

    def finished(self) -> dict[str, str] | None:
        """The machine's last diagnostics (with finished_at_ns), once received."""
        ends = [values for _, _, values in self.statuses() if "finished_at_ns" in values]
        return ends[-1] if ends else None

    def final_status(self) -> tuple[bytes, str, dict[str, str]]:
        return [status for status in self.statuses() if "finished_at_ns" in status[2]][-1]

    @staticmethod
    def by_stamp(messages: list) -> dict[int, object]:
        return {stamp_ns(message.header.stamp): message for message in messages}

    @property
    def joints(self) -> dict[int, object]:
        return self.by_stamp([message for message in self.joint_messages if "crank" in message.name])

    @staticmethod
    def by_group(messages: list) -> dict[int, dict[str, tuple[float, float, float]]]:
        """Batched messages (nodes.common.Batch) by exchange time: {joint: (position, velocity, effort)}."""
        return {when: joints for message in messages for when, joints in batch_groups(message)}

    @property
    def moments(self) -> dict[int, dict[str, float]]:
        return {
            when: {name: effort for name, (_, _, effort) in joints.items()}
            for when, joints in self.by_group(self.moment_messages).items()
        }

    @property
    def governor(self) -> dict[int, dict[str, tuple[float, float, float]]]:
        return self.by_group(self.governor_messages)

    def wait_finished(self) -> int:
        """Spin until the machine said it finished and its (and the governor's) last samples are in;
        returns the end time [ns]."""
        finished = self.probe.spin_until(
            self.finished, "the machine's diagnostics saying it finished", describe=self.describe
        )
        end = int(finished["finished_at_ns"])
        self.probe.spin_until(
            lambda: not self.streams_without(end),
            f"the last samples of the run (stamped {end} ns)",
            describe=lambda: f"{self.stream_report(end)}\n{self.describe()}",
        )
        return end

    def received(self) -> dict[str, dict[int, object]]:
        """The exchange times [ns] received so far on each stream the end waits for (governor/state when governed)."""
        streams: dict[str, dict[int, object]] = {"joint_states": self.joints, "machine/moments": self.moments}
        if self.governor_messages is not None:
            streams["governor/state"] = self.governor
        return streams

    def streams_without(self, end: int) -> list[str]:
        """The streams whose sample at exchange time `end` [ns] has not been received."""
        return [topic for topic, samples in self.received().items() if end not in samples]

    def stream_report(self, end: int) -> str:
        """What each stream's wait for the end sample found, for a failure message: whether the end is in, how many
        messages and exchange times came and the newest exchange time, and how many publishers the test node's
        subscription has matched (0: the sender's writer never reached this node, its history lost with it)."""
        lines = []
        for topic, samples in self.received().items():
            matched = [
                subscription.get_publisher_count()
                for node in (self.probe.node, *self.probe.others)
                for subscription in node.subscriptions
                if subscription.topic_name.lstrip("/") == topic
            ]
            messages = {
                "joint_states": self.joint_messages,
                "machine/moments": self.moment_messages,
                "governor/state": self.governor_messages,
            }[topic]
            newest = f"{max(samples)} ns" if samples else "none"
            lines.append(
                f"{topic}: end {'in' if end in samples else 'MISSING'}; {len(messages or [])} messages, "
                f"{len(samples)} exchange times, the newest {newest}; publishers matched {matched}"
            )
        return "\n".join(lines)
