"""A swarm of Kilobots running BittyBuzz, behind one bridge radio on a pty, written from BittyBuzz's C.

Independent of vstig_hw: the 9-byte message with struct ('<BHHBHB', bbzoutmsg.c),
the Kilobot message_t with the `cobs` package and crccheck's CRC-16/MCRF4XX, and the
receive rules of bbzmsg.c `bbzmsg_process_vstig` (HEAD, threshold 50). Every robot
hears every other robot and the bridge radio (one IR neighbourhood); every step each
robot calls get() on its keys, which queues a QUERY (nil at lamport 0 for a key it lacks).
"""

from __future__ import annotations

import struct
import threading
from dataclasses import dataclass, field

from cobs import cobs
from crccheck.crc import Crc16Mcrf4XX
from peers import PtyPeer

BBZMSG = 2
PUT, QUERY = 1, 2
INT, NIL = 1, 0
LAYOUT = struct.Struct("<BHHBHB")


def frame(data9: bytes) -> bytes:
    message_t = data9 + bytes((BBZMSG,))
    return cobs.encode(message_t + Crc16Mcrf4XX.calc(message_t).to_bytes(2, "little")) + b"\0"


def unframe(segment: bytes) -> bytes | None:
    try:
        data = bytes(cobs.decode(segment))
    except cobs.DecodeError:
        return None
    if len(data) != 12 or Crc16Mcrf4XX.calc(data[:10]) != int.from_bytes(data[10:], "little") or data[9] != BBZMSG:
        return None
    return data[:9]


def newer(lamport: int, old: int) -> bool:
    return lamport != old and (lamport - old) & 0xFF < 50


@dataclass
class Entry:
    value: int
    lamport: int
    robot: int
    tag: int = INT


@dataclass
class Kilobot:
    rid: int
    store: dict[int, Entry] = field(default_factory=dict)
    outbox: list[bytes] = field(default_factory=list)

    def _send(self, kind: int, key: int, entry: Entry, rid: int | None = None) -> None:
        self.outbox.append(LAYOUT.pack(kind, entry.robot if rid is None else rid, key, entry.tag,
                                       entry.value & 0xFFFF, entry.lamport))

    def put(self, key: int, value: int) -> None:
        old = self.store.get(key)
        self.store[key] = Entry(value, (old.lamport + 1) & 0xFF if old else 1, self.rid)
        self._send(PUT, key, self.store[key])

    def get(self, key: int) -> None:
        entry = self.store.get(key)
        if entry is None:
            self.outbox.append(LAYOUT.pack(QUERY, self.rid, key, NIL, 0, 0))
        else:
            self._send(QUERY, key, entry)

    def receive(self, data9: bytes) -> None:
        kind, rid, key, mdata, value, lamport = LAYOUT.unpack(data9)
        if kind not in (PUT, QUERY):
            return
        signed = value - 0x10000 if value & 0x8000 else value
        local = self.store.get(key)
        if local is None or newer(lamport, local.lamport):  # stored whatever it is, then relayed as a PUT
            self.store[key] = Entry(signed, lamport, rid, mdata & 7)
            self._send(PUT, key, self.store[key])
        elif kind == QUERY and newer(local.lamport, lamport):
            self._send(PUT, key, local, rid=self.rid)  # BittyBuzz answers with its own id (a known bug)
        elif local.lamport == lamport and local.robot != rid:
            if rid >= local.robot:
                self.store[key] = Entry(signed, lamport, rid, mdata & 7)
            self._send(PUT, key, self.store[key])


class KilobotSwarm:
    """The robots, stepped on a thread; `from_bridge` keeps every message the PC sent, decoded."""

    def __init__(self, radio: PtyPeer, rids: list[int], keys: list[int]) -> None:
        self.radio = radio
        self.robots = [Kilobot(rid) for rid in rids]
        self.keys = keys
        self.from_bridge: list[tuple[int, ...]] = []
        self.lock = threading.Lock()
        self._stop = threading.Event()
        self._buffer = b""
        self._thread = threading.Thread(target=self._run, daemon=True)

    def start(self) -> None:
        self._thread.start()

    def act(self, rid: int, key: int, value: int) -> None:
        with self.lock:
            next(r for r in self.robots if r.rid == rid).put(key, value)

    def held(self, key: int) -> list[Entry | None]:
        with self.lock:
            return [r.store.get(key) for r in self.robots]

    def _run(self) -> None:
        while not self._stop.is_set():
            self._buffer += self.radio.read(0.05)
            *segments, self._buffer = self._buffer.split(b"\0")
            with self.lock:
                for data in (unframe(s) for s in segments if s):
                    if data is not None:
                        self.from_bridge.append(LAYOUT.unpack(data))
                        for robot in self.robots:
                            robot.receive(data)
                for robot in self.robots:
                    for key in self.keys:
                        robot.get(key)
                self._broadcast()

    def _broadcast(self) -> None:
        """Every robot's queue goes out once: heard by the others and by the bridge radio."""
        for _ in range(4):  # a few hops per step
            sent = [(robot, data) for robot in self.robots for data in robot.outbox]
            for robot in self.robots:
                robot.outbox = []
            if not sent:
                return
            for sender, data in sent:
                self.radio.write(frame(data))
                for robot in self.robots:
                    if robot is not sender:
                        robot.receive(data)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
