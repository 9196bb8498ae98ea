"""ros2: specs, the vstig_msgs CDR against rclpy's own serializer, and what the write topic's framing makes.

Nothing here starts a ROS 2 node (no DDS traffic): rclpy serializes without one.
The link against a real ROS 2 node in another process: tests/cli/test_ros2.py.
"""

from __future__ import annotations

import os
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vstig_hw.auth import Tagged
from vstig_hw.extras import missing
from vstig_hw.framing.ros2 import (
    TAGGED_CDR_SIZE,
    Ros2Framing,
    Ros2Sample,
    cdr_message,
    cdr_tagged,
    message_of_cdr,
    ros_name,
    sender_of_wire,
    tagged_of_cdr,
    wire_sender,
)
from vstig_hw.links import parse
from vstig_hw.links.ros2 import Ros2Spec
from vstig_hw.wire import Message, Op


def test_spec_defaults_and_every_key() -> None:
    spec = parse("ros2:lab")
    assert isinstance(spec, Ros2Spec)
    assert (spec.name, spec.full_namespace, spec.domain, spec.discovery, spec.reliable, spec.depth,
            spec.write_rate) == ("ros2-lab", "/vstig/lab", None, "localhost", True, 100, 500)
    assert parse("ros2:lab?stigmergy=2").full_namespace == "/vstig/lab/stigmergy2"  # type: ignore[attr-defined]
    spec = parse("ros2:lab?namespace=/arena/one&domain=7&discovery=subnet&qos=best_effort&depth=10&write_rate=50"
                 "&profile=dds.xml")
    assert isinstance(spec, Ros2Spec)
    assert (spec.full_namespace, spec.domain, spec.discovery, spec.reliable, spec.depth, spec.write_rate,
            spec.profile) == ("/arena/one", 7, "subnet", False, 10, 50, "dds.xml")


@pytest.mark.parametrize(("spec", "names"), [
    ("ros2:1lab", "swarm name '1lab'"),
    ("ros2:la-b", "swarm name 'la-b'"),
    ("ros2:lab?namespace=vstig", "namespace='vstig'"),
    ("ros2:lab?namespace=/a//b", "namespace='/a//b'"),
    ("ros2:lab?domain=233", "domain=233 is outside 0..232"),
    ("ros2:lab?discovery=lan", "discovery='lan'"),
    ("ros2:lab?qos=fast", "qos='fast'"),
    ("ros2:lab?depth=0", "depth=0 is outside 1..10000"),
    ("ros2:lab?write_rate=x", "write_rate='x' is not an integer"),
    ("ros2:lab?domains=1", "unknown parameter 'domains=1'"),
])
def test_a_bad_ros2_spec_is_one_line_naming_the_bad_part(spec: str, names: str) -> None:
    with pytest.raises(ValueError, match="bad link spec") as error:
        parse(spec)
    assert names in str(error.value) and "\n" not in str(error.value)


def test_link_names_become_ros_name_tokens() -> None:
    assert [ros_name(n) for n in ("can0", "ttyUSB0", "zenoh-lab", "0", "")] == \
        ["can0", "ttyUSB0", "zenoh_lab", "link_0", "link"]


def test_the_write_topic_framing_stamps_a_put_with_timestamp_0_after_the_gateways_entry() -> None:
    framing = Ros2Framing(200)
    assert framing.feed(Ros2Sample(cdr_message(Message(Op.PUT, 9, 99, 0, 300), None))) == \
        [Message(Op.PUT, 9, 99, 0, 300)]  # no table to stamp from: as written (the engine refuses it: invalid)
    framing.stamp = {9: 41}.get  # type: ignore[assignment]
    assert framing.feed(Ros2Sample(cdr_message(Message(Op.PUT, 9, 99, 0, 300), None))) == \
        [Message(Op.PUT, 9, 99, 41, 300)]
    assert framing.feed(Ros2Sample(cdr_message(Message(Op.PUT, 9, 99, 5, 300), None))) == \
        [Message(Op.PUT, 9, 99, 5, 300)]  # a writer that keeps its own clock keeps it
    assert framing.feed(Ros2Sample(cdr_message(Message(Op.GET, 9, 0, 0, 300), None))) == \
        [Message(Op.GET, 9, 0, 0, 300)]  # an empty GET asks every holder
    assert framing.encode(Message(Op.PUT, 1, 2, 3, 4)) == [Ros2Sample(cdr_message(Message(Op.PUT, 1, 2, 3, 4), 200))]


@pytest.mark.parametrize("payload", [b"", b"\x00\x01\x00\x00", b"\x00\x00\x00\x00" + bytes(16),  # big-endian CDR
                                     cdr_message(Message(Op.PUT, 1, 2, 3, 4), None)[:-1],
                                     b"\x00\x01\x00\x00\x02" + bytes(15)])  # op 2
def test_what_is_not_a_vstig_message_is_dropped_and_counted(payload: bytes) -> None:
    framing = Ros2Framing(200)
    assert framing.feed(Ros2Sample(payload)) == []
    assert framing.drops == {"bad_cdr": 1}


