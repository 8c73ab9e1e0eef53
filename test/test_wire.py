"""The critical path's messages as bytes (mech_regulator/nodes/wire.py): a layout's places in rclpy's serialization,
checked against rclpy's own deserialization on layouts of every alignment, the alignment bytes never compared, a
layout it has not seen read the ordinary way, and bytes that are no JointState refused."""

import array
import math
import struct

import numpy as np
import pytest

pytest.importorskip("rclpy")

from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from mech_regulator.nodes.common import JointMessage  # noqa: E402
from mech_regulator.nodes.trust import BadMessage  # noqa: E402
from mech_regulator.nodes.wire import (  # noqa: E402
    FIELDS,
    JointStateCodec,
    JointStateReader,
    JointStateView,
    joint_state_places,
)


def joint_state(names, frame_id="", stamp=(3, 250_000_000), fields=FIELDS, seed=0):
    """A JointState of `names` with random numbers in `fields` (the others empty), NaN and infinities among them."""
    numbers = np.random.default_rng(seed).normal(size=(3, len(names))) * 1e3
    if len(names) > 2:
        numbers[0, 1], numbers[1, 2], numbers[2, 0] = math.nan, math.inf, -0.0
    message = JointState(name=list(names))
    message.header.frame_id = frame_id
    message.header.stamp.sec, message.header.stamp.nanosec = stamp
    for row, field in enumerate(FIELDS):
        setattr(message, field, array.array("d", numbers[row] if field in fields else []))
    return message


def same_message(read, message) -> bool:
    """Whether `read` (a JointStateView or a JointState) holds `message`'s stamp, frame_id, names and numbers, bit for
    bit (NaN included)."""
    return (
        (read.header.stamp.sec, read.header.stamp.nanosec) == (message.header.stamp.sec, message.header.stamp.nanosec)
        and read.header.frame_id == message.header.frame_id
        and list(read.name) == list(message.name)
        and all(bytes(getattr(read, field)) == bytes(getattr(message, field)) for field in FIELDS)
    )


LAYOUTS = [
    ((), ""),
    (("crank",), ""),
    (("a", "bb", "ccc", "dddd", "eeeee"), "x"),  # every remainder of a name's length modulo 4
    (("throttle",) + ("throttle_tentative",) * 8, "frame"),
    (("crank", "slider") + ("crank_corrected",) * 33 + ("crank_predicted",) * 33, "abc"),
]


@pytest.mark.parametrize("names, frame_id", LAYOUTS)
@pytest.mark.parametrize("fields", [FIELDS, ("position",), ("velocity", "effort"), ()])
def test_a_layout_s_places_read_back_what_rclpy_serialized(names, frame_id, fields):
    """For layouts whose names and frame_id leave every alignment, with all three arrays, one, two or none: the codec
    is found, and a second message of the layout (other stamp and numbers) read through it is rclpy's deserialization
    of the same bytes, bit for bit."""
    codec = JointStateCodec.of(joint_state(names, frame_id, fields=fields))
    assert codec is not None
    other = joint_state(names, frame_id, stamp=(1_700_000_000, 999_999_999), fields=fields, seed=1)
    data = serialize_message(other)
    assert codec.matches(data)
    read = codec.view(data)
    assert isinstance(read, JointStateView) and same_message(read, other)
    assert same_message(read, deserialize_message(data, JointState))
    assert all(type(getattr(read, field)) is array.array for field in FIELDS)


def test_the_places_follow_the_cdr_alignment_rules():
    """A worked case, the name 'ab' and the position alone: after the 4-byte encapsulation header the stamp at 4 (sec,
    nanosec), frame_id '' at 12 (its length 1, then its NUL at 16), the name count at 20 (16 + 1 aligned to 4), the
    name's length 3 at 24 and 'ab' at 28, the position count at 32 and its double at 36 (36 - 4 = 32 is a multiple of
    8: aligned from the header's end), the velocity and effort counts at 44 and 48; rclpy's buffer is 60 bytes, 8 past
    the last count (wire.MAX_TRAILING)."""
    data = serialize_message(joint_state(["ab"], fields=("position",)))
    places = joint_state_places(data)
    assert places is not None
    assert places.stamp == 4 and places.names == [(28, 2)] and places.spans == {"position": (36, 1)}
    assert data[28:30] == b"ab" and struct.unpack_from("<3I", data, 12)[0] == 1 and len(data) == 60
    assert places.meaningful.max() == 51  # the effort count's last byte: what follows is not compared


