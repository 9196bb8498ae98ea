"""The Wireshark dissector on tagged units (SPEC.md 10.5), run by real tshark over captures made from the spec's
vectors: CAN FD frames of one record, XBee API frames of 0xA1 || N records, MAVLink TUNNELs of payload_type 46450.
Every record's fields equal the vector's; a malformed tagged unit on each link is flagged, never a Lua error."""

from __future__ import annotations

from pathlib import Path

import can
from conftest import load
from pymavlink.dialects.v20 import common as mav2  # type: ignore[import-untyped]
from test_spec_tshark import frames_through_tshark, tshark_fields

from vstig_hw.auth import RECORD_SIZE, decode_record
from vstig_hw.capture.pcap import PcapWriter
from vstig_hw.framing.xbee import api_frame, receive_packet, transmit_request

AUTH = load("auth.json")
MAVLINK = load("mavlink.json")
RECORD_FIELDS = ["vstig.op", "vstig.key", "vstig.value", "vstig.timestamp", "vstig.robot", "vstig.epoch",
                 "vstig.tag"]
EXPERT = "_ws.expert.message"
SOURCE = 0x0013A20040A1B2C3  # an XBee's 64-bit address
TAGGED_TYPE = int(MAVLINK["payload_type_tagged"])

# Each `tags` vector's record -> the fields tshark should show for it, as the vector gives them.
VECTOR_FIELDS = {vector["record"]: [str(int(vector["fields"]["op"] == "GET")), str(vector["fields"]["key"]),
                                    str(vector["fields"]["value"]), str(vector["fields"]["timestamp"]),
                                    str(vector["fields"]["robot"]), str(vector["epoch"]), vector["tag"]]
                 for vector in AUTH["tags"]}
TAG_RECORDS = [bytes.fromhex(record) for record in VECTOR_FIELDS]


def _fields_of(record: bytes) -> list[str]:
    """The vector's fields of a `tags` record; our decoder's for the others (an empty GET's, SPEC.md 10.2)."""
    if record.hex() in VECTOR_FIELDS:
        return VECTOR_FIELDS[record.hex()]
    msg, epoch, tag = decode_record(record)
    return [str(msg[0] >> 15), str(msg[0] & 0x7FFF), str(msg[1]), str(msg[2]), str(msg[3]), str(epoch), tag.hex()]


def _columns(records: list[bytes]) -> list[str]:
    """RECORD_FIELDS' columns for these records, each occurrence joined by commas as tshark shows them."""
    return [",".join(column) for column in zip(*map(_fields_of, records), strict=True)]


def _records(data: bytes) -> list[bytes]:
    return [data[i:i + RECORD_SIZE] for i in range(0, len(data), RECORD_SIZE)]


# -- CAN FD: one record per frame of data length 20 (DLC 11), under the IDs of 6.5.2 and 6.5.3 ------------------------

CAN_FIELDS = ["vstig.sender", "vstig.count", *RECORD_FIELDS, EXPERT]


def _can_pcap(path: Path, frames: list[can.Message]) -> Path:
    with PcapWriter(path) as writer:
        for i, frame in enumerate(frames):
            frame.timestamp = 1_700_000_000 + i / 1000
            writer.on_message_received(frame)
    return path


def test_can_fd_records(tmp_path: Path) -> None:
    framed = AUTH["framed"]["can_fd"]
    frames = [can.Message(arbitration_id=int(framed["id_11bit"], 16), is_extended_id=False, is_fd=True,
                          data=bytes.fromhex(framed["data"]))]
    for record in TAG_RECORDS:  # each under its op's ID, 11-bit and 29-bit (stigmergy 5), sent by node 0x2A
        op = record[0] >> 7
        frames.append(can.Message(arbitration_id=0x600 | op << 8 | 0x2A, is_extended_id=False, is_fd=True,
                                  data=record))
        frames.append(can.Message(arbitration_id=0x18000000 | 5 << 17 | op << 16 | 0x2A, is_extended_id=True,
                                  is_fd=True, data=record))
    rows = tshark_fields(_can_pcap(tmp_path / "tagged.pcap", frames), CAN_FIELDS)
    assert len(rows) == len(frames) == 1 + 2 * len(TAG_RECORDS)
    for frame, row in zip(frames, rows, strict=True):
        assert row == ["0x002a", "1", *_columns([bytes(frame.data)]), ""], frame


def test_can_fd_malformed_records(tmp_path: Path) -> None:
    record = bytes.fromhex(AUTH["framed"]["can_fd"]["data"])  # a PUT
    frames = [can.Message(arbitration_id=0x62A, is_extended_id=False, is_fd=True, data=record[:12]),  # cut: DLC 9
              can.Message(arbitration_id=0x72A, is_extended_id=False, is_fd=True, data=record)]  # under a GET ID
    rows = tshark_fields(_can_pcap(tmp_path / "bad.pcap", frames), ["vstig.key", "vstig.epoch", EXPERT])
    assert rows == [["", "", "length is neither 1, 2, 3, 4, 6 or 8 messages nor one 20-byte record (dropped)"],
                    ["258", "0", "op bit differs from the ID's op (dropped by receivers)"]]


