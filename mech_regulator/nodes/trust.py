"""Who may speak to a node, what a message may say, and what a run could not refuse: the nodes' own defence on a
shared ROS domain (docs/ros.md, "Who may speak").

Every subscription of the nodes goes through `receive`: the publisher is identified by its GID (the message info rclpy
gives a two-argument callback) and the graph's endpoint info (node name and namespace of that GID); a topic a node
takes from named peers only is refused from anyone else, and from a second publisher of a peer's name (the first one
accepted is pinned). Then the message's own checks run (they raise BadMessage); a refused message is counted per
topic and reason, and one refused for who sent it also per sender and topic (Refusals, in /diagnostics and the
recorder's summary), and never reaches the state. An error a check did not foresee is caught at the callback's
boundary, logged with its traceback and reported as a disturbance that may have changed the run's numbers: no node
raises out of a callback, and no such run ends `complete` unmarked.
"""

from __future__ import annotations

import inspect
import json
import math
import time
import traceback
from collections.abc import Callable
from typing import Annotated, Literal, NamedTuple, overload

import numpy as np
import pydantic
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.node import Node

from mech_regulator.solvers.cosim import NANOSECONDS

WARNING_PERIOD = 2.0  # [s] of wall time between repeated warnings about refused messages
MAX_DISTURBANCES = 20  # disturbances a node keeps the text of (the others: counted, and in its log)
LARGEST_STAMP = 2**53  # [ns] the largest exchange time a Batch carries exactly (about 104 days)
UNKNOWN_NODE = "_NODE_NAME_UNKNOWN_"  # the graph's node name of an endpoint whose node it has not heard of yet
# [s] of wall time a node waits at most, once per publisher, for the graph to name the node of a publisher whose
# message has come: a participant announces its nodes' names on a topic of its own (ros_discovery_info), which can
# arrive a moment after the first messages of a publisher it has just matched
NAME_WAIT = 2.0
UNNAMED_SENDER = "a publisher the graph does not name"  # Speakers.sender of a GID the graph named within no wait
NAME_POLL = 0.005  # [s] of wall time between two looks at the graph meanwhile


class BadMessage(Exception):
    """A message refused: `reason` (short: the counter's key, e.g. 'not finite') and `detail` (what was wrong);
    `sender`: the fully qualified name of the publisher's node when it is refused for who sent it (Speakers.check),
    None otherwise."""

    def __init__(self, reason: str, detail: str, sender: str | None = None):
        super().__init__(f"{reason}: {detail}")
        self.reason, self.detail, self.sender = reason, detail, sender


