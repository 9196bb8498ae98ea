"""The Wireshark dissector on MAVLink TUNNELs (SPEC.md 6.10), run by real tshark over a pcap that text2pcap makes
from frames pymavlink and our framing wrote: every field it shows equals what the framing reads."""

from __future__ import annotations

from pathlib import Path

from pymavlink.dialects.v20 import common as mav2
from test_spec_tshark import frames_through_tshark

from vstig_hw.framing.mavlink import PAYLOAD_TYPE, MavlinkFraming, Signing
from vstig_hw.wire import Message, Op

FIELDS = ["vstig_mavlink.sysid", "vstig_mavlink.signed", "vstig.mavlink_sender", "vstig.op", "vstig.key",
          "vstig.value", "vstig.timestamp", "vstig.robot", "_ws.expert.message", "vstig_mavlink.link_id",
          "vstig_mavlink.signing_timestamp", "vstig_mavlink.signature"]


class _Sink:
    def write(self, data: bytes) -> None:
        pass


def _frames() -> list[bytes]:
    msgs = [Message(Op(k % 2), k, k * 7, k, 3) for k in range(1, 21)]
    ours = MavlinkFraming(12).encode_batch(msgs) + MavlinkFraming(13, signing=Signing(bytes(32))).encode_batch(msgs[:3])
    theirs = mav2.MAVLink(_Sink(), srcSystem=9, srcComponent=1)
    data = b"".join(bytes.fromhex(f"{m[0]:04x}{m[1]:04x}{m[2]:04x}{m[3]:04x}") for m in msgs[:2])
    tunnel = bytes(mav2.MAVLink_tunnel_message(0, 0, PAYLOAD_TYPE, len(data), list(data) + [0] * 112).pack(theirs))
    other = bytes(mav2.MAVLink_tunnel_message(0, 0, PAYLOAD_TYPE - 1, 2, [1, 2] + [0] * 126).pack(theirs))
    beat = bytes(mav2.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(theirs))
    bad_crc = bytearray(tunnel)
    bad_crc[15] ^= 1
    odd = bytes(mav2.MAVLink_tunnel_message(0, 0, PAYLOAD_TYPE, 7, list(range(7)) + [0] * 121).pack(theirs))
    return [*ours, tunnel, other, beat, bytes(bad_crc), odd]


def _expected(frame: bytes) -> list[str]:
    framing = MavlinkFraming(255)
    msgs = framing.feed(frame)
    sender = framing.sender_of(frame)
    col = lambda values: ",".join(str(v) for v in values)  # noqa: E731
    expert = ""
    if framing.drops["bad_length"]:
        expert = "payload_length is not 1 to 16 whole messages (dropped)"
    elif frame[7:10] == (385).to_bytes(3, "little") and not msgs and not framing.drops["other_payload_type"]:
        expert = "crc does not match (dropped)"
    signing = ["", "", ""]
    if frame[2] & 1:  # the signature block after the crc: link_id, timestamp (u48 LE), signature (SPEC.md 6.10.1)
        block = frame[12 + frame[1]:]
        signing = [str(block[0]), str(int.from_bytes(block[1:7], "little")), block[7:13].hex()]
    return [str(frame[5]), str(frame[2] & 1), col(sender for _ in msgs), col(int(m.op) for m in msgs),
            col(m.key for m in msgs), col(m.value for m in msgs), col(m.timestamp for m in msgs),
            col(m.robot for m in msgs), expert, *signing]


def test_mavlink_frames_from_a_capture(tmp_path: Path) -> None:
    frames = _frames()
    rows = frames_through_tshark(tmp_path, frames, 148, FIELDS)
    for frame, row in zip(frames, rows, strict=True):
        row[1] = {"True": "1", "False": "0"}.get(row[1], row[1])
        assert row == _expected(frame), frame.hex()
