"""vstig_hw.auth against vectors/auth.json (SPEC.md section 10): robot keys, tags, records, verdicts, order."""

from __future__ import annotations

from typing import Any

import pytest
from conftest import load

from vstig_hw.auth import (
    BATCH_MARKER,
    RECORD_SIZE,
    SwarmKeys,
    Tagged,
    decode_batch,
    decode_record,
    encode_batch,
    encode_record,
    entry_tag,
    next_epoch,
    robot_key,
    tagged_newer,
)
from vstig_hw.counters import Counters
from vstig_hw.framing.cobsframe import CobsFrameReader, encode_frame
from vstig_hw.wire import DecodeError, decode

VECTORS = load("auth.json")
MASTER = bytes.fromhex(VECTORS["master"])


@pytest.mark.parametrize("case", VECTORS["robot_keys"], ids=lambda c: str(c["robot"]))
def test_robot_keys(case: dict[str, Any]) -> None:
    assert robot_key(MASTER, case["robot"]).hex() == case["key"]
    assert SwarmKeys(MASTER).key_of(case["robot"]).hex() == case["key"]


@pytest.mark.parametrize("case", VECTORS["tags"], ids=lambda c: c["name"])
def test_tags_and_records(case: dict[str, Any]) -> None:
    msg = decode(bytes.fromhex(case["message"]))
    key = robot_key(MASTER, case["signer"])
    assert entry_tag(key, case["stigmergy"], msg, case["epoch"]).hex() == case["tag"]
    tagged = SwarmKeys(MASTER, case["stigmergy"]).tag(msg, case["epoch"])
    assert encode_record(tagged).hex() == case["record"]
    assert decode_record(bytes.fromhex(case["record"])) == tagged


@pytest.mark.parametrize("case", VECTORS["verify"], ids=lambda c: c["name"])
def test_verdicts(case: dict[str, Any]) -> None:
    tagged = decode_record(bytes.fromhex(case["record"]))
    assert SwarmKeys(MASTER, case["stigmergy"]).verify(tagged) is (case["verdict"] == "good")


def test_order_closes_the_wraparound_replay() -> None:
    for case in VECTORS["order"]:
        assert tagged_newer(*case["a"], *case["b"]) is case["a_is_newer"], case["why"]


def test_epoch_advances_only_at_the_wrap() -> None:
    for case in VECTORS["epochs"]:
        assert next_epoch(case["epoch"], case["timestamp"], case["next_timestamp"]) == case["next_epoch"], case["why"]


def test_cobs8_frame_of_a_record_and_an_empty_get() -> None:
    for name in ("cobs8", "cobs8_get_empty"):
        framed = VECTORS["framed"][name]
        record = bytes.fromhex(framed["record"])
        assert encode_frame(record).hex() == framed["frame"]
        reader = CobsFrameReader(RECORD_SIZE, Counters())
        assert reader.feed(bytes.fromhex(framed["frame"])) == [record]


def test_batches_and_their_refusals() -> None:
    batch = VECTORS["framed"]["batch"]
    data = bytes.fromhex(batch["data"])
    records = decode_batch(data)
    assert len(records) == batch["records"] and int(batch["marker"], 16) == BATCH_MARKER
    assert encode_batch(records) == data
    for bad in (data[:-1], data[1:], b"\xa0" + data[1:], data[:1], b""):
        with pytest.raises(DecodeError, match="tagged batch"):
            decode_batch(bad)
    with pytest.raises(DecodeError, match="exactly 20 bytes"):
        decode_record(data[1:20])


def test_can_fd_and_mavlink_carry_the_record_as_is() -> None:
    framed = VECTORS["framed"]
    record = bytes.fromhex(framed["cobs8"]["record"])
    assert bytes.fromhex(framed["can_fd"]["data"]) == record and framed["can_fd"]["length"] == RECORD_SIZE
    assert bytes.fromhex(framed["mavlink"]["payload"]) == record


def test_a_master_of_the_wrong_size_is_refused() -> None:
    with pytest.raises(ValueError, match="32 bytes, got 31"):
        SwarmKeys(MASTER[:31])


def test_the_tag_is_the_entrys_not_the_messages() -> None:
    keys = SwarmKeys(MASTER)
    put = decode(bytes.fromhex("0102abcd8000002a"))
    get = decode(bytes.fromhex("8102abcd8000002a"))
    assert keys.tag(put, 0).tag == keys.tag(get, 0).tag
    assert keys.verify(Tagged(get, 0, keys.tag(put, 0).tag))