class Refusals:
    """What a node refused (counts per topic and reason; `foreign`: those refused for who sent them, per sender and
    topic) and what disturbed its run that it could not refuse (a lost peer, a stall, a service called from outside,
    a namesake on the domain, a load poked from outside, an error in a callback): each logged, both in the node's
    /diagnostics (key_values) and so in the recorder's summary. `alters_results`: whether a disturbance may have
    changed the run's numbers (its summary is then not `complete`). `report`, when given, is called at once for news:
    a topic and reason refused for the first time, a new sender, or a disturbance (the recorder must have them before
    the run ends; there are only so many of either, whatever a flood of bad messages does)."""

    def __init__(self, node: Node, report: Callable[[], None] | None = None):
        self.node, self.report = node, report
        self.counts: dict[str, dict[str, int]] = {}
        self.foreign: dict[str, dict[str, int]] = {}  # sender (fully qualified node name) -> topic -> count
        self.disturbances: list[str] = []
        self.alters_results = False
        self.altering: dict[tuple[str, str], str] = {}  # (topic, reason) -> why such a refusal may alter the results
        self.altering_unnamed: dict[str, str] = {}  # topic -> why refusing an unnamed publisher there may alter them

    def alters_when_refused(self, topic: str, reason: str, why: str) -> None:
        """Count a refusal on `topic` under `reason` also as a disturbance that may alter the results (once per
        sender), saying `why`: a refusal that does not keep the run's numbers the scene's."""
        self.altering[(topic, reason)] = why

    def alters_when_unnamed(self, topic: str, why: str) -> None:
        """Count a refusal on `topic` of a publisher the graph did not name (UNNAMED_SENDER: it may be the run's own
        node, named too late) also as a disturbance that may alter the results, saying `why`."""
        self.altering_unnamed[topic] = why

    def refuse(self, topic: str, reason: str, detail: str, sender: str | None = None) -> None:
        """Count a refused message on `topic` under `reason` (and under its `sender` when it was refused for who
        sent it) and warn (at most every WARNING_PERIOD s per call site) with what was wrong."""
        reasons = self.counts.setdefault(topic, {})
        news = reason not in reasons
        reasons[reason] = reasons.get(reason, 0) + 1
        if sender is not None:
            topics = self.foreign.setdefault(sender, {})
            news = news or topic not in topics
            topics[topic] = topics.get(topic, 0) + 1
        self.node.get_logger().warning(
            f"refused a message on {topic} ({reason}): {detail}; the state is unchanged ({reasons[reason]} so far)",
            throttle_duration_sec=WARNING_PERIOD,
        )
        if (topic, reason) in self.altering:
            self.disturb(f"{topic} from {sender or 'a publisher'} ({reason}): {self.altering[topic, reason]}", True)
        elif sender == UNNAMED_SENDER and topic in self.altering_unnamed:
            self.disturb(f"{topic} from {sender} ({reason}): {self.altering_unnamed[topic]}", True)
        if news and self.report is not None:
            self.report()

    def disturb(self, text: str, alters_results: bool) -> None:
        """Note a disturbance (once per text; the first MAX_DISTURBANCES texts, then that there were more), logged as
        an error."""
        if text in self.disturbances:
            return
        self.node.get_logger().error(
            f"disturbance: {text}" + ("; this run's numbers may no longer be the scene's" if alters_results else "")
        )
        news = len(self.disturbances) <= MAX_DISTURBANCES or alters_results and not self.alters_results
        if len(self.disturbances) < MAX_DISTURBANCES:
            self.disturbances.append(text)
        elif len(self.disturbances) == MAX_DISTURBANCES:
            self.disturbances.append("more disturbances: see the node's log")
        self.alters_results = self.alters_results or alters_results
        if news and self.report is not None:
            self.report()

    def status(self, level: bytes, text: str) -> tuple[bytes, str]:
        """A node's diagnostics level and message with its refusals and disturbances in them (WARN), unless it has a
        worse one already."""
        if level != DiagnosticStatus.OK:
            return level, text
        if self.disturbances:
            return DiagnosticStatus.WARN, f"disturbed: {self.disturbances[-1]}"
        if self.total:
            return DiagnosticStatus.WARN, f"{self.total} messages refused"
        return level, text

    @property
    def total(self) -> int:
        return sum(count for reasons in self.counts.values() for count in reasons.values())

    def key_values(self) -> list[KeyValue]:
        """The diagnostics' entries: refused_messages (the total), 'refused: <topic>: <reason>' (each count),
        'foreign: <sender>: <topic>' (each count of a sender refused for who it is), 'disturbance: <n>' (each text)
        and alters_results."""
        values = [KeyValue(key="refused_messages", value=str(self.total))]
        values += [
            KeyValue(key=f"{kind}: {first}: {second}", value=str(count))
            for kind, table in (("refused", self.counts), ("foreign", self.foreign))
            for first, inner in sorted(table.items())
            for second, count in sorted(inner.items())
        ]
        values += [KeyValue(key=f"disturbance: {index}", value=text) for index, text in enumerate(self.disturbances)]
        return values + [KeyValue(key="alters_results", value=str(self.alters_results))]


class Report(NamedTuple):
    """What a node refused and what disturbed it, as its diagnostics say (Refusals.key_values): refused counts per
    topic and reason, foreign counts per sender and topic, the disturbances' texts, and whether one may have changed
    the run's numbers."""

    counts: dict[str, dict[str, int]]
    foreign: dict[str, dict[str, int]]
    disturbances: list[str]
    alters_results: bool


def report_of(values: dict[str, str]) -> Report:
    """A node's Report from its diagnostics values (Refusals.key_values), checked; raises BadMessage when they do not
    read so."""
    tables: dict[str, dict[str, dict[str, int]]] = {"refused": {}, "foreign": {}}
    disturbances = []
    for key, value in values.items():
        kind, _, rest = key.partition(": ")
        if kind in tables and rest:
            first, _, second = rest.partition(": ")
            tables[kind].setdefault(first, {})[second] = whole_number(value, key)
        elif kind == "disturbance":
            disturbances.append(value)
    alters = values.get("alters_results", "False")
    if alters not in ("True", "False"):
        raise BadMessage("bad value", f"alters_results = {alters!r}, expected True or False")
    return Report(tables["refused"], tables["foreign"], disturbances, alters == "True")


def whole_number(text: str, what: str) -> int:
    """A count >= 0 written in a diagnostics value; BadMessage otherwise."""
    if not text.isdigit():
        raise BadMessage("bad value", f"{what} = {text!r}, expected a whole number >= 0")
    return int(text)


