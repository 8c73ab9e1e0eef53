"""What the nodes share: parameters with descriptors, QoS, stamps, the scene, the run state, batches, the messages
refilled at every exchange (JointMessage) and their samples read back, diagnostics, and the `main` wrapper that
turns a user's mistake into a message instead of a traceback.

The nodes are thin: every number they publish comes from the core (mech_regulator.solvers.cosim).
"""

from __future__ import annotations

import array
import contextlib
import math
import operator
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from typing import NamedTuple, TypeVar, cast

import numpy as np
import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType, SetParametersResult
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from mech_regulator.model import MachineModel, build_model
from mech_regulator.nodes.launch import PARTICIPANT_LEASE
from mech_regulator.nodes.trust import (
    LARGEST_STAMP,
    BadMessage,
    Refusals,
    RunStateMessage,
    Speakers,
    joint_fields,
    json_message,
    receive,
)
from mech_regulator.nodes.wire import FIELDS, JointStateCodec
from mech_regulator.scene import SceneError, load_scene
from mech_regulator.solvers import on_path_for_a_command
from mech_regulator.solvers.cosim import (
    COUPLINGS,
    DEFAULT_COUPLING,
    NANOSECONDS,
    Samples,
    cosimulation_refusal,
    seconds,
)

EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
IDLE_SPIN_SLICE = 0.1  # [s] of wall time per wait of a spin loop that only waits for callbacks
HISTORY_DEPTH = 2000  # state messages kept by each publisher for late-joining subscribers (the recorder)
BATCH_HISTORY_DEPTH = 200  # batched messages (class Batch) kept by each of their publishers (BATCH_QOS)
BATCH_PERIOD = 0.1  # [s] of wall time a recorder-only sample waits at most before it is sent (class Batch)
BATCH_SIZE = 50  # exchanges gathered at most in one recorder-only message (class Batch)
ACKED_EVERY = BATCH_HISTORY_DEPTH // 2  # batches a Batch sends between two waits for its readers' acknowledgements
ACK_PATIENCE = 10.0  # [s] of wall time of a Batch's wait for its readers before the node says it waits
ACK_CATCH_UP = PARTICIPANT_LEASE + ACK_PATIENCE  # [s] of wall time a Batch waits at most for its readers to
# acknowledge what it sent: longer than the lease, so that a reader stopped or starved is waited for as long as it is
# taken for there (wait_for_readers)
RECORDER_LEAD = 10_000  # exchanges the machine may run ahead of what its recorder has taken (recorder/progress)
PROGRESS_EVERY = 100  # exchanges between two looks of the machine at recorder/progress
ACK_WAIT = 5.0  # [s] of wall time a publisher waits for its subscribers' acknowledgements before its node ends
DESTROY_WAIT = 3.0  # [s] of wall time destroying a node may take before the process ends anyway (end_if_stuck)
TEARDOWN_ALARM = 5  # [s] of wall time after which SIGALRM ends a node whose destruction hangs holding the GIL
MATCH_WAIT = 1.0  # [s] of wall time a publisher waits at most to match what the graph lists (deliver_all)
MATCH_POLL = 0.01  # [s] between two looks at whether a publisher has matched the subscriptions the graph knows
PUBLISH_RETRY_LIMIT = 10.0  # [s] of wall time a message the middleware refuses is tried again (publish_steadily)
PUBLISH_RETRY_PAUSE = 0.001  # [s] of wall time before the first new try, doubled up to PUBLISH_RETRY_LONGEST
PUBLISH_RETRY_LONGEST = 0.05  # [s] of wall time between two tries at most
N = TypeVar("N", bound=Node)  # the kind of node `run` builds and hands to its work

# Commands (throttle, loads): reliable, only what arrives after subscribing counts.
COMMAND_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=100,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
# State streams (joint states, moments, governor state): reliable, and a subscriber that joins late (the
# recorder) still receives the last HISTORY_DEPTH messages. Volatile subscribers match them too.
STATE_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=HISTORY_DEPTH,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
# The batched state streams (machine/moments, governor/state: class Batch), as STATE_QOS but with a history counted in
# batches of up to BATCH_SIZE exchanges: 200 of them are 20 s of wall time at one batch every BATCH_PERIOD, up to
# 10 000 exchanges. Fast DDS keeps each message of a history in a buffer that stays as large as the largest message
# it has held, so a history's memory is its depth times the largest batch, reached slowly as batches of every size
# pass: at 2000 (up to 100 000 exchanges; 30 MB of full batches in the machine) it still grew after an hour
# (docs/speed.md, "Soak"). Subscribers read them with STATE_QOS: a subscriber's depth is its own memory.
BATCH_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=BATCH_HISTORY_DEPTH,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
# ... as the recorder reads them: every message kept until its callback takes it. A recorder slower than the machine
# (the walking beam's 16 columns at 44 times real time: 77 402 of 500 001 exchanges dropped from a reader 2000 batches
# deep over 10 000 s) then fills its reader, which holds back its acknowledgements until the callback takes messages,
# and each Batch waits for them (ACKED_EVERY): the run goes at the recorder's pace and drops nothing
# (docs/ros.md, "A recorder that falls behind").
RECORD_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_ALL,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
# The recorder's progress (recorder/progress): the machine reads the newest; a few are kept until it takes them, so
# that a stranger's messages on the topic (refused: trust.Speakers) do not at once push the recorder's out.
PROGRESS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
# The machine's run state (RunState): the latest only, kept for nodes that join late.
STATUS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
# ... as its followers read it: each reader keeps 100 messages until its callback takes them, so that another
# publisher's on the topic (refused: trust.Speakers) cannot push the machine's out first (with the publisher's depth
# of 1, a stranger's status every 50 ms could take the place of the machine's `finished`: the run never ended).
STATUS_READER_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=100,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)


