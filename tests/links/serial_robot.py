"""The robot's side of a serial link, written the way firmware would, independently of vstig_hw.

It uses the `cobs` package, crccheck's CRC-16/MCRF4XX and zlib directly, so a
round trip through a pty checks vstig_hw against a second implementation of
firmware_spec/serial.md rather than against itself.
"""

from __future__ import annotations

import os
import queue
import select
import struct
import threading
import time
import zlib
from collections.abc import Callable

from cobs import cobs
from crccheck.crc import Crc16Mcrf4XX

from vstig_hw import Message, Op

KILOBOT_TYPE = 0x56


def message_bytes(msg: Message) -> bytes:
    return struct.pack(">HHHH", (int(msg.op) << 15) | msg.key, msg.value, msg.timestamp, msg.robot)


def message_from(data: bytes) -> Message:
    first, value, timestamp, robot = struct.unpack(">HHHH", data)
    return Message(Op(first >> 15), first & 0x7FFF, value, timestamp, robot)


def frame(payload: bytes) -> bytes:
    return cobs.encode(payload + Crc16Mcrf4XX.calc(payload).to_bytes(2, "little")) + b"\x00"


def unframe(segment: bytes) -> bytes | None:
    try:
        data = cobs.decode(segment)
    except cobs.DecodeError:
        return None
    if len(data) < 2 or Crc16Mcrf4XX.calc(data[:-2]) != int.from_bytes(data[-2:], "little"):
        return None
    return bytes(data[:-2])


def epuck_words(msg: Message) -> list[bytes]:
    """The three radio words, built as one 96-bit number rather than chunk by chunk."""
    raw = message_bytes(msg)
    c = zlib.crc32(raw)
    payload78 = (int.from_bytes(raw, "big") << 14) | ((c >> 14) & 0x3FFF)
    words = []
    for index, shift in enumerate((52, 26, 0)):
        words.append(((index << 30) | ((c >> 28) << 26) | ((payload78 >> shift) & 0x3FFFFFF)).to_bytes(4, "big"))
    return words


def encode_for(framing: str, msg: Message) -> bytes:
    """The bytes a robot puts on the UART for one message."""
    if framing == "cobs8":
        return frame(message_bytes(msg))
    if framing == "kilobot":
        return frame(message_bytes(msg) + bytes((1, KILOBOT_TYPE)))
    if framing == "epuck4":
        return b"".join(frame(word) for word in epuck_words(msg))
    raise ValueError(framing)


def decode_stream(framing: str, data: bytes) -> list[Message]:
    """Messages in a byte stream from the PC (assumes no loss: this is the clean direction)."""
    payloads = [p for p in (unframe(s) for s in data.split(b"\x00") if s) if p is not None]
    if framing == "cobs8":
        return [message_from(p) for p in payloads]
    if framing == "kilobot":
        return [message_from(p[:8]) for p in payloads if p[8:] == bytes((1, KILOBOT_TYPE))]
    if framing == "epuck4":
        out = []
        for i in range(0, len(payloads) - 2, 3):
            bits = 0
            for word in payloads[i:i + 3]:
                bits = (bits << 26) | (int.from_bytes(word, "big") & 0x3FFFFFF)
            out.append(message_from((bits >> 14).to_bytes(8, "big")))
        return out
    raise ValueError(framing)


class OhcReceiver:
    """The overhead controller's UART receive logic (kilolib ohc.c): a 132-byte ring and a running XOR."""

    SIZE = 132

    def __init__(self) -> None:
        self.ring = bytearray(self.SIZE)
        self.head = 0
        self.xor = 0
        self.packets: list[bytes] = []

    def feed(self, data: bytes) -> None:
        for byte in data:
            self.xor ^= self.ring[self.head] ^ byte
            self.ring[self.head] = byte
            self.head = (self.head + 1) % self.SIZE
            if self.ring[self.head] == 0x55 and self.xor == 0:
                self.packets.append(bytes(self.ring[self.head:] + self.ring[:self.head]))


class PtyRobot:
    """A thread on a pty's master side: collects what the PC sends, writes what the robot says."""

    def __init__(self, master: int) -> None:
        self.master = master
        self.received = bytearray()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._outbox: queue.Queue[bytes] = queue.Queue()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        self._writer = threading.Thread(target=self._write, daemon=True)
        self._writer.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([self.master], [], [], 0.05)
            if ready:
                try:
                    data = os.read(self.master, 4096)
                except OSError:
                    return
                with self._lock:
                    self.received.extend(data)

    def _write(self) -> None:
        # Its own thread: a pty holds only a few KB, so a big write waits for the PC to read.
        while not self._stop.is_set():
            try:
                view = memoryview(self._outbox.get(timeout=0.05))
            except queue.Empty:
                continue
            while view:
                try:
                    written = os.write(self.master, view)
                except OSError:
                    return
                view = view[written:]

    def send(self, data: bytes) -> None:
        """Queue bytes for the robot to write, in order."""
        self._outbox.put(data)

    def snapshot(self) -> bytes:
        with self._lock:
            return bytes(self.received)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self._writer.join(timeout=5)


def poll(condition: Callable[[], bool], deadline_s: float = 10.0, what: str = "condition") -> None:
    """Wait for `condition` with a generous deadline (no fixed sleeps)."""
    end = time.monotonic() + deadline_s
    while not condition():
        if time.monotonic() > end:
            raise AssertionError(f"timed out after {deadline_s} s waiting for {what}")
        time.sleep(0.005)
