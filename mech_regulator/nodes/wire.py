"""The two messages of the lockstep's critical path as bytes: the machine's `joint_states` and the governor's
`throttle`, both sensor_msgs/JointState of one layout exchange after exchange (the same joints, the same number of
samples), only their stamp and numbers changing.

rclpy converts every field of a message between Python and C on each publish and each take: for the machine's 38
to 70 entries (the crank, the slider, the corrected and the predicted speed samples), a name as a string for each,
each way, though they never change. A JointStateCodec knows where a layout's stamp and
numbers lie in the message's serialized bytes (CDR, as rclpy's serialize_message writes them and the middleware
carries them), so that a node publishes the bytes of its message with the numbers written in place (rclpy's
Publisher.publish takes bytes), and a node reading a raw subscription (`raw=True`: the bytes as they came) reads a
message of a layout it has seen by comparing everything but the stamp and the numbers with that layout's bytes, then
taking the numbers as they lie; a message of any other layout goes through rclpy's deserialize_message as before. On
the wire nothing changes: every other reader (the scenario, a user's controller or bystander) sees the same
messages. docs/speed.md, "An eleventh sitting", gives what it saves.

Where the stamp, the names and the numbers lie follows the CDR rules for this one type (joint_state_places: each
field aligned to its size from the end of the 4-byte encapsulation header, strings as a length and their bytes),
and is checked for every layout before it is used: read back at those places from rclpy's own serialization of a
message of that layout, the stamp, the names and every number must be the message's (JointStateCodec.of). A layout
that fails the check (an encoding this does not foresee) has no codec, and its messages go the ordinary way. The
bytes CDR leaves between fields to align them are not set by the serializer (whatever the memory held): they are
never compared.
"""

from __future__ import annotations

import array
import struct
import sys
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from builtin_interfaces.msg import Time
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

from mech_regulator.nodes.trust import BadMessage

FIELDS = ("position", "velocity", "effort")
"""The number arrays of a sensor_msgs/JointState, in the order of its definition."""

MAX_TRAILING = 24
"""[bytes] rclpy's serialization may end after the message's last field: the serializer sizes its buffer with the
alignment of each float64 sequence's elements even when the sequence is empty (2 empty ones: 8 bytes more), at most
7 bytes for each of the three. The bytes after the last field are not compared."""

CDR_LITTLE_ENDIAN = 0x01
"""The second byte of a CDR encapsulation header: 0x01 (CDR_LE) or 0x00 (CDR_BE)."""


@dataclass(frozen=True)
class JointStateHeader:
    """A std_msgs/Header as a JointStateView carries it: the stamp (builtin_interfaces/Time) and the frame_id."""

    stamp: Time
    frame_id: str


@dataclass(frozen=True)
class JointStateView:
    """A sensor_msgs/JointState read from its bytes by a JointStateCodec: the fields a reader uses, with the same types
    as rclpy's message (a list of names, array.array('d') of numbers), a new list and new arrays for each message."""

    header: JointStateHeader
    name: list[str]
    position: array.array
    velocity: array.array
    effort: array.array


class JointStatePlaces(NamedTuple):
    """Where the parts of one serialized sensor_msgs/JointState lie (offsets in bytes from the start of the data)."""

    stamp: int  # sec (int32) and nanosec (uint32)
    names: list[tuple[int, int]]  # each name's characters: (offset, length without the terminating NUL)
    spans: dict[str, tuple[int, int]]  # field -> (offset, count) of its float64 array, for the fields it has
    meaningful: np.ndarray  # the offsets of every byte but the stamp's, the numbers' and the alignment's


def joint_state_places(data: bytes) -> JointStatePlaces | None:
    """Where the stamp, the names and the numbers of the sensor_msgs/JointState serialized in `data` lie, by the CDR
    rules (XCDR1, either byte order: the 4-byte encapsulation header, then std_msgs/Header's stamp and frame_id, the
    names, position, velocity and effort; every primitive aligned to its size from the end of the header, a string a
    uint32 length with its terminating NUL counted, a sequence a uint32 count); None when `data` is shorter than
    they need, or longer by MAX_TRAILING bytes or more."""
    if len(data) < 4 or data[1] not in (0x00, CDR_LITTLE_ENDIAN):
        return None
    count_format = ("<" if data[1] == CDR_LITTLE_ENDIAN else ">") + "I"
    position, kept = 4, [(0, 4)]

    def aligned(size: int) -> int:
        return position + (-(position - 4)) % size

    def counted() -> int:
        nonlocal position
        position = aligned(4)
        (count,) = struct.unpack_from(count_format, data, position)
        kept.append((position, position + 4))
        position += 4
        return count

    try:
        stamp = aligned(4)
        position = stamp + 8
        frame_length = counted()
        kept.append((position, position + frame_length))
        position += frame_length
        names = []
        for _ in range(counted()):
            length = counted()
            names.append((position, length - 1))
            kept.append((position, position + length))
            position += length
        spans = {}
        for field in FIELDS:
            count = counted()
            if count:
                position = aligned(8)
                spans[field] = (position, count)
                position += 8 * count
    except struct.error:  # a count beyond the data
        return None
    if not position <= len(data) < position + MAX_TRAILING:
        return None
    meaningful = np.concatenate([np.arange(start, end) for start, end in kept])
    return JointStatePlaces(stamp, names, spans, meaningful)


