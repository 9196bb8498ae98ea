"""A Khepera IV running BuzzKH4 with the paper's script, as a separate process, written from Buzz's C alone.

Independent of vstig_hw. The robot listens on 127.0.0.1 (port 0: the first line it
prints is `port N`), accepts one connection and only then starts, as bzzkh4 does
(BuzzKH4 buzz_utility.c). Every step it sends one `size`-byte frame: u16 robot id,
[u16 length][message]..., zero padding, little-endian (buzz_utility.c:479-511). Its
script: stigmergy.create(1), put("leader", id) once, get("leader") every step, with
Buzz's vstig rules (buzzvm.c:276-420), its default conflict rule (higher robot id,
non-nil first) and its out-queue (one pending message per key, replaced only by a
higher timestamp; PUTs before QUERYs).

It prints `leader VALUE TS ROBOT` each time its entry changes (a float as `float:` and
its float32 bits in hex, so a rounded copy shows), and `bad HEX` for any vstig message
that does not parse to its exact end in the current dialect.

Options, for tests that look at the medium: `--ts N` puts at timestamp N instead of 1;
`--float V` puts the C float V instead of its id (Buzz's float: buzzmsg.c:87-163);
`--silent` never puts (it only stores, re-broadcasts and answers what it hears);
`--deaf S` drops every frame of its first S seconds (a robot that missed them);
`--trace` also prints `heard SENDER put|query KEY VALUE TS WRITER` for every vstig
message it hears (any key), with the frame's sender.

Usage: python kh4_robot.py ROBOT_ID SIZE [--ts N] [--float V] [--silent] [--deaf S] [--trace]
"""

from __future__ import annotations

import math
import select
import socket
import struct
import sys
import time
from collections.abc import Iterator

PUT, QUERY = 2, 3
STIG, KEY = 1, b"leader"


Value = int | float | None
Entry = tuple[Value, int, int]


def f32(x: float) -> float:
    """`x` as a C float holds it."""
    return float(struct.unpack("<f", struct.pack("<f", x))[0])


def float_pair(value: float) -> tuple[int, int]:
    """buzzmsg_serialize_float: frexpf, then (int32)((|f| - 0.5) * 2 * 2147483648.0f) + 1, signed; zero is (0, 0)."""
    if value == 0:
        return 0, 0
    fraction, exponent = math.frexp(value)
    mantissa = int((abs(fraction) - 0.5) * 2 * 2147483648.0) + 1
    return (-mantissa if value < 0 else mantissa), exponent


def float_from_pair(mantissa: int, exponent: int) -> float:
    """buzzmsg_deserialize_float, in single precision: (float)(|m| - 1) / 2^32 + 0.5f, then ldexpf."""
    if mantissa == 0:
        return 0.0
    magnitude = math.ldexp(f32(f32(float(abs(mantissa) - 1)) / 2**32 + 0.5), exponent)
    return -magnitude if mantissa < 0 else magnitude


def show(value: object) -> str:
    """How the robot prints a value: a float by its float32 bits."""
    return f"float:{struct.pack('>f', value).hex()}" if isinstance(value, float) else str(value)


def obj(value: Value) -> bytes:
    if value is None:
        return b"\x00"
    if isinstance(value, float):
        return b"\x02" + struct.pack(">ii", *float_pair(value))
    return b"\x01" + struct.pack(">i", value)


def message(kind: int, entry: Entry) -> bytes:
    value, ts, robot = entry
    return bytes((kind,)) + struct.pack(">HBH", STIG, 3, len(KEY)) + KEY + obj(value) + struct.pack(">HH", ts, robot)


def parse_obj(data: bytes, pos: int) -> tuple[object, int]:
    tag = data[pos]
    if tag == 0:
        return None, pos + 1
    if tag == 1:
        return struct.unpack_from(">i", data, pos + 1)[0], pos + 5
    if tag == 2:
        return float_from_pair(*struct.unpack_from(">ii", data, pos + 1)), pos + 9
    if tag == 3:
        (size,) = struct.unpack_from(">H", data, pos + 1)
        if pos + 3 + size > len(data):
            raise ValueError("string past the end")
        return data[pos + 3:pos + 3 + size], pos + 3 + size
    raise ValueError(f"tag {tag}")


def parse(data: bytes) -> tuple[int, int, object, object, int, int]:
    (stig,) = struct.unpack_from(">H", data, 1)
    key, pos = parse_obj(data, 3)
    value, pos = parse_obj(data, pos)
    ts, robot = struct.unpack_from(">HH", data, pos)
    if pos + 4 != len(data):
        raise ValueError("length")
    return data[0], stig, key, value, ts, robot


