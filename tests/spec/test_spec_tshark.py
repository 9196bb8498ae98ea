"""The Wireshark dissector, run by real tshark over a pcap and a candump log that we write.

Every field tshark shows must equal our decoder: the wire codec on the payload and
the ID scheme (SPEC.md 6.5) on the arbitration ID.
"""

from __future__ import annotations

import random
import subprocess
from pathlib import Path

import can
from conftest import SPEC, can_id_fields, load, require_tool

from vstig_hw.capture.pcap import PcapWriter
from vstig_hw.wire import decode_many

LUA = SPEC / "wireshark" / "vstig.lua"
FIELDS = ["vstig.id_op", "vstig.sender", "vstig.stigmergy", "vstig.count",
          "vstig.op", "vstig.key", "vstig.value", "vstig.timestamp", "vstig.robot"]


def _frames() -> list[can.Message]:
    frames = [can.Message(arbitration_id=int(f["id"], 16), is_extended_id=f["extended"], data=bytes.fromhex(f["data"]))
              for f in load("can_frames.json")["frames"]]
    rng = random.Random(10)
    for _ in range(300):
        extended, op = rng.random() < 0.5, rng.randrange(2)
        can_id = (0x18000000 | rng.randrange(256) << 17 | op << 16 | rng.randrange(0x10000) if extended
                  else 0x600 | op << 8 | rng.randrange(256))
        count = rng.choice((1, 1, 1, 2, 3, 4, 6, 8))
        data = b"".join(bytes([op << 7 | rng.randrange(128)]) + rng.randbytes(7) for _ in range(count))
        frames.append(can.Message(arbitration_id=can_id, is_extended_id=extended, is_fd=count > 1, data=data))
    # Not ours: other 11-bit bases and 29-bit bases are left to other dissectors.
    frames.append(can.Message(arbitration_id=0x123, is_extended_id=False, data=bytes(8)))
    frames.append(can.Message(arbitration_id=0x0C000005, is_extended_id=True, data=bytes(8)))
    for i, frame in enumerate(frames):
        frame.timestamp = 1_700_000_000 + i / 1000
        frame.channel = "vcan0"
    return frames


def _expected(frame: can.Message) -> list[str]:
    ids = can_id_fields(frame.arbitration_id, frame.is_extended_id)
    ours = ids["base"] == (0x18000000 if frame.is_extended_id else 0x600)
    if not ours:
        return [""] * len(FIELDS)
    msgs = list(decode_many(bytes(frame.data)))
    column = lambda values: ",".join(str(v) for v in values)  # noqa: E731
    return [str(ids["op"]), f"0x{ids['sender']:04x}", str(ids["stigmergy"]), str(len(msgs)),
            column(int(m.op) for m in msgs), column(m.key for m in msgs), column(m.value for m in msgs),
            column(m.timestamp for m in msgs), column(m.robot for m in msgs)]