# -- XBee: RF data 0xA1 || N records, in Receive Packets and Transmit Requests, either API mode ------------------------

XBEE_FIELDS = ["vstig_xbee.frame_type", "vstig_xbee.tagged_marker", "vstig.xbee_sender", *RECORD_FIELDS, EXPERT]


def test_xbee_records(tmp_path: Path) -> None:
    batch = bytes.fromhex(AUTH["framed"]["batch"]["data"])
    every = bytes([batch[0]]) + b"".join(TAG_RECORDS)  # 6 records: 121 bytes of RF data
    frames = [api_frame(receive_packet(SOURCE, batch)), api_frame(transmit_request(1, batch), escaped=True),
              api_frame(receive_packet(SOURCE, every), escaped=True), api_frame(transmit_request(0, every))]
    rows = frames_through_tshark(tmp_path, frames, 147, XBEE_FIELDS)
    assert len(_records(batch[1:])) == AUTH["framed"]["batch"]["records"]
    for rf_data, kind, row in zip((batch, batch, every, every), (0x90, 0x10, 0x90, 0x10), rows, strict=True):
        records = _records(rf_data[1:])
        sender = ",".join([f"0x{SOURCE:016x}"] * len(records)) if kind == 0x90 else ""
        assert row == [f"0x{kind:02x}", "0xa1", sender, *_columns(records), ""]


def test_xbee_malformed_records(tmp_path: Path) -> None:
    batch = bytes.fromhex(AUTH["framed"]["batch"]["data"])
    # Cut by 2 bytes (by 1 it is 40 bytes: five untagged messages, SPEC.md 10.5), the marker alone, garbage.
    cut, marker_only, garbage = batch[:-2], batch[:1], bytes.fromhex("a1") + bytes(range(1, 20))
    frames = [api_frame(receive_packet(SOURCE, rf_data)) for rf_data in (cut, marker_only, garbage)]
    rows = frames_through_tshark(tmp_path, frames, 147, ["vstig_xbee.tagged_marker", "vstig.key", EXPERT])
    assert rows == [["0xa1", "", "RF data 0xA1 is not followed by whole 20-byte records (dropped)"]] * 3


# -- MAVLink: TUNNELs of payload_type 46450, payload = N records, 1 <= N <= 6 ----------------------------------------

MAVLINK_FIELDS = ["vstig_mavlink.payload_type", "vstig.mavlink_sender", *RECORD_FIELDS, EXPERT]


class _Sink:
    def write(self, data: bytes) -> None:
        pass


def _tunnel(payload_type: int, payload_length: int, data: bytes) -> bytes:
    """A TUNNEL from system 9, component 1, as pymavlink writes it."""
    theirs = mav2.MAVLink(_Sink(), srcSystem=9, srcComponent=1)
    return bytes(mav2.MAVLink_tunnel_message(0, 0, payload_type, payload_length,
                                             list(data) + [0] * (128 - len(data))).pack(theirs))


def test_mavlink_records(tmp_path: Path) -> None:
    six = b"".join(TAG_RECORDS)
    cases = [(bytes.fromhex(vector["wire"]), vector["sysid"] << 8 | vector["compid"],
              [bytes.fromhex(record) for record in vector["records"]]) for vector in MAVLINK["transmit_tagged"]]
    cases.append((_tunnel(TAGGED_TYPE, len(six), six), 9 << 8 | 1, TAG_RECORDS))
    assert TAGGED_TYPE == int(AUTH["framed"]["mavlink"]["payload_type"], 16) == 46450
    rows = frames_through_tshark(tmp_path, [wire for wire, _, _ in cases], 148, MAVLINK_FIELDS)
    for (_, sender, records), row in zip(cases, rows, strict=True):
        assert row == [str(TAGGED_TYPE), ",".join([str(sender)] * len(records)), *_columns(records), ""]


def test_mavlink_malformed_records(tmp_path: Path) -> None:
    not_whole = next(s for s in MAVLINK["streams"] if s["name"] == "a tagged TUNNEL that is not whole records")
    assert not_whole["drops"] == {"bad_length": 2}
    seven = b"".join(TAG_RECORDS) + TAG_RECORDS[0][:8]
    frames = [bytes.fromhex(not_whole["stream"]),  # two TUNNELs, payload_length 28 and 8
              _tunnel(TAGGED_TYPE, 140, seven), _tunnel(TAGGED_TYPE, 0, b""),
              _tunnel(TAGGED_TYPE, 20, TAG_RECORDS[0])[:-5]]  # cut short
    rows = frames_through_tshark(tmp_path, frames, 148, ["vstig.key", EXPERT])
    bad = "payload_length is not 1 to 6 whole 20-byte records (dropped)"
    assert rows == [["", f"{bad},{bad}"], ["", bad], ["", bad], ["", "not a whole MAVLink 2 frame (dropped)"]]
