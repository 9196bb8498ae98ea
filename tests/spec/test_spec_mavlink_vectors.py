"""vectors/mavlink.json (SPEC.md 6.10) against the Python framing and against pymavlink, MAVLink's own library."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from conftest import SPEC, VECTORS, load

from vstig_hw.auth import decode_record, encode_record
from vstig_hw.counters import Counters
from vstig_hw.framing.mavlink import MavlinkFraming, MavlinkStreamReader, Signing
from vstig_hw.wire import decode_many, encode

VECTORS_OF = load("mavlink.json")


def test_the_generator_reproduces_mavlink_json(tmp_path: Path) -> None:
    subprocess.run([sys.executable, "-I", "-S", str(SPEC / "tools" / "mavlink_vectors.py"), str(tmp_path)],
                   check=True, timeout=60)
    assert (tmp_path / "mavlink.json").read_text() == (VECTORS / "mavlink.json").read_text()


def _signing(key: str | None, link_id: int = 0, timestamp: int = 0) -> Signing | None:
    if key is None:
        return None
    signing = Signing(bytes.fromhex(key), link_id, clock=lambda: 0.0)  # 2015 is long past: the stamp below wins
    signing._sent = timestamp - 1
    return signing


@pytest.mark.parametrize("case", VECTORS_OF["transmit"], ids=lambda c: c["name"])
def test_transmit(case: dict[str, Any]) -> None:
    framing = MavlinkFraming(case["sysid"], case["compid"], target=case["target"],
                             signing=_signing(case["key"], case["link_id"], case["timestamp"]))
    messages = decode_many(bytes.fromhex("".join(case["messages"])))
    assert framing.encode_batch(messages) == [bytes.fromhex(case["wire"])]


@pytest.mark.parametrize("case", VECTORS_OF["transmit"], ids=lambda c: c["name"])
def test_pymavlink_reads_every_transmit_vector(case: dict[str, Any]) -> None:
    from pymavlink.dialects.v20 import common as mav2

    parser = mav2.MAVLink(None)
    if case["key"] is not None:
        parser.signing.secret_key = bytes.fromhex(case["key"])
    (msg,) = parser.parse_buffer(bytes.fromhex(case["wire"]))
    assert (msg.get_type(), msg.get_srcSystem(), msg.get_srcComponent()) == ("TUNNEL", case["sysid"], case["compid"])
    assert msg.payload_type == VECTORS_OF["payload_type"] and msg.get_signed() == (case["key"] is not None)
    assert bytes(msg.payload[:msg.payload_length]).hex() == "".join(case["messages"])


@pytest.mark.parametrize("case", VECTORS_OF["transmit_tagged"], ids=lambda c: c["name"])
def test_transmit_tagged_and_pymavlink_reads_it(case: dict[str, Any]) -> None:
    from pymavlink.dialects.v20 import common as mav2

    framing = MavlinkFraming(case["sysid"], case["compid"], target=case["target"],
                             signing=_signing(case["key"], case["link_id"], case["timestamp"]))
    records = [decode_record(bytes.fromhex(record)) for record in case["records"]]
    assert framing.encode_tagged(records) == [bytes.fromhex(case["wire"])]
    parser = mav2.MAVLink(None)
    if case["key"] is not None:
        parser.signing.secret_key = bytes.fromhex(case["key"])
    (msg,) = parser.parse_buffer(bytes.fromhex(case["wire"]))
    assert (msg.get_type(), msg.payload_type) == ("TUNNEL", VECTORS_OF["payload_type_tagged"])
    assert bytes(msg.payload[:msg.payload_length]).hex() == "".join(case["records"])


def test_seven_records_take_two_tunnels_and_come_back_whole() -> None:
    records = [decode_record(bytes.fromhex(record)) for record in VECTORS_OF["transmit_tagged"][1]["records"]] + \
        [decode_record(bytes.fromhex(VECTORS_OF["transmit_tagged"][0]["records"][1]))]
    sender, receiver = MavlinkFraming(1), MavlinkFraming(4)
    units = sender.encode_tagged(records)
    assert len(units) == 2 and [unit[4] for unit in units] == [0, 1]  # one sequence for every frame
    assert [record for unit in units for _, record in receiver.feed_tagged(unit)] == records
    assert [msg for unit in units for msg in receiver.feed(unit)] == [record.message for record in records]
    assert not receiver.drops


def test_heartbeat() -> None:
    from pymavlink.dialects.v20 import common as mav2

    beat = VECTORS_OF["heartbeat"]
    assert MavlinkFraming(beat["sysid"], beat["compid"]).heartbeat().hex() == beat["wire"]
    (msg,) = mav2.MAVLink(None).parse_buffer(bytes.fromhex(beat["wire"]))
    assert (msg.type, msg.autopilot) == (mav2.MAV_TYPE_ONBOARD_CONTROLLER, mav2.MAV_AUTOPILOT_INVALID)


def _read(case: dict[str, Any], chunks: list[bytes]) -> tuple[list[dict[str, object]], dict[str, int]]:
    """What a link does: its transport's reader cuts frames, its framing takes them."""
    receiver = VECTORS_OF["receiver"]
    framing = MavlinkFraming(receiver["sysid"], receiver["compid"], signing=_signing(case["key"]))
    drops = Counters()
    reader = MavlinkStreamReader(drops)
    frames: list[dict[str, object]] = []
    cut = [frame for chunk in chunks for frame in reader.feed(chunk)] + reader.flush()
    for unit in cut:
        heard = framing.feed_tagged(unit)
        if heard:
            sender = framing.sender_of(unit)
            assert sender is not None
            frames.append({"sender": f"{sender >> 8}/{sender & 0xFF}", "messages": [encode(m).hex() for m, _ in heard]}
                          | ({"records": [encode_record(r).hex() for _, r in heard if r]} if heard[0][1] else {}))
            assert [m for m, _ in heard] == MavlinkFraming(4, 191).feed(unit)  # auth off: the same messages
    drops.update(framing.drops)
    return frames, dict(drops)


@pytest.mark.parametrize("case", VECTORS_OF["streams"], ids=lambda c: c["name"])
def test_streams(case: dict[str, Any]) -> None:
    stream = bytes.fromhex(case["stream"])
    for chunks in ([stream], [stream[i:i + 1] for i in range(len(stream))]):
        assert _read(case, chunks) == (case["frames"], case["drops"])