def test_the_alignment_bytes_are_not_compared_but_every_other_byte_is():
    """CDR leaves the bytes between fields as the memory held them: a message whose alignment bytes differ still
    matches its layout; one whose name, frame_id, length or count differs does not."""
    message = joint_state(("a", "bb", "ccc"), "x")
    codec = JointStateCodec.of(message)
    assert codec is not None
    data = bytearray(serialize_message(message))
    padding = sorted(
        set(range(len(data)))
        - set(codec.places.meaningful.tolist())
        - set(range(codec.places.stamp, codec.places.stamp + 8))
        - {at + k for at, count in codec.places.spans.values() for k in range(8 * count)}
    )
    assert padding  # 'a', 'bb', 'ccc' and 'x' leave some
    for at in padding:
        data[at] ^= 0xFF
    assert codec.matches(bytes(data))
    first_name = codec.places.names[0][0]
    for at in (first_name, codec.places.meaningful[-1], 8 + 4):  # a name's character, the last count, frame_id's
        changed = bytearray(data)
        changed[at] ^= 0x01
        assert not codec.matches(bytes(changed))
    assert not codec.matches(bytes(data) + b"\0" * 8)


def test_the_reader_reads_its_last_layout_through_the_codec_and_any_other_the_ordinary_way():
    """The first message of a layout is deserialized by rclpy (a JointState) and its layout kept; the next of that
    layout comes as a view; another layout is deserialized again and becomes the one kept."""
    read = JointStateReader()
    first, second = joint_state(("crank",) * 3), joint_state(("crank",) * 3, stamp=(9, 1), seed=2)
    other = joint_state(("crank",) * 4)
    results = [read(serialize_message(message)) for message in (first, second, other, first)]
    assert [type(result).__name__ for result in results] == ["JointState", "JointStateView", "JointState", "JointState"]
    assert all(same_message(result, message) for result, message in zip(results, (first, second, other, first)))


@pytest.mark.parametrize(
    "data",
    [b"", b"\x00\x01\x00\x00", b"\x00\x01\x00\x00" + struct.pack("<iII", 1, 2, 10**6), bytes(range(40))],
    ids=["empty", "header only", "a string longer than the bytes", "noise"],
)
def test_bytes_that_are_no_joint_state_are_refused(data):
    with pytest.raises(BadMessage, match="not a JointState"):
        JointStateReader()(data)
    assert joint_state_places(data) is None


def test_a_joint_message_publishes_rclpy_s_bytes_and_a_reader_reads_them_back():
    """JointMessage.fill's bytes, exchange after exchange of one layout, are what rclpy serializes for the same
    message, up to the alignment bytes: the reader's view and rclpy's deserialization agree bit for bit."""
    message, read = JointMessage(), JointStateReader()
    for step in range(3):
        samples = ([0.02 * step + 0.00125 * k for k in range(17)], [100.0 + step + k for k in range(17)])
        data = message.fill(
            20_000_000 * step, ("crank", "slider"), [0.1, 0.2], [100.0, math.nan], [4.0, 5.0],
            (("crank_corrected", "velocity", samples), ("crank_predicted", "velocity", samples)),
        )  # fmt: skip
        assert isinstance(data, bytes)
        view = read(data)
        assert same_message(view, deserialize_message(data, JointState))
        assert step == 0 or isinstance(view, JointStateView)
        assert list(view.velocity[2:19]) == samples[1] and list(view.effort[2:19]) == samples[0]
