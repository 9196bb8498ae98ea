"""A ROSBuzz drone on its XBee radio, as a separate process, written from ROSBuzz's and XbeeMav's C++ alone.

Independent of vstig_hw: its XBee frames are the emulated modules' own codec (xbee_network.py).
The drone runs the paper's script with Buzz's vstig rules (the `Robot` of kh4_robot.py:
put("leader", id) once, get("leader") every step, Buzz's conflict rule and out-queue).
Every step (ROSBuzz's BUZZRATE, 10 Hz) it publishes what ROSBuzz publishes (roscontroller.cpp
`prepare_msg_and_publish`, buzz_utility.cpp `obt_out_msg`):

    payload64 = [header: u16 type 2 (BUZZ_MESSAGE), u16 message number, u32 time] [ROS time ns]
                [latitude] [longitude] [altitude] [Buzz block: u16 words, u16 robot id,
                (u16 length, message)..., zero padded to whole words; little-endian]

and sends it as XbeeMav does (PacketsHandler.cpp): u8 sysid, u8 msgid, each word big-endian;
under 250 bytes behind 'S', otherwise as 'F' fragments of 250 bytes followed by a 'P' ping;
each in a Transmit Request (0x10) broadcast with frame id 1 in API mode 1 (XbeeMav's), or 2.
At start it asks its module SL and SH with 0x09 frames, as XbeeMav does. It reads Receive
Packets (0x90) at XbeeMav's offsets (SerialDevice.cpp: the packet type at RF byte 0) and
hands 'S' packets to ROSBuzz's `payload_obt`; it does not reassemble fragments (the gateway
never sends any).

It prints `leader VALUE TS ROBOT` each time its entry changes, `bad HEX` for a vstig message
that does not parse, and `module SH SL` when its module answered.

Usage: python rosbuzz_robot.py ROBOT_ID PORT [--api 2] [--fragment] [--silent]
  --fragment  pad every payload64 with zero words past 250 bytes, so it goes out as fragments
  --silent    never put (only store, re-broadcast and answer)
"""

from __future__ import annotations

import struct
import sys
import time
from collections import Counter
from pathlib import Path

import serial

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "cli"))
from kh4_robot import KEY, PUT, QUERY, STIG, Robot, message, messages_in, parse_or_say_bad
from xbee_network import FrameParser, wire

MTU = 250


def transmit(rf: bytes, api: int) -> bytes:
    """PacketsHandler::Generate_Transmit_Request_Frame: frame id 1, broadcast, 16-bit FFFE, radius 0, options 0."""
    return wire(b"\x10\x01" + bytes.fromhex("000000000000FFFF" "FFFE" "00" "00") + rf, api)


def packets(robot_id: int, number: int, entry_messages: list[bytes], fragment: bool) -> list[bytes]:
    """The RF data XbeeMav sends for this step's payload64."""
    block = struct.pack("<HH", 0, robot_id)
    for data in entry_messages:
        block += struct.pack("<H", len(data)) + data
    words = -(-len(block) // 8)
    block = struct.pack("<H", words) + block[2:].ljust(words * 8 - 2, b"\0")
    header = 2 | (number & 0xFFFF) << 16
    payload64 = [header, int(time.time() * 1e9), 0, 0, 0, *struct.unpack(f"<{words}Q", block)]
    if fragment:
        payload64 += [0] * max(0, MTU // 8 + 1 - len(payload64))  # 2 + 8 * 32 = 258 bytes serialized
    serialized = bytes((robot_id & 0xFF, number & 0xFF)) + b"".join(w.to_bytes(8, "big") for w in payload64)
    if len(serialized) < MTU:
        return [b"S" + serialized]
    fragments = [b"F" + bytes((number & 0xFF, robot_id & 0xFF, i)) + offset.to_bytes(2, "big")
                 + serialized[offset:offset + MTU] for i, offset in enumerate(range(0, len(serialized), MTU))]
    return [*fragments, b"P" + bytes((number & 0xFF, robot_id & 0xFF, len(fragments)))]


class Radio:
    """The module's UART: frames in (the frame data, checksums checked), ours out."""

    def __init__(self, path: str, api: int) -> None:
        self.port = serial.Serial(path, 230400, timeout=0.05)
        self.parser = FrameParser(api, Counter())

    def frames(self) -> list[bytes]:
        return [data for _raw, data in self.parser.feed(self.port.read(65536))]


def payload_obt(robot: Robot, payload64: list[int]) -> None:
    """roscontroller.cpp payload_obt, then buzz_utility in_message_process: the block's vstig messages."""
    if not payload64 or payload64[0] & 0xFFFF != 2:
        return
    block = struct.pack(f"<{len(payload64) - 5}Q", *payload64[5:])
    (words,) = struct.unpack_from("<H", block)
    for data in messages_in(block, 4, min(words * 8, len(block))):
        parsed = parse_or_say_bad(data) if data[0] in (PUT, QUERY) else None
        if parsed is not None and parsed[1:3] == (STIG, KEY):
            kind, _stig, _key, value, ts, writer = parsed
            robot.receive(kind, value, ts, writer)


def main() -> int:
    rid, path = int(sys.argv[1]), sys.argv[2]
    options = sys.argv[3:]
    api = int(options[options.index("--api") + 1]) if "--api" in options else 1
    fragment, silent = "--fragment" in options, "--silent" in options
    radio = Radio(path, api)
    radio.port.write(wire(b"\x09\x01SL", api) + wire(b"\x09\x01SH", api))  # PacketsHandler::Send_SL_and_SH_Commands
    robot = Robot(rid)
    if not silent:
        robot.store((rid, 1, rid))  # put("leader", id)
        robot.queue(PUT, robot.entry)  # type: ignore[arg-type]
    number, address = 0, {}
    while True:
        end = time.monotonic() + 0.1
        while time.monotonic() < end:
            for data in radio.frames():
                if data[0] == 0x88 and len(data) >= 5 and data[4] == 0:
                    address[data[2:4].decode()] = data[5:].hex().upper()
                    if len(address) == 2:
                        print(f"module {address['SH']} {address['SL']}", flush=True)
                elif data[0] == 0x90 and len(data) > 12 and data[12:13] == b"S":
                    serialized = data[13:]
                    words = [int.from_bytes(serialized[i:i + 8], "big") for i in range(2, len(serialized) - 7, 8)]
                    payload_obt(robot, words)
        if robot.entry is not None:
            robot.queue(QUERY, robot.entry)  # get("leader")
        outgoing = []
        if robot.pending is not None:
            outgoing.append(message(*robot.pending))
            robot.pending = None
        number += 1
        try:
            radio.port.write(b"".join(transmit(rf, api) for rf in packets(rid, number, outgoing, fragment)))
        except (serial.SerialException, OSError):
            return 0


if __name__ == "__main__":
    sys.exit(main())