@overload
def real_number(text: str, what: str, allow_none: Literal[False] = False) -> float: ...
@overload
def real_number(text: str, what: str, allow_none: bool) -> float | None: ...
def real_number(text: str, what: str, allow_none: bool = False) -> float | None:
    """A finite number written in a diagnostics value ('None' too when allow_none); BadMessage otherwise."""
    if allow_none and text == "None":
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise BadMessage(
            "bad value", f"{what} = {text!r}, expected a finite number" + (" or None" if allow_none else "")
        )
    return value


def merge_counts(into: dict[str, dict[str, int]], counts: dict[str, dict[str, int]]) -> None:
    """Add refusal counts (topic -> reason -> count, or sender -> topic -> count) to `into`."""
    for first, inner in counts.items():
        for second, count in inner.items():
            into.setdefault(first, {})[second] = into.get(first, {}).get(second, 0) + count


# ---------------------------------------------------------------------------------------------------------------------
# Who may speak


class Speakers:
    """Which nodes a node takes each topic from (`allow`), and the publisher of each it pinned on it: the first
    accepted message's GID. A publisher is known by its GID through the graph (Node.get_publishers_info_by_topic: node
    name and namespace of each endpoint GID), looked up again whenever a GID is new; a GID the graph does not name
    yet is waited for, at most name_wait [s] of wall time once per GID (publisher_name). A message refused for who
    sent it names its sender (BadMessage.sender: the node's fully qualified name, `sender`)."""

    def __init__(self, node: Node, name_wait: float = NAME_WAIT):
        self.node, self.name_wait = node, name_wait
        self.allowed: dict[str, tuple[str, ...]] = {}  # topic -> node names
        self.pinned: dict[tuple[str, str], bytes] = {}  # (topic, node name) -> GID of its accepted publisher
        self.names: dict[bytes, str] = {}  # GID -> node name (in this node's namespace; '' elsewhere)
        self.qualified: dict[bytes, str] = {}  # GID -> fully qualified node name (namespace and name)
        self.waited: set[bytes] = set()  # GIDs waited name_wait for already

    def allow(self, topic: str, *node_names: str) -> None:
        """Take `topic` from these nodes only; with no names, from whichever publisher sends first (pinned: an
        external controller, whose name the run does not know)."""
        self.allowed[topic] = node_names

    def publisher_name(self, topic: str, gid: bytes) -> str:
        """The name of the node that has the publisher `gid` on `topic` ('' when its node is in another namespace, or
        when the graph does not name it within name_wait s of wall time: the graph learns a publisher's node a
        moment after the publisher's first messages can arrive, so the first message of a new GID waits for it,
        blocking the node's callbacks that long at most, once per GID)."""
        deadline = time.monotonic() + (0.0 if gid in self.waited else self.name_wait)
        while not self._look_up(topic, gid) and time.monotonic() < deadline:
            time.sleep(NAME_POLL)
        self.waited.add(gid)
        return self.names.get(gid, "")

    def _look_up(self, topic: str, gid: bytes) -> bool:
        """Whether the graph names the node of publisher `gid` (self.names has it), reading the graph's publishers
        of `topic` into self.names unless it did already."""
        if gid not in self.names:
            namespace = self.node.get_namespace()
            for info in self.node.get_publishers_info_by_topic(topic):
                if info.node_name != UNKNOWN_NODE:
                    endpoint = bytes(info.endpoint_gid)
                    self.names[endpoint] = info.node_name if info.node_namespace == namespace else ""
                    self.qualified[endpoint] = f"{info.node_namespace.rstrip('/')}/{info.node_name}"
        return gid in self.names

    def sender(self, gid: bytes) -> str:
        """The fully qualified name of the node of publisher `gid` as the graph named it (publisher_name looked it
        up), or 'a publisher the graph does not name'."""
        return self.qualified.get(gid, UNNAMED_SENDER)

    def check(self, topic: str, info: dict | None) -> str:
        """The name of the node that sent a message on `topic` (info: its rclpy MessageInfo; '' when the graph does
        not name it in this node's namespace); BadMessage, naming the sender, unless the topic is open to all (not
        allowed: anyone may send it), or the message is an allowed node's pinned publisher's, or an allowed node's
        first publisher's on the topic (then pinned)."""
        expected = self.allowed.get(topic)
        gid = bytes(((info or {}).get("publisher_gid") or {}).get("data") or b"")
        name = self.publisher_name(topic, gid) if gid else ""
        if expected is None:
            return name
        if expected and name not in expected:
            raise BadMessage(
                "not from " + " or ".join(expected),
                f"sent by {self.sender(gid)}; this node takes {topic} from {' or '.join(expected)} only",
                self.sender(gid),
            )
        if self.pinned.setdefault((topic, name if expected else ""), gid) != gid:
            first = f"node '{name}'" if expected else "the first publisher"
            raise BadMessage(
                "second publisher",
                f"a second publisher of {first} on {topic}, {self.sender(gid)} (another node of "
                "that name on the domain?); the first one is kept",
                self.sender(gid),
            )
        return name