class JointStateCodec:
    """Where the stamp and the numbers of one layout of sensor_msgs/JointState (frame_id, names, and how many positions,
    velocities and efforts: each as many as the names, or none) lie in its serialized bytes, with those bytes as a
    template (module docstring). Made by `of`, None for a layout whose places fail the check."""

    def __init__(self, template: bytes, places: JointStatePlaces, message: JointState):
        self.template = template  # [bytes] a message of the layout, serialized by rclpy
        self.places = places
        self.names = list(message.name)
        self.frame_id = message.header.frame_id
        self.byte_order = "<" if template[1] == CDR_LITTLE_ENDIAN else ">"
        self.stamp_format = self.byte_order + "iI"
        self.template_meaningful = np.frombuffer(template, dtype=np.uint8)[places.meaningful]

    @classmethod
    def of(cls, message: JointState) -> JointStateCodec | None:
        """The codec of `message`'s layout: its places in rclpy's serialization of `message` (joint_state_places),
        checked there (the stamp, every name and every number read back are the message's, bit for bit); None when
        they are not."""
        template = serialize_message(message)
        places = joint_state_places(template)
        if places is None:
            return None
        codec = cls(template, places, message)
        stamp = message.header.stamp
        names = [template[at : at + length].decode() for at, length in places.names]
        same = (
            struct.unpack_from(codec.stamp_format, template, places.stamp) == (stamp.sec, stamp.nanosec)
            and names == list(message.name)
            and all(
                codec.numbers(template, field).tobytes() == bytes(getattr(message, field))
                if field in places.spans
                else not len(getattr(message, field))
                for field in FIELDS
            )
        )
        return codec if same else None

    def numbers(self, data: bytes | bytearray, field: str) -> np.ndarray:
        """A view on the float64 array of `field` in `data` (writable if `data` is a bytearray), in native order
        when the data's is (else as stored: JointStateView swaps)."""
        at, count = self.places.spans[field]
        return np.frombuffer(data, dtype=self.byte_order + "f8", count=count, offset=at)

    def arrays(self, buffer: bytearray) -> dict[str, np.ndarray]:
        """Views on the float64 arrays of `buffer` (a copy of the template), by field, to write a message's numbers in."""
        return {field: self.numbers(buffer, field) for field in self.places.spans}

    def write(self, buffer: bytearray, sec: int, nanosec: int) -> None:
        """Write the stamp (sec [s], nanosec [ns]) into `buffer`, a copy of the template."""
        struct.pack_into(self.stamp_format, buffer, self.places.stamp, sec, nanosec)

    def matches(self, data: bytes) -> bool:
        """Whether `data`, a serialized JointState, has this layout: its length, and every byte but the stamp's, the
        numbers' and the alignment's, the template's."""
        return len(data) == len(self.template) and bool(
            np.array_equal(np.frombuffer(data, dtype=np.uint8)[self.places.meaningful], self.template_meaningful)
        )

    def view(self, data: bytes) -> JointStateView:
        """The message in `data` (one that `matches`), its fields read from where they lie."""
        sec, nanosec = struct.unpack_from(self.stamp_format, data, self.places.stamp)
        numbers = {field: array.array("d") for field in FIELDS}
        for field, (at, count) in self.places.spans.items():
            numbers[field].frombytes(data[at : at + 8 * count])
            if self.byte_order != NATIVE_ORDER:
                numbers[field].byteswap()
        return JointStateView(
            JointStateHeader(Time(sec=sec, nanosec=nanosec), self.frame_id), list(self.names), **numbers
        )


NATIVE_ORDER = "<" if sys.byteorder == "little" else ">"


class JointStateReader:
    """Reads the bytes of a raw subscription to sensor_msgs/JointState (trust.receive's `reader`): a message of the
    layout last seen through its codec (a JointStateView), any other through rclpy's deserialize_message, whose layout
    then becomes the one kept. Bytes that are not a JointState are refused (trust.BadMessage)."""

    def __init__(self) -> None:
        self.codec: JointStateCodec | None = None

    def __call__(self, data: bytes) -> JointState | JointStateView:
        if self.codec is not None and self.codec.matches(data):
            return self.codec.view(data)
        try:
            message = deserialize_message(data, JointState)
        except Exception as error:  # rclpy raises what its C layer reports, of no documented type
            raise BadMessage("not a JointState", f"{len(data)} bytes that do not deserialize: {error}") from error
        self.codec = JointStateCodec.of(message)
        return message