class PeerError(Exception):
    """A peer node the run needs did not come (the machine then ends with exit code 1 and says which)."""


class OutputError(Exception):
    """An output a node writes could not be written (a full disk); the node said which and ends with exit code 1."""


def publish_steadily(send: Callable[[], None], topic: str, live: Callable[[], bool]) -> None:
    """Send a message with `send` (one publish of it), trying again while the middleware refuses it for a moment.
    On a loaded machine Fast DDS's write sometimes fails at once ("cannot publish data") and takes the same message
    some 50 ms later: the lathe through the nodes for 10 000 s at a load average of 7-12 met it one to four times a
    run, and the machine node ended there with a traceback (docs/ros.md, "A message the middleware refuses"). Each
    new try comes after a pause of PUBLISH_RETRY_PAUSE s, doubled up to PUBLISH_RETRY_LONGEST; refused for
    PUBLISH_RETRY_LIMIT s of wall time, PeerError naming the topic (the node ends with exit code 1). The message is
    sent once, unchanged and in its order: the run's numbers are the same, only its pace is not. When `live()` is
    false (the node's context shut down: Ctrl-C, the run's end) the error is raised at once, as before."""
    refused = 0
    deadline = time.monotonic() + PUBLISH_RETRY_LIMIT
    pause = PUBLISH_RETRY_PAUSE
    while True:
        try:
            send()
            return
        except rclpy_implementation.RCLError as error:
            if not live():
                raise
            if time.monotonic() >= deadline:
                raise PeerError(
                    f"the middleware refused every message on {topic} for {PUBLISH_RETRY_LIMIT:g} s of wall time "
                    f"({refused + 1} tries; the last: {error})"
                ) from error
        refused += 1
        time.sleep(pause)
        pause = min(2.0 * pause, PUBLISH_RETRY_LONGEST)


class SteadyPublisher(Publisher):
    """An rclpy Publisher whose publish tries again when the middleware refuses a message for a moment
    (publish_steadily). Made by SteadyNode.create_publisher."""

    context_ok: Callable[[], bool] = staticmethod(rclpy.ok)

    def publish(self, msg) -> None:
        """Publish `msg` (Publisher.publish), again while the middleware refuses it (publish_steadily)."""
        publish_steadily(lambda: super(SteadyPublisher, self).publish(msg), self.topic, self.context_ok)


class SteadyNode(Node):
    """An rclpy Node whose create_publisher makes SteadyPublishers, their publish tried again while the middleware
    refuses a message for a moment (publish_steadily). The base class of the run's nodes."""

    def create_publisher(self, *args, **kwargs) -> Publisher:
        """Node.create_publisher with publisher_class SteadyPublisher (unless given), its context this node's."""
        kwargs.setdefault("publisher_class", SteadyPublisher)
        publisher = super().create_publisher(*args, **kwargs)
        if isinstance(publisher, SteadyPublisher):
            publisher.context_ok = self.context.ok
        return publisher