def tshark_fields(capture: Path, fields: list[str]) -> list[list[str]]:
    """The `fields` tshark shows for each packet of `capture` with our dissector, every occurrence joined by commas;
    no Lua error allowed."""
    tshark = require_tool("tshark")
    command = [tshark, "-X", f"lua_script:{LUA}", "-r", str(capture), "-T", "fields",
               "-E", "separator=/t", "-E", "occurrence=a", "-E", "aggregator=,"]
    for name in fields:
        command += ["-e", name]
    done = subprocess.run(command, capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    assert "Lua" not in done.stderr and "rror" not in done.stderr, done.stderr
    return [line.split("\t") for line in done.stdout.splitlines()]


def _compare(capture: Path, frames: list[can.Message]) -> None:
    rows = tshark_fields(capture, FIELDS)
    assert len(rows) == len(frames)
    for frame, row in zip(frames, rows, strict=True):
        assert row == _expected(frame), frame


def test_pcap(tmp_path: Path) -> None:
    require_tool("tshark")
    frames = _frames()
    path = tmp_path / "swarm.pcap"
    with PcapWriter(path) as writer:
        for frame in frames:
            writer.on_message_received(frame)
    _compare(path, frames)


def test_candump_log(tmp_path: Path) -> None:
    require_tool("tshark")
    frames = _frames()
    path = tmp_path / "swarm.log"
    with can.Logger(str(path)) as writer:  # python-can's own candump writer
        for frame in frames:
            writer.on_message_received(frame)
    # python-can ends each line with can-utils' direction flag (" R"/" T"), which
    # Wireshark 4.0's candump reader predates: strip it (SPEC.md says so too).
    text = path.read_text(encoding="utf-8")
    assert all(line.endswith((" R", " T")) for line in text.splitlines())
    path.write_text("".join(line[:-2] + "\n" for line in text.splitlines()), encoding="utf-8")
    _compare(path, frames)


def test_malformed_frames_are_flagged(tmp_path: Path) -> None:
    require_tool("tshark")
    frames = [can.Message(arbitration_id=0x605, is_extended_id=False, data=bytes.fromhex("8001002a00030005")),
              can.Message(arbitration_id=0x605, is_extended_id=False, data=bytes(7))]
    path = tmp_path / "bad.pcap"
    with PcapWriter(path) as writer:
        for frame in frames:
            writer.on_message_received(frame)
    assert tshark_fields(path, ["_ws.expert.message"]) == [
        ["op bit differs from the ID's op (dropped by receivers)"],
        ["length is neither 1, 2, 3, 4, 6 or 8 messages nor one 20-byte record (dropped)"]]


# -- XBee API frames (SPEC.md 6.9): one per packet of link type USER0, made by text2pcap as a user would ------------

XBEE_FIELDS = ["vstig_xbee.frame_type", "vstig_xbee.escaped", "vstig.xbee_sender", "vstig.op", "vstig.key",
               "vstig.value", "vstig.timestamp", "vstig.robot", "_ws.expert.message"]


def _xbee_frames() -> list[bytes]:
    """Receive Packets built by Digi's digi-xbee, Transmit Requests by our framing, in both API modes, and bad ones."""
    from digi.xbee.models.address import XBee16BitAddress, XBee64BitAddress
    from digi.xbee.models.mode import OperatingMode
    from digi.xbee.packets.common import ReceivePacket

    from vstig_hw import Message, Op, encode
    from vstig_hw.framing import make_serial_framing
    from vstig_hw.framing.xbee import api_frame, receive_packet

    rng = random.Random(34)
    frames = []
    for escaped in (False, True):
        for _ in range(40):
            batch = [Message(Op(rng.getrandbits(1)), rng.getrandbits(15), rng.getrandbits(16), rng.getrandbits(16),
                             rng.getrandbits(16)) for _ in range(rng.randrange(1, 6))]
            source = 0x0013A200_00000000 | rng.getrandbits(32)
            packet = ReceivePacket(XBee64BitAddress.from_hex_string(f"{source:016X}"),
                                   XBee16BitAddress.from_hex_string("FFFE"), 0x02,
                                   rf_data=bytearray(b"".join(encode(m) for m in batch)),
                                   op_mode=OperatingMode.ESCAPED_API_MODE if escaped else OperatingMode.API_MODE)
            frames.append(bytes(packet.output(escaped=escaped)))
            frames += make_serial_framing("xbee-api2" if escaped else "xbee").encode_batch(batch)
    bad_sum = bytearray(api_frame(receive_packet(0x0013A20040A1B2C3, bytes(8))))
    bad_sum[-1] ^= 1
    return [*frames, api_frame(receive_packet(0x0013A20040A1B2C3, bytes(7))), bytes(bad_sum),
            api_frame(bytes.fromhex("8b01fffe000000"))]


def _xbee_expected(frame: bytes) -> list[str]:
    """What our framing reads in one frame, as tshark's fields show it."""
    from digi.xbee.packets.base import XBeePacket

    from vstig_hw.framing import make_serial_framing

    escaped = (frame[1] << 8 | frame[2]) + 4 != len(frame)
    plain = bytes(XBeePacket.unescape_data(bytearray(frame))) if escaped else frame
    framing = make_serial_framing("xbee-api2" if escaped else "xbee")
    msgs = framing.feed(frame)
    sender = framing.sender_of(frame)  # type: ignore[attr-defined]
    column = lambda values: ",".join(str(v) for v in values)  # noqa: E731
    expert = {"checksum": "frame data and checksum do not sum to 0xFF (dropped)",
              "bad_length": "RF data is not a whole number of 8-byte messages (dropped)"}
    return [f"0x{plain[3]:02x}", str(int(escaped)), column(f"0x{sender:016x}" for _ in msgs) if sender else "",
            column(int(m.op) for m in msgs), column(m.key for m in msgs), column(m.value for m in msgs),
            column(m.timestamp for m in msgs), column(m.robot for m in msgs),
            ",".join(text for reason, text in expert.items() if framing.drops[reason])]


def frames_through_tshark(tmp_path: Path, frames: list[bytes], link_type: int, fields: list[str]) -> list[list[str]]:
    """Each frame one packet of `link_type` (text2pcap makes the pcap, as a user would), and the `fields` tshark
    shows for each, with every occurrence joined by commas."""
    text2pcap = require_tool("text2pcap", "wireshark-common")
    dump = tmp_path / "frames.txt"
    dump.write_text("".join("".join(f"{i:06x} {frame[i:i + 16].hex(' ')}\n" for i in range(0, len(frame), 16)) + "\n"
                            for frame in frames))
    pcap = tmp_path / "frames.pcap"
    subprocess.run([text2pcap, "-q", "-l", str(link_type), str(dump), str(pcap)], check=True, capture_output=True,
                   timeout=60)
    rows = tshark_fields(pcap, fields)
    assert len(rows) == len(frames)
    return rows


def test_xbee_frames_from_a_capture(tmp_path: Path) -> None:
    frames = _xbee_frames()
    rows = frames_through_tshark(tmp_path, frames, 147, XBEE_FIELDS)
    for frame, row in zip(frames, rows, strict=True):
        assert row == _xbee_expected(frame), frame.hex()
