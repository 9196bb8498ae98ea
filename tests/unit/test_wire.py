"""The 8-byte codec: layout, ranges, errors, and the struct fast path equal to the schema."""

from __future__ import annotations

import pickle
import subprocess
import sys

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vstig_hw import DecodeError, Message, Op, decode, encode
from vstig_hw.wire import decode_many, decode_schema, encode_schema

messages = st.builds(
    Message,
    st.sampled_from(Op),
    st.integers(0, 0x7FFF),
    st.integers(0, 0xFFFF),
    st.integers(0, 0xFFFF),
    st.integers(0, 0xFFFF),
)

# Worked by hand from the layout: op bit, 15-bit key, then three big-endian u16.
FIXED = [
    (Message(Op.PUT, 0, 0, 0, 0), "0000000000000000"),
    (Message(Op.GET, 0, 0, 0, 0), "8000000000000000"),
    (Message(Op.PUT, 0x7FFF, 0xFFFF, 0xFFFF, 0xFFFF), "7fffffffffffffff"),
    (Message(Op.GET, 0x7FFF, 0xFFFF, 0xFFFF, 0xFFFF), "ffffffffffffffff"),
    (Message(Op.PUT, 1, 0x1234, 1, 42), "0001123400010 02a".replace(" ", "")),
    (Message(Op.GET, 0x0102, 0xABCD, 0x8000, 0x00FF), "8102abcd800000ff"),
]


@pytest.mark.parametrize(("msg", "hexbytes"), FIXED)
def test_fixed_vectors_both_paths(msg: Message, hexbytes: str) -> None:
    raw = bytes.fromhex(hexbytes)
    assert encode(msg) == raw
    assert encode_schema(msg) == raw
    assert decode(raw) == msg
    assert decode_schema(raw) == msg


@given(messages)
def test_fast_path_equals_schema_on_messages(msg: Message) -> None:
    assert encode(msg) == encode_schema(msg)
    assert decode(encode(msg)) == msg


@given(st.binary(min_size=8, max_size=8))
def test_fast_path_equals_schema_on_bytes(raw: bytes) -> None:
    assert decode(raw) == decode_schema(raw)
    assert encode(decode(raw)) == raw


def test_fields_read_by_name() -> None:
    msg = decode(bytes.fromhex("8102abcd800000ff"))
    assert (msg.op, msg.key, msg.value, msg.timestamp, msg.robot) == (Op.GET, 0x102, 0xABCD, 0x8000, 0xFF)
    assert msg.op is Op.GET
    match msg:
        case Message(Op.GET, key, _, ts, _):
            assert (key, ts) == (0x102, 0x8000)
        case _:
            pytest.fail("pattern matching by field did not match")


def test_immutable_hashable_picklable() -> None:
    msg = Message(Op.PUT, 5, 6, 7, 8)
    with pytest.raises(AttributeError):
        msg.key = 9  # type: ignore[misc]
    assert {msg: 1}[Message(Op.PUT, 5, 6, 7, 8)] == 1
    assert pickle.loads(pickle.dumps(msg)) == msg
    assert msg.replace(value=9) == Message(Op.PUT, 5, 9, 7, 8)
    assert repr(msg) == "Message(PUT, key=5, value=6, timestamp=7, robot=8)"


@pytest.mark.parametrize(
    ("args", "field", "limit"),
    [
        ((Op.PUT, 0x8000, 0, 1, 1), "key", "0..32767"),
        ((Op.PUT, -1, 0, 1, 1), "key", "0..32767"),
        ((Op.PUT, 1, 0x10000, 1, 1), "value", "0..65535"),
        ((Op.PUT, 1, 0, -5, 1), "timestamp", "0..65535"),
        ((Op.PUT, 1, 0, 1, 70000), "robot", "0..65535"),
        ((Op.PUT, 1, 0, 1.0, 1), "timestamp", "0..65535"),
        ((Op.PUT, True, 0, 1, 1), "key", "0..32767"),
    ],
)
def test_out_of_range_field_names_field_and_range(args: tuple, field: str, limit: str) -> None:
    with pytest.raises(ValueError, match=rf"^{field} must be an integer in {limit}"):
        Message(*args)


def test_bad_op_rejected() -> None:
    with pytest.raises(ValueError, match="op must be"):
        Message(2, 1, 1, 1, 1)


@pytest.mark.parametrize("length", [0, 1, 7, 9, 16])
def test_wrong_length_is_decode_error_naming_length(length: int) -> None:
    with pytest.raises(DecodeError, match=rf"got {length}$"):
        decode(bytes(length))
    assert issubclass(DecodeError, ValueError)


@given(st.binary(max_size=64))
def test_fuzz_decode_only_raises_decode_error(raw: bytes) -> None:
    try:
        msg = decode(raw)
    except DecodeError:
        assert len(raw) != 8
    else:
        assert len(raw) == 8 and encode(msg) == raw


@given(st.lists(messages, max_size=10))
def test_decode_many_round_trips(batch: list[Message]) -> None:
    assert list(decode_many(b"".join(map(encode, batch)))) == batch


def test_decode_many_rejects_partial_message() -> None:
    with pytest.raises(DecodeError, match="multiple of 8 bytes, got 12"):
        list(decode_many(bytes(12)))


def test_accepts_bytearray_and_memoryview() -> None:
    raw = bytes.fromhex("8102abcd800000ff")
    assert decode(bytearray(raw)) == decode(memoryview(raw)) == decode(raw)


def test_importing_the_package_does_not_load_construct() -> None:
    probe = "import sys, vstig_hw; print('construct' in sys.modules)"
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, check=True)
    assert done.stdout.strip() == "False"