def about_the_nodes(message) -> bool:
    """Whether a diagnostic_msgs/DiagnosticArray has a status of this package's nodes (named 'mech_regulator: ...',
    common.diagnostics): a diagnostics aggregator's or another program's own statuses are none of their business."""
    return any(status.name.startswith("mech_regulator: ") for status in message.status)


def namesakes(node: Node, names: list[str]) -> list[str]:
    """Those of `names` that more than one node in this node's namespace has on the domain (the graph as this node
    sees it), in order."""
    namespace = node.get_namespace()
    seen = [name for name, space in node.get_node_names_and_namespaces() if space == namespace]
    return [name for name in dict.fromkeys(names) if seen.count(name) > 1]


def receive(
    node: Node,
    message_type,
    topic: str,
    handle: Callable,
    qos,
    refusals: Refusals,
    speakers: Speakers | None = None,
    pass_speaker: bool = False,
    concerns: Callable[[object], bool] | None = None,
    reader: Callable[[bytes], object] | None = None,
):
    """Subscribe `node` to `topic`: each message that `concerns` the node (default: all; a shared topic such as
    /diagnostics also carries others' messages, passed over) is checked for its speaker (speakers.check) and handed
    to `handle` (with the speaker's node name too when pass_speaker), which raises BadMessage to refuse it; a
    refusal is counted (refusals.refuse), any other error logged with its traceback and reported as a disturbance
    that may alter the results. Nothing raises out of the callback. With a `reader` the subscription is raw (the
    message's serialized bytes, rclpy converting nothing) and `reader` makes the message of them (wire.JointStateReader;
    BadMessage for bytes it cannot read).

    rclpy 9.1's EventsExecutor calls a callback that takes message info with one argument, the (message, info)
    tuple, where the other executors pass them as two: the callback takes both forms (its signature says two, so
    that rclpy hands it the info)."""

    def on_message(*received) -> None:
        message, info = received if len(received) == 2 else received[0]
        if concerns is not None and not concerns(message):
            return
        try:
            speaker = speakers.check(topic, info) if speakers is not None else ""
            if reader is not None:
                message = reader(message)
            if pass_speaker:
                handle(message, speaker)
            else:
                handle(message)
        except BadMessage as refused:
            refusals.refuse(topic, refused.reason, refused.detail, refused.sender)
        except Exception as error:  # what no check foresaw: the message may have changed the state half way
            node.get_logger().error(
                f"a message on {topic} raised {type(error).__name__}: {error}\n{traceback.format_exc()}"
            )
            refusals.disturb(f"a message on {topic} raised {type(error).__name__}: {error}", alters_results=True)

    # inspect.signature reads a function's __signature__, an attribute typeshed does not declare on functions
    on_message.__signature__ = inspect.Signature(  # type: ignore[attr-defined]
        [
            inspect.Parameter("message", inspect.Parameter.POSITIONAL_ONLY),
            inspect.Parameter("info", inspect.Parameter.POSITIONAL_ONLY),
        ]
    )
    return node.create_subscription(message_type, topic, on_message, qos, raw=reader is not None)


# ---------------------------------------------------------------------------------------------------------------------
# What a message may say


def stamp_of(stamp) -> int:
    """Whole nanoseconds of a builtin_interfaces/Time, checked: seconds >= 0, nanoseconds < 1e9, at most
    LARGEST_STAMP; BadMessage otherwise."""
    if stamp.sec < 0 or stamp.nanosec >= NANOSECONDS or stamp.sec * NANOSECONDS + stamp.nanosec > LARGEST_STAMP:
        raise BadMessage(
            "bad stamp",
            f"stamp {stamp.sec} s {stamp.nanosec} ns, expected a time >= 0 with nanoseconds "
            f"below 1e9, at most {LARGEST_STAMP} ns",
        )
    return stamp.sec * NANOSECONDS + stamp.nanosec