def stamp(nanoseconds: int) -> Time:
    """A builtin_interfaces/Time from whole nanoseconds of simulation time."""
    return Time(sec=nanoseconds // NANOSECONDS, nanosec=nanoseconds % NANOSECONDS)


def nanoseconds(time: Time) -> int:
    """Whole nanoseconds of a builtin_interfaces/Time."""
    return time.sec * NANOSECONDS + time.nanosec


def float_parameter(
    node: Node, name: str, value: float, description: str, low: float, high: float, read_only: bool = False
) -> float:
    """Declare a double parameter with its range (ROS refuses values outside it) and return its value."""
    descriptor = ParameterDescriptor(
        name=name,
        type=ParameterType.PARAMETER_DOUBLE,
        description=description,
        read_only=read_only,
        floating_point_range=[FloatingPointRange(from_value=low, to_value=high)],
    )
    return node.declare_parameter(name, float(value), descriptor).value


def int_parameter(
    node: Node, name: str, value: int, description: str, low: int, high: int, read_only: bool = True
) -> int:
    """Declare an integer parameter with its range and return its value."""
    descriptor = ParameterDescriptor(
        name=name,
        type=ParameterType.PARAMETER_INTEGER,
        description=description,
        read_only=read_only,
        integer_range=[IntegerRange(from_value=low, to_value=high, step=1)],
    )
    return node.declare_parameter(name, int(value), descriptor).value


def text_parameter(
    node: Node, name: str, value: str, description: str, choices: tuple[str, ...] = (), read_only: bool = True
) -> str:
    """Declare a string parameter (choices: the allowed values, checked on every set) and return its value."""
    if choices:
        description += f" (one of: {', '.join(choices)})"
        node.add_on_set_parameters_callback(_choice_check(name, choices))
    descriptor = ParameterDescriptor(
        name=name,
        type=ParameterType.PARAMETER_STRING,
        description=description,
        read_only=read_only,
        additional_constraints=f"one of {', '.join(choices)}" if choices else "",
    )
    return node.declare_parameter(name, value, descriptor).value


def list_parameter(node: Node, name: str, value: list[str], description: str) -> list[str]:
    """Declare a read-only string-array parameter and return its value."""
    descriptor = ParameterDescriptor(
        name=name, type=ParameterType.PARAMETER_STRING_ARRAY, description=description, read_only=True
    )
    return list(node.declare_parameter(name, value, descriptor).value)


def peer_parameter(node: Node, role: str) -> str:
    """Declare the read-only parameter `<role>_node` (default: `role`): the name of the node, in this node's
    namespace, whose messages this node takes as the `role`'s (trust.Speakers; docs/ros.md, "Who may speak"), and
    return it."""
    return text_parameter(node, f"{role}_node", role, f"the node whose messages this node takes as the {role}'s")


def bool_parameter(node: Node, name: str, value: bool, description: str) -> bool:
    """Declare a read-only boolean parameter and return its value."""
    descriptor = ParameterDescriptor(
        name=name, type=ParameterType.PARAMETER_BOOL, description=description, read_only=True
    )
    return node.declare_parameter(name, value, descriptor).value


def _choice_check(name: str, choices: tuple[str, ...]) -> Callable:
    def check(parameters) -> SetParametersResult:
        for parameter in parameters:
            if parameter.name == name and parameter.value not in choices:
                return SetParametersResult(
                    successful=False, reason=f"{name} = {parameter.value!r}: expected one of {', '.join(choices)}"
                )
        return SetParametersResult(successful=True)

    return check


def coupling_parameter(node: Node) -> str:
    """Declare the `coupling` parameter (solvers.cosim.COUPLINGS: how machine and governor see each other over an
    exchange step; machine, governor and recorder must have the same) and return it."""
    return text_parameter(
        node,
        "coupling",
        DEFAULT_COUPLING,
        "how machine and governor see each other over an "
        "exchange step: hold, waveform (the governor follows the machine's speed over the step, the machine the "
        "throttle extrapolated from the governor's last answers) or corrected (each step predicted, "
        "then done again with the governor's own throttle over it)",
        COUPLINGS,
    )


def exchange_tolerance_parameter(node: Node) -> float | None:
    """Declare the `exchange_tolerance` parameter (the adaptive exchange step's tolerance [-], 0: the fixed step;
    solvers.cosim.ExchangeTimes; the machine decides the exchange times with it, the recorder's summary names it) and
    return it, None for 0."""
    tolerance = float_parameter(
        node,
        "exchange_tolerance",
        0.0,
        "the adaptive exchange step's tolerance on the corrected coupling's predictor miss, relative to the largest "
        "speed [-]; 0: the fixed exchange_step (docs/speed.md, 'The adaptive step tried again')",
        0.0,
        1.0,
        read_only=True,
    )
    return tolerance or None


class JointMessage:
    """A sensor_msgs/JointState built once and refilled at every exchange, for what a node publishes on the lockstep's
    critical path (the machine's joint_states, the governor's throttle), sent as its serialized bytes
    (wire.JointStateCodec): as long as the layout (the joints, and how many samples each signal has) is the exchange
    before's, `fill` writes the stamp and the numbers into the bytes in place (numpy views on them), no new message nor
    array, and rclpy publishes the bytes without converting the names; a new layout builds a new message. (A layout
    whose codec cannot be found is filled into the JointState itself and published as one.) A signal's samples over an
    exchange step (times [s], values; solvers.cosim.Samples) are entries of its joint, one per sample: the value in its
    field ('position' or 'velocity'), the sample's time in effort, NaN in the other field (`samples` reads them
    back)."""

    def __init__(self) -> None:
        self.layout: tuple | None = None
        self.joint_state = JointState()
        self.codec: JointStateCodec | None = None
        self.buffer = bytearray()  # the codec's template with this exchange's stamp and numbers
        self.message: JointState | bytes = self.joint_state  # what fill gave last, to publish
        self.arrays: dict[str, np.ndarray] = {}  # field -> a view on that field's numbers (in buffer, or joint_state)
        self.spans: list[tuple[str, slice]] = []  # each signal's field and its entries

    def fill(
        self,
        when: int,
        names: tuple[str, ...],
        positions: list[float],
        velocities: list[float],
        efforts: list[float],
        signals: tuple[tuple[str, str, Samples | None], ...] = (),
    ) -> JointState | bytes:
        """The message stamped `when` [ns] with the joints `names` (one entry each: positions, velocities, efforts),
        then the samples of each signal (joint, field, samples; none when samples is None): its bytes, or the
        JointState for a layout without a codec."""
        layout = (
            names,
            tuple((joint, field, 0 if found is None else len(found[0])) for joint, field, found in signals),
        )
        if layout != self.layout:
            self.build(layout)
        for field, values in zip(FIELDS, (positions, velocities, efforts)):
            self.arrays[field][: len(names)] = values
        for (field, span), (_, _, found) in zip(self.spans, signals):
            if found is not None:
                self.arrays[field][span] = found[1]
                self.arrays["effort"][span] = found[0]
        sec, nanosec = divmod(when, NANOSECONDS)
        if self.codec is None:
            self.joint_state.header.stamp.sec, self.joint_state.header.stamp.nanosec = sec, nanosec
            self.message = self.joint_state
        else:
            self.codec.write(self.buffer, sec, nanosec)
            self.message = bytes(self.buffer)
        return self.message

    def build(self, layout: tuple) -> None:
        """A new message for `layout` (fill's), the other field of each signal's entries NaN, and its codec."""
        names, counts = layout
        self.joint_state = JointState(name=[*names, *(joint for joint, _, count in counts for _ in range(count))])
        size = len(self.joint_state.name)
        for index, field in enumerate(FIELDS):  # distinct numbers, for the codec's check to find each in its place
            setattr(self.joint_state, field, array.array("d", np.arange(size) + 0.5 + index * size))
        self.codec = JointStateCodec.of(self.joint_state)
        if self.codec is None:
            self.arrays = {field: np.frombuffer(getattr(self.joint_state, field), dtype=np.float64) for field in FIELDS}
        else:
            self.buffer = bytearray(self.codec.template)
            self.arrays = self.codec.arrays(self.buffer)
        self.spans, start = [], len(names)
        for _, field, count in counts:
            span = slice(start, start + count)
            self.arrays["velocity" if field == "position" else "position"][span] = math.nan
            self.spans.append((field, span))
            start += count
        self.layout = layout


def samples(message, joint: str, field: str) -> tuple[list[float], list[float]] | None:
    """The samples (times [s], values) that JointMessage put in a sensor_msgs/JointState under `joint`; None when
    there are fewer than two, they are not finite or their times do not increase (or the message's `field` or
    efforts are not one per name). The checks run in C (map over the sample lists): a few dozen samples cost less
    so than through numpy's arrays."""
    names, values, times = message.name, getattr(message, field), message.effort
    if len(values) != len(names) or len(times) != len(names):
        return None
    entries = [index for index, name in enumerate(names) if name == joint]
    found_times, found_values = [times[index] for index in entries], [values[index] for index in entries]
    if (
        len(entries) < 2
        or not all(map(math.isfinite, found_times))
        or not all(map(math.isfinite, found_values))
        or not all(map(operator.lt, found_times, found_times[1:]))
    ):
        return None
    return found_times, found_values


def sent_samples(message, joint: str, field: str, low: float, high: float) -> tuple[list[float], list[float]] | None:
    """The samples of `joint` in a sensor_msgs/JointState (samples), None when it has none; trust.BadMessage when it
    has some that samples() cannot read (fewer than two, not finite, times not increasing) or values outside
    [low, high]."""
    if joint not in message.name:
        return None
    found = samples(message, joint, field)
    if found is None or not low <= min(found[1]) <= max(found[1]) <= high:
        raise BadMessage(
            "bad samples",
            f"the {joint} samples are not at least two finite values within [{low:g}, {high:g}] at increasing times",
        )
    return found


class Batch:
    """What only the recorder reads (the machine's states and moments, the governor's state), gathered over exchanges
    and sent as one sensor_msgs/JointState, off the lockstep's critical path: one group per exchange time, each opened
    by a joint "stamp" whose position is the exchange time in whole nanoseconds (exact as a double up to 2^53 ns,
    about 104 days) and whose velocity a wall-clock time [s] the sender gives (the machine: when it published that
    exchange's joint_states, time.monotonic, the host's clock its processes share; NaN when none), then that time's
    joints. The node sends it when due (send_when_due: BATCH_SIZE groups in, or the
    oldest BATCH_PERIOD s of wall time old, so the recorder still shows a live picture) at a moment it would
    otherwise wait, and at once (send) when the run ends, pauses or resets. A sender whose groups cost less computed
    together (the machine's moments: one vectorised call for the batch instead of one per exchange) defers them
    (defer) and gives `complete`, which adds them (add) when the batch goes out; a batch holds either kind only.
    Every ACKED_EVERY batches, and at the run's end (deliver), it first waits, at most ACK_CATCH_UP s of wall time,
    until its readers (the recorder) have acknowledged all it sent (wait_for_readers): a recorder held back (a loaded
    machine, a process stopped) slows the run instead of losing the batches its publisher's history of
    BATCH_HISTORY_DEPTH no longer holds when it asks for them again (docs/ros.md, "A recorder that falls behind")."""

    def __init__(self, publisher, say: Callable[[str], object], complete: Callable[[list], None] | None = None):
        self.publisher = publisher
        self.say = say  # a warning on the node's log (wait_for_readers)
        self.fields: tuple[list, list, list, list] = ([], [], [], [])  # names, positions, velocities, efforts
        self.groups = 0
        self.last = 0  # [ns] the newest exchange time waiting
        self.oldest_wall = 0.0  # [s] of wall time (time.monotonic) the oldest waiting group was added
        self.complete = complete
        self.deferred: list = []  # what `complete` turns into groups when the batch goes out
        self.unacknowledged = 0  # batches sent since the readers last acknowledged all (at most ACKED_EVERY)

    def add(
        self,
        when: int,
        names: list[str],
        positions: list[float],
        velocities: list[float],
        efforts: list[float],
        wall: float = math.nan,
    ) -> None:
        """Add the joints of exchange time `when` [ns] (a field left empty: NaN for each joint), with a wall-clock
        time [s] in the "stamp" joint's velocity."""
        if not self.groups and not self.deferred:
            self.oldest_wall = time.monotonic()
        missing = [math.nan] * len(names)
        columns: tuple[list[str] | list[float], ...] = (names, positions, velocities, efforts)
        for gathered, values, first in zip(self.fields, columns, ("stamp", float(when), wall, math.nan)):
            gathered.append(first)
            gathered.extend(values or missing)
        self.groups, self.last = self.groups + 1, when

    def defer(self, item) -> None:
        """Note what `complete` makes one group of when the batch goes out (counted as a waiting group)."""
        if not self.groups and not self.deferred:
            self.oldest_wall = time.monotonic()
        self.deferred.append(item)

    def send_when_due(self) -> None:
        """Send the waiting groups if BATCH_SIZE are in or the oldest waited BATCH_PERIOD s of wall time."""
        waiting = self.groups + len(self.deferred)
        if waiting >= BATCH_SIZE or waiting and time.monotonic() - self.oldest_wall >= BATCH_PERIOD:
            self.send()

    def send(self) -> None:
        """Publish the waiting groups (nothing when there are none; the deferred ones completed first), stamped with
        the newest exchange time."""
        if self.deferred:
            assert self.complete is not None, "only a sender that gave `complete` defers"
            deferred, self.deferred = self.deferred, []
            self.complete(deferred)
        if self.groups:
            names, positions, velocities, efforts = self.fields
            message = JointState(name=names, position=positions, velocity=velocities, effort=efforts)
            message.header.stamp = stamp(self.last)
            if self.unacknowledged >= ACKED_EVERY:  # the publisher keeps BATCH_HISTORY_DEPTH: none lost unsent
                wait_for_readers(self.publisher, self.say)
                self.unacknowledged = 0
            self.publisher.publish(message)
            self.unacknowledged += 1
            self.fields, self.groups = ([], [], [], []), 0

    def deliver(self) -> None:
        """Send the waiting groups, then wait (wait_for_readers) until the readers have acknowledged every batch: the
        end of a run, before the node ends and its publisher's history with it."""
        self.send()
        wait_for_readers(self.publisher, self.say)


def wait_for_readers(publisher, say: Callable[[str], object]) -> None:
    """Wait until every reader of `publisher` has acknowledged all it sent, at most ACK_CATCH_UP s of wall time. A wait
    past ACK_PATIENCE s is said (`say`: the node's log). A reader that has gone is not waited for: its node ended, or
    it announced nothing for the participants' lease (PARTICIPANT_LEASE: its process stopped or starved that long)
    and is taken for gone; one that left during a wait is said too, since what it had not taken is lost to it (a
    recorder that comes back counts what it lost in its summary). ACK_CATCH_UP outlasts the lease, so a reader
    stopped is waited for as long as it is taken for there; one still there that has acknowledged nothing for
    ACK_CATCH_UP s (alive but not taking, or resumed after a long stop and no longer receiving: seen once after a
    90-s stop) ends the node (PeerError: exit code 1, the topic named) rather than have the run wait that long again
    at every ACKED_EVERY batches (docs/ros.md, "A recorder that falls behind")."""
    readers = publisher.get_subscription_count()
    acknowledged = publisher.wait_for_all_acked(Duration(seconds=ACK_PATIENCE))
    if not acknowledged:
        say(
            f"the readers of {publisher.topic_name} (the recorder among them) have not acknowledged its messages for "
            f"{ACK_PATIENCE:g} s of wall time: the run waits for them as long as they are there (a reader that "
            f"announces nothing for {PARTICIPANT_LEASE:g} s is taken for gone), at most "
            f"{ACK_CATCH_UP - ACK_PATIENCE:g} s more"
        )
        acknowledged = publisher.wait_for_all_acked(Duration(seconds=ACK_CATCH_UP - ACK_PATIENCE))
    left = readers - publisher.get_subscription_count()
    if left > 0:
        say(
            f"{left} reader(s) of {publisher.topic_name} left while the run waited for their acknowledgements (a "
            "node ended, or one stopped or starved for longer than the participants' lease, "
            f"{PARTICIPANT_LEASE:g} s in the run's Fast DDS profile, was taken for gone): what they had not taken is "
            "lost to them, the run goes on"
        )
    if not acknowledged:
        raise PeerError(
            f"the readers of {publisher.topic_name} (the recorder among them) are there but have acknowledged "
            f"nothing more it sent for {ACK_CATCH_UP:g} s of wall time (a node stopped, or one resumed that no longer "
            "receives): the run ends; the recorder's summary says what it has"
        )


class JointColumns(NamedTuple):
    """One joint's fields over a batch's groups (batch_columns), each an array with one value per group."""

    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray


class BatchColumns(NamedTuple):
    """A Batch message read column by column (batch_columns): `times` [ns] (int64) the groups' exchange times, in
    order; `walls` [s] the wall-clock times their senders gave (the "stamp" joint's velocity); `joints` the joints
    asked for, each over the groups."""

    times: np.ndarray
    walls: np.ndarray
    joints: dict[str, JointColumns]

    def rows(self, taken: np.ndarray) -> BatchColumns:
        """The groups at the indices or where the mask `taken` says, in the same layout."""
        return BatchColumns(
            self.times[taken],
            self.walls[taken],
            {name: JointColumns(*(field[taken] for field in joint)) for name, joint in self.joints.items()},
        )


def batch_columns(message, required: tuple[str, ...]) -> BatchColumns:
    """A Batch message as columns (BatchColumns): the exchange times, the senders' wall-clock times and, for each
    joint `required`, its position, velocity and effort at each group (a joint given twice in a group: the later
    one). Checked (trust.BadMessage otherwise), in the order of the message: the arrays as long as the names, a
    "stamp" first, exchange times whole, within 0..2^53 ns and not decreasing, and every group with the joints
    `required`. One pass of numpy over the message, whatever its number of groups."""
    names = joint_fields(message, "position", "velocity", "effort")
    if names and names[0] != "stamp":
        raise BadMessage("no stamp", f"a batch starting with joint {names[0]!r}, expected 'stamp'")
    fields = [np.asarray(getattr(message, field), dtype=float) for field in ("position", "velocity", "effort")]
    named = np.array(names, dtype=str)
    opens = np.flatnonzero(named == "stamp")  # the entries that open a group
    stamps = fields[0][opens]
    with np.errstate(invalid="ignore"):
        whole = np.isfinite(stamps) & (stamps >= 0.0) & (stamps <= LARGEST_STAMP) & (stamps == np.floor(stamps))
        back = np.flatnonzero(stamps[1:] < stamps[:-1]) + 1  # (a repeat: a peer answered an exchange time twice)
    bad = np.flatnonzero(~whole)
    if bad.size and (not back.size or bad[0] <= back[0]):
        raise BadMessage(
            "bad stamp",
            f"a batch's exchange time {float(stamps[bad[0]])!r} ns, expected a whole number in 0..{LARGEST_STAMP}",
        )
    if back.size:
        raise BadMessage(
            "out of order",
            f"a batch's exchange time {stamps[back[0]]:.0f} ns after {int(stamps[back[0] - 1])} ns",
        )
    times = stamps.astype(np.int64)
    group_of = np.cumsum(named == "stamp") - 1  # each entry's group
    entries = {}  # joint -> the entry holding it in each group (-1: none)
    for joint in required:
        at = np.flatnonzero(named == joint)
        last = np.append(group_of[at][1:] != group_of[at][:-1], True) if at.size else at.astype(bool)
        entries[joint] = np.full(times.size, -1)
        entries[joint][group_of[at][last]] = at[last]
    lacking = [int(np.argmax(entry < 0)) for entry in entries.values() if (entry < 0).any()]
    if lacking:
        group = min(lacking)
        end = opens[group + 1] if group + 1 < opens.size else len(names)
        missing = [joint for joint, entry in entries.items() if entry[group] < 0]
        raise BadMessage(
            "missing joint",
            f"the group at {seconds(int(times[group])):.9g} s has no {', '.join(missing)} "
            f"(it has {', '.join(dict.fromkeys(names[opens[group] : end]))})",
        )
    return BatchColumns(
        times,
        fields[1][opens],
        {joint: JointColumns(*(field[entry] for field in fields)) for joint, entry in entries.items()},
    )


def scene_model(node: Node) -> MachineModel:
    """The scene named by the node's `scene_file` parameter (a path or a bundled name) with the
    `overrides` parameter's KEY=VALUE changes, assembled by the core, its solver.path decided as a command decides
    it (solvers.on_path_for_a_command; `run` passes its decision to every node). Raises SceneError, also for a
    scene that cannot be co-simulated (solvers.cosim.cosimulation_refusal)."""
    scene_file = text_parameter(
        node, "scene_file", "engine_direct", "scene file (YAML path) or the name of a bundled scene"
    )
    overrides = list_parameter(
        node, "overrides", [""], "scene changes KEY=VALUE, as `mech-regulator --set` (e.g. governor.damping=300)"
    )
    model = on_path_for_a_command(
        build_model(load_scene(scene_file, [item for item in overrides if item])), node.get_logger().info
    )  # solver.path auto: fast once compiled (`run` decides it)
    reason = cosimulation_refusal(model)
    if reason is not None:
        raise SceneError(f"{scene_file}: the nodes cannot play this scene: {reason}")
    return model


class RunState:
    """What the machine says of the run on `machine/status` (std_msgs/String, JSON, transient-local so that a node
    joining late reads it): `state` running, paused, holding (at the end, waiting for ~/reset) or finished; the
    simulation `time` [s]; the `trial` (1, then one more at every ~/reset); `status` of the solver (complete,
    failed, ...), `tripped_at` [s] (None: no overspeed trip), in realtime `max_lag_s` (the largest lag [s] of the
    published simulation time behind the wall clock) and, once finished, `finished_at_ns`."""

    RUNNING, PAUSED, HOLDING, FINISHED = "running", "paused", "holding", "finished"


def follow_run_state(
    node: Node, on_state: Callable[[RunStateMessage], None], refusals: Refusals, speakers: Speakers
) -> Subscription:
    """Subscribe `node` to the machine's run state (RunState), taken from the node speakers allow on machine/status
    only; on_state gets it checked (trust.RunStateMessage), and return the subscription. A node that follows the
    machine sets `node.done = True` when the state is finished, so `run` ends it by itself."""
    return receive(
        node,
        String,
        "machine/status",
        lambda message: on_state(json_message(message.data, RunStateMessage)),
        STATUS_READER_QOS,
        refusals,
        speakers,
    )


def diagnostics(node: Node, level: bytes, message: str, values: dict[str, object]) -> DiagnosticArray:
    """A DiagnosticArray with this node's status (hardware_id: the scene)."""
    status = DiagnosticStatus(
        level=level,
        name=f"mech_regulator: {node.get_fully_qualified_name()}",
        message=message,
        hardware_id=str(values.pop("scene", "")),
        values=[KeyValue(key=key, value=str(value)) for key, value in values.items()],
    )
    array = DiagnosticArray(status=[status])
    array.header.stamp = node.get_clock().now().to_msg()
    return array


OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR


def remember_ctrl_c() -> Callable[[], bool]:
    """Install Python's handler for SIGINT (a KeyboardInterrupt, as by default) that also notes the signal,
    and return whether it came. Installed before rclpy.init, whose C handler chains to it. rclpy shuts its
    context down on a thread of its own, so the KeyboardInterrupt can surface while rclpy.ok() still says
    True — and wrapped by rclpy's C++ layer in another exception when it interrupts the conversion of a
    message for a callback ("RuntimeError: Unable to convert call argument '0' to Python object")."""
    received: list[int] = []

    def note_and_interrupt(number, frame) -> None:
        received.append(number)
        if len(received) == 1:  # a second interrupt while the node stops would cut its closing short
            signal.default_int_handler(number, frame)

    signal.signal(signal.SIGINT, note_and_interrupt)
    return lambda: bool(received)


def node_label(node_factory: Callable[[], Node]) -> str:
    """The name a node's messages start with: machine_node for MachineNode (the launcher finds them by it)."""
    label = getattr(node_factory, "__name__", "node")
    return label[: -len("Node")].lower() + "_node" if label.endswith("Node") else label


def deliver_all(node: Node, publishers: list | None = None) -> None:
    """Wait (at most ACK_WAIT s each; the machine's end longer: MachineNode.deliver_the_end) until
    every subscriber has acknowledged what the publishers (default: all the node's) sent: a node that ends by itself
    right after its last message (the governor's last state, the machine's `finished`) must not take it with it.
    Acknowledgements count only the subscriptions a publisher has matched, and discovery tells a process of a
    subscription (the graph) and matches its publisher to it (the middleware) separately: so each publisher first
    waits (at most MATCH_WAIT s) until it has matched as many subscriptions as the graph knows on its topic."""
    for publisher in node.publishers if publishers is None else publishers:
        deadline = time.monotonic() + MATCH_WAIT  # a subscription the graph still lists may never match (its node
        # was killed and its lease has not run out yet, or its QoS does not fit)
        while (
            publisher.get_subscription_count() < node.count_subscribers(publisher.topic_name)
            and time.monotonic() < deadline
        ):
            time.sleep(MATCH_POLL)
        publisher.wait_for_all_acked(Duration(seconds=ACK_WAIT))


def take_waiting(subscription: Subscription) -> int:
    """Hand every message waiting in `subscription`'s reader, with its message info, to the subscription's callback
    (one made by trust.receive, which checks its speaker), taken straight from the reader rather than through the
    executor, and return how many there were. rclpy's EventsExecutor was seen to leave messages in a reader without calling its callback: the
    machine's recorder/progress, and the recorder's machine/moments after its process had been stopped for 90 s (a
    reader kept full acknowledges nothing more, and the run waited for it; docs/ros.md, "A recorder that falls
    behind")."""
    taken = 0
    while True:
        with subscription.handle:
            received = subscription.handle.take_message(subscription.msg_type, subscription.raw)
        if received is None:
            return taken
        cast(Callable[..., None], subscription.callback)(*received)  # (message, info): trust.receive's callback
        taken += 1


def spin_once(node: Node, timeout: float) -> None:
    """Handle the node's callbacks that are ready, waiting up to `timeout` [s] of wall time for one, on the executor
    `run` added the node to."""
    executor = node.executor
    assert executor is not None, "run adds the node to its executor before the node's work"
    executor.spin_once(timeout_sec=timeout)


def run(node_factory: Callable[[], N], work: Callable[[N], None] | None = None) -> int:
    """Run a node until it finishes or Ctrl-C: rclpy.init with the process's --ros-args, build the node,
    add it to rclpy's EventsExecutor (`node.executor`: an idle spin costs about a third of the default
    executor's), then `work(node)` or spin until the node says it is done (`node.done`, see follow_run_state).
    A bad scene or parameter ends with a message 'mech_regulator: <name>_node: <why>' (node_label; the launcher
    quotes it) and exit code 2, a missing peer or an output it could not write with exit code 1; Ctrl-C ends
    with exit code 0 whatever call into rclpy it interrupts, rclpy.init included."""
    interrupted = remember_ctrl_c()
    try:
        rclpy.init(args=sys.argv)
    except KeyboardInterrupt:  # stopped while rclpy starts (Ctrl-C, or the launcher ending a run another node refused)
        with contextlib.suppress(Exception, KeyboardInterrupt):
            rclpy.try_shutdown()
        return 0
    node = None
    name = node_label(node_factory)
    code = EXIT_FAILED  # an unexpected error: it propagates, the process ends with 1
    try:
        node = node_factory()
        executor = EventsExecutor()
        executor.add_node(node)
        if work is not None:
            work(node)
        else:
            while rclpy.ok() and not getattr(node, "done", False):
                executor.spin_once(timeout_sec=IDLE_SPIN_SLICE)
            if rclpy.ok():
                deliver_all(node)
        code = 0
    except SceneError as error:
        print(f"mech_regulator: {name}: {error}", file=sys.stderr)
        code = EXIT_BAD_INPUT
    except (PeerError, OutputError) as error:
        print(f"mech_regulator: {name}: {error}", file=sys.stderr)
        code = EXIT_FAILED
    except (KeyboardInterrupt, ExternalShutdownException):  # Ctrl-C: a normal way to stop a node
        code = 0
    except rclpy.exceptions.ParameterException as error:  # a parameter override outside its range or type
        print(f"mech_regulator: {name}: {error}", file=sys.stderr)
        code = EXIT_BAD_INPUT
    except Exception as error:
        if interrupted() or not rclpy.ok():  # Ctrl-C in the middle of a call into rclpy
            code = 0
        elif node is None and isinstance(error, (ArithmeticError, RecursionError, MemoryError)):
            print(
                f"mech_regulator: {name}: the scene cannot be computed with ({type(error).__name__}: {error}); "
                "expected the values of a real machine",
                file=sys.stderr,
            )  # a scene beyond the limits' reach
            code = EXIT_BAD_INPUT
        else:
            raise
    finally:
        try:
            if node is not None:
                close = getattr(node, "close", None)
                if close is not None:
                    close()
            end_if_stuck(code)
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()  # rclpy's SIGINT handler may shut the context down at any moment
        except KeyboardInterrupt:  # the interrupt that stops the node, surfacing late (rclpy defers it)
            pass
    return code


def end_if_stuck(code: int) -> None:
    """End the process with `code` (os._exit) should destroying its node and rclpy's context take longer than
    DESTROY_WAIT s: Fast DDS can deadlock when a participant is destroyed while it handles another's leaving
    (eProsima/Fast-DDS#6193 and kin; seen as a node that never ended after its run), and by then everything the node
    owes is sent and acknowledged, and its files closed. A hang inside a call that holds the GIL (seen as a recorder
    that had written its summary still there 30 s later, killed by the launcher) stops that watchdog too: after a
    node's work ended normally (code 0), SIGALRM, unhandled, ends the process after TEARDOWN_ALARM s whatever it is
    in, and the launcher reads that signal as a teardown hang after a finished node (launch.TEARDOWN_HANG)."""

    def end() -> None:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)

    watchdog = threading.Timer(DESTROY_WAIT, end)
    watchdog.daemon = True
    watchdog.start()
    if code == 0:
        signal.alarm(TEARDOWN_ALARM)