def parse_or_say_bad(data: bytes) -> tuple[int, int, object, object, int, int] | None:
    """`parse`, or None after printing `bad HEX` for a vstig message that does not parse to its exact end."""
    try:
        return parse(data)
    except (ValueError, struct.error, IndexError):
        print(f"bad {data.hex()}", flush=True)
        return None


def messages_in(frame: bytes, pos: int, end: int) -> Iterator[bytes]:
    """The messages of a Buzz frame from `pos`: [u16 length, little-endian][message]..., until a zero length or less
    than a length is left before `end` (buzz_utility.c:413-439)."""
    while end - pos > 2:
        (length,) = struct.unpack_from("<H", frame, pos)
        pos += 2
        if length == 0 or length > end - pos:
            return
        yield frame[pos:pos + length]
        pos += length


class Robot:
    def __init__(self, rid: int) -> None:
        self.rid = rid
        self.entry: Entry | None = None
        self.pending: tuple[int, Entry] | None = None

    def queue(self, kind: int, entry: Entry) -> None:
        if self.pending is not None and self.pending[1][1] >= entry[1]:
            return
        self.pending = (kind, entry)

    def store(self, entry: Entry) -> None:
        if entry != self.entry:
            print(f"leader {show(entry[0])} {entry[1]} {entry[2]}", flush=True)
        self.entry = entry

    def conflict(self, remote: Entry) -> Entry:
        local = self.entry
        assert local is not None
        if (local[0] is None) == (remote[0] is None):
            winner = remote if remote[2] > local[2] else local
        else:
            winner = remote if local[0] is None else local
        return (winner[0], local[1], winner[2])

    def receive(self, kind: int, value: object, ts: int, robot: int) -> None:
        remote = (value if isinstance(value, int | float) else None, ts, robot)
        local = self.entry
        if kind == PUT:
            if local is None or local[1] < ts:
                self.store(remote)
                self.queue(PUT, remote)
            elif local[1] == ts and local[2] != robot:
                self.store(self.conflict(remote))
                self.queue(PUT, self.entry)  # type: ignore[arg-type]
        elif local is None:
            if remote[0] is None:
                self.queue(QUERY, remote)
            else:
                self.store(remote)
                self.queue(PUT, remote)
        elif local[1] < ts:
            self.store(remote)
            self.queue(PUT, remote)
        elif local[1] > ts:
            self.queue(PUT, local)
        elif local[2] != robot:
            self.store(self.conflict(remote))
            self.queue(PUT, self.entry)  # type: ignore[arg-type]


def main() -> int:
    rid, size = int(sys.argv[1]), int(sys.argv[2])
    options = sys.argv[3:]
    first_ts = int(options[options.index("--ts") + 1]) if "--ts" in options else 1
    written: Value = f32(float(options[options.index("--float") + 1])) if "--float" in options else rid
    deaf = float(options[options.index("--deaf") + 1]) if "--deaf" in options else 0.0
    silent, trace = "--silent" in options, "--trace" in options
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    print(f"port {server.getsockname()[1]}", flush=True)
    conn, _ = server.accept()
    server.close()
    robot = Robot(rid)
    if not silent:
        robot.store((written, first_ts, rid))  # put("leader", id)
        robot.queue(PUT, robot.entry)  # type: ignore[arg-type]
    hearing_from = time.monotonic() + deaf
    inbox = b""
    while True:
        end = time.monotonic() + 0.05
        while (left := end - time.monotonic()) > 0:
            if select.select([conn], [], [], left)[0]:
                chunk = conn.recv(65536)
                if not chunk:
                    return 0
                inbox += chunk
        while len(inbox) >= size:
            frame, inbox = inbox[:size], inbox[size:]
            if time.monotonic() < hearing_from:
                continue
            (sender,) = struct.unpack_from("<H", frame)
            for data in messages_in(frame, 2, size):
                if data[0] in (PUT, QUERY):
                    parsed = parse_or_say_bad(data)
                    if parsed is None:
                        continue
                    kind, stig, key, value, ts, writer = parsed
                    if trace:
                        name = key.decode() if isinstance(key, bytes) else key
                        print(f"heard {sender} {'put' if kind == PUT else 'query'} {name} {show(value)} {ts} {writer}",
                              flush=True)
                    if stig == STIG and key == KEY:
                        robot.receive(kind, value, ts, writer)
        if robot.entry is not None:
            robot.queue(QUERY, robot.entry)  # get("leader")
        out = struct.pack("<H", rid)
        if robot.pending is not None:
            data = message(*robot.pending)
            out += struct.pack("<H", len(data)) + data
            robot.pending = None
        try:
            conn.sendall(out.ljust(size, b"\0"))
        except OSError:
            return 0


if __name__ == "__main__":
    sys.exit(main())