def joint_fields(message, *needed: str) -> list[str]:
    """The names of a sensor_msgs/JointState, checked against its arrays: each of position, velocity and effort as
    long as the names, or empty (as the message's definition allows: a field its sender does not give) unless it is
    one of the fields `needed` here; BadMessage otherwise."""
    names = list(message.name)
    lengths = {field: len(getattr(message, field)) for field in ("position", "velocity", "effort")}
    if any(length != len(names) and (length or field in needed) for field, length in lengths.items()):
        raise BadMessage(
            "array lengths",
            f"{len(names)} names but "
            + ", ".join(f"{length} {field}s" for field, length in lengths.items())
            + "; expected one of each per name"
            + (f" ({', '.join(needed)} needed here, the others may be empty)" if needed else " (or none)"),
        )
    return names


def bounded(value: float, low: float, high: float, what: str) -> float:
    """`value` if it is finite and within [low, high]; BadMessage ('not finite' or 'out of range') naming `what`."""
    if not math.isfinite(value):
        raise BadMessage("not finite", f"{what} = {value!r}, expected a finite number in [{low:g}, {high:g}]")
    if not low <= value <= high:
        raise BadMessage("out of range", f"{what} = {value!r}, expected a finite number in [{low:g}, {high:g}]")
    return value


def bounded_rows(values: np.ndarray, low: np.ndarray, high: np.ndarray, what: Callable[[int, int], str]) -> None:
    """Check `values` (rows x fields) as `bounded` checks one value, each field against its bounds `low` and `high`
    (one per field), vectorised; the first bad value, rows first, raises bounded's BadMessage with what(row, field)
    naming it."""
    with np.errstate(invalid="ignore"):
        bad = ~(np.isfinite(values) & (values >= low) & (values <= high))
    if bad.any():
        row, field = divmod(int(np.argmax(bad)), values.shape[1])
        bounded(float(values[row, field]), float(low[field]), float(high[field]), what(row, field))


def in_order(when: int, newest: int | None, what: str) -> int:
    """`when` [ns] unless it is behind `newest` [ns] (what was taken already): BadMessage 'out of order'."""
    if newest is not None and when < newest:
        raise BadMessage(
            "out of order", f"{what} stamped {when / NANOSECONDS:.9g} s after one stamped {newest / NANOSECONDS:.9g} s"
        )
    return when


def not_ahead(when: int, latest: int, what: str) -> int:
    """`when` [ns] unless it is ahead of `latest` [ns] (the newest exchange time the machine has published: nothing
    can answer a time not asked yet): BadMessage 'ahead of the machine'."""
    if when > latest:
        raise BadMessage(
            "ahead of the machine",
            f"{what} stamped {when / NANOSECONDS:.9g} s, the machine is at {latest / NANOSECONDS:.9g} s",
        )
    return when


FiniteTime = Annotated[float, pydantic.Field(allow_inf_nan=False, ge=0.0)]  # [s]


class RunStateMessage(pydantic.BaseModel):
    """machine/status as the nodes read it (common.RunState)."""

    model_config = pydantic.ConfigDict(extra="ignore", strict=True)

    state: Literal["running", "paused", "holding", "finished"]
    time: FiniteTime
    trial: Annotated[int, pydantic.Field(ge=1)]
    status: str
    tripped_at: FiniteTime | None = None
    max_lag_s: Annotated[float, pydantic.Field(allow_inf_nan=False)] | None = None
    finished_at_ns: Annotated[int, pydantic.Field(ge=0, le=LARGEST_STAMP)] | None = None

    @pydantic.model_validator(mode="after")
    def finished_says_when(self):
        if self.state == "finished" and self.finished_at_ns is None:
            raise ValueError("a finished state needs finished_at_ns")
        return self


class GovernorEvent(pydantic.BaseModel):
    """An entry of governor/events: a mode change at `time` [s]."""

    model_config = pydantic.ConfigDict(extra="forbid", strict=True)

    time: FiniteTime
    event: str
    mode: Annotated[list[str | None], pydantic.Field(min_length=1, max_length=4)]


def json_message(text: str, model: type[pydantic.BaseModel]):
    """The JSON object `text` read as `model`; BadMessage ('bad JSON' or 'bad fields') naming what is wrong."""
    try:
        data = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as error:
        raise BadMessage("bad JSON", f"{text[:80]!r}: {error}") from None
    try:
        return model.model_validate(data)
    except pydantic.ValidationError as error:
        problems = "; ".join(
            f"{'.'.join(map(str, item['loc'])) or 'the message'}: {item['msg']}" for item in error.errors()[:3]
        )
        raise BadMessage("bad fields", f"{text[:80]!r}: {problems}") from None