def test_a_tagged_write_is_taken_as_written_and_a_broken_one_counted() -> None:
    """Its tag covers its timestamp: a tagged PUT with timestamp 0 is not stamped (the gateway's policy judges it);
    with auth off the link takes its message without the tag."""
    framing = Ros2Framing(200)
    framing.stamp = lambda key: 6
    record = Tagged(Message(Op.PUT, 9, 99, 0, 300), 2, bytes(range(8)))
    sample = Ros2Sample(cdr_tagged(record, None))
    assert framing.feed_tagged(sample) == [(record.message, record)] and framing.feed(sample) == [record.message]
    assert framing.encode_tagged([record]) == [Ros2Sample(cdr_tagged(record, 200))]
    for broken in (sample.payload[:4] + bytes([2]) + sample.payload[5:],  # an op neither PUT nor GET
                   b"\x00\x00\x00\x00" + sample.payload[4:]):  # big-endian CDR
        assert framing.feed_tagged(Ros2Sample(broken)) == [] and framing.feed(Ros2Sample(broken)) == []
    assert framing.drops == {"bad_cdr": 4} and len(sample.payload) == TAGGED_CDR_SIZE


ros2 = pytest.mark.skipif(bool(missing(["rclpy"])) and os.environ.get("VSTIG_REQUIRE_PEERS") != "1",
                          reason="the ros2 extra is not installed (pip install 'vstig-hw[ros2]')")


@pytest.fixture(scope="module")
def types() -> Any:
    import rclpy.serialization  # noqa: F401  (loaded once here: the first import takes longer than a deadline)

    from vstig_hw import ros2msgs

    return ros2msgs.load()


@ros2
@given(op=st.sampled_from(Op), key=st.integers(0, 0x7FFF), value=st.integers(0, 0xFFFF),
       timestamp=st.integers(0, 0xFFFF), robot=st.integers(0, 0xFFFF),
       sender=st.none() | st.integers(0, 0xFFFF) | st.integers(0, (1 << 64) - 2))  # CAN ids; XBee addresses
def test_our_cdr_is_what_rclpy_serializes_and_reads_back(types: Any, op: Op, key: int, value: int, timestamp: int,
                                                         robot: int, sender: int | None) -> None:
    """Every sender from CAN ids to 64-bit XBee addresses (all ones is the broadcast address, never a sender: as
    -1 on the wire, it would read back as none)."""
    from rclpy.serialization import deserialize_message, serialize_message

    message = Message(op, key, value, timestamp, robot)
    theirs = types.msg.Message(op=int(op), key=key, value=value, timestamp=timestamp, robot=robot,
                               sender=wire_sender(sender))
    ours = cdr_message(message, sender)
    assert deserialize_message(ours, types.msg.Message) == theirs
    decoded = message_of_cdr(serialize_message(theirs))
    assert decoded is not None and decoded[0] == message and sender_of_wire(decoded[1]) == sender


@ros2
@given(op=st.sampled_from(Op), key=st.integers(0, 0x7FFF), words=st.tuples(*[st.integers(0, 0xFFFF)] * 3),
       epoch=st.integers(0, 0xFFFFFFFF), tag=st.binary(min_size=8, max_size=8),
       sender=st.none() | st.integers(0, (1 << 64) - 2))
def test_our_tagged_cdr_is_what_rclpy_serializes_and_reads_back(types: Any, op: Op, key: int,
                                                                words: tuple[int, int, int], epoch: int, tag: bytes,
                                                                sender: int | None) -> None:
    from rclpy.serialization import deserialize_message, serialize_message

    record = Tagged(Message(op, key, *words), epoch, tag)
    theirs = types.msg.TaggedMessage(op=int(op), key=key, value=words[0], timestamp=words[1], robot=words[2],
                                     sender=wire_sender(sender), epoch=epoch, tag=list(tag))
    assert deserialize_message(cdr_tagged(record, sender), types.msg.TaggedMessage) == theirs
    decoded = tagged_of_cdr(serialize_message(theirs))
    assert decoded is not None and decoded[0] == record and sender_of_wire(decoded[1]) == sender


@ros2
def test_the_interfaces_are_the_idl_and_message_is_our_captures_schema(types: Any) -> None:
    from vstig_hw.capture.rosbag import MSGDEF

    fields = types.msg.Message.get_fields_and_field_types()
    declared = [line.split() for line in MSGDEF.splitlines() if line and not line.startswith("#") and "=" not in line]
    assert list(fields.items()) == [(name, kind) for kind, name in declared]
    assert (types.msg.Message.PUT, types.msg.Message.GET) == (0, 1)
    assert list(types.msg.Change.get_fields_and_field_types()) == \
        ["key", "has_old", "old_entry", "new_entry", "link", "sender"]
    assert list(types.srv.Put.Response.get_fields_and_field_types()) == ["taken", "entry", "reason"]
    assert list(types.srv.Table.Response.get_fields_and_field_types()) == ["entries"]
