"""Tags that prove who wrote an entry (firmware_spec/SPEC.md section 10): keys, tags, records. Pure, no I/O
but `read_swarm_key`.

A swarm has one master secret; each robot's key is derived from it and the robot's id, so a robot holds only
its own key and a gateway, holding the master, can check every writer. A tag is keyed BLAKE2s with an 8-byte
digest over (epoch, stigmergy, key, value, timestamp, writer): the entry, not the message, so a GET that shows
an entry and every relay of it carry the writer's own tag. The epoch counts the key's timestamp wrap-arounds;
tagged entries are ordered by (epoch, timestamp) as plain numbers, so a recorded write replayed after any
number of updates, across a wrap or not, is older than the entry it would replace.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
import struct
from typing import Any, NamedTuple

from .inputs import InputFileError, read_regular
from .timestamps import TS_NONE
from .wire import KEY_MAX, DecodeError, Message, decode, encode

__all__ = [
    "BATCH_MARKER",
    "EPOCH_MAX",
    "KEY_SIZE",
    "NO_TAG",
    "RECORD_SIZE",
    "TAG_SIZE",
    "SwarmKeys",
    "Tagged",
    "decode_batch",
    "decode_record",
    "encode_batch",
    "encode_record",
    "entry_tag",
    "new_swarm_key_text",
    "next_epoch",
    "read_swarm_key",
    "robot_key",
    "tagged_newer",
]

KEY_SIZE = 32  # the master secret and every robot key
TAG_SIZE = 8  # 64 bits: the issue's floor, MAVLink 2's 48 and SecOC's usual 24..64 for scale
EPOCH_MAX = 0xFFFFFFFF
RECORD_SIZE = 20  # message (8) || epoch (u32) || tag (8)
BATCH_MARKER = 0xA1  # first byte of N records where untagged messages would be 8*N bytes (XBee, zenoh)
NO_TAG = bytes(TAG_SIZE)  # a GET showing no entry (timestamp 0) has nothing to prove
_KDF_LABEL = b"vstig robot key"
_KEY_FILE_MAX_BYTES = 4096
_EPOCH = struct.Struct(">I")
_MAC_INPUT = struct.Struct(">IHHHHH")  # epoch, stigmergy, key without the op bit, value, timestamp, robot


class Tagged(NamedTuple):
    """One authenticated message: the message, its entry's epoch and its writer's tag."""

    message: Message
    epoch: int
    tag: bytes


def robot_key(master: bytes, robot: int) -> bytes:
    """The 32-byte key of `robot`: BLAKE2s-256 keyed with the master over 'vstig robot key' || robot (u16)."""
    return hashlib.blake2s(_KDF_LABEL + robot.to_bytes(2, "big"), key=master, digest_size=KEY_SIZE).digest()


def entry_tag(key: bytes, stigmergy: int, msg: Message, epoch: int) -> bytes:
    """The tag of `msg`'s entry under its writer's `key` (the op is not covered: PUT and GET tag alike)."""
    return hashlib.blake2s(_mac_input(stigmergy, msg, epoch), key=key, digest_size=TAG_SIZE).digest()


def _mac_input(stigmergy: int, msg: Message, epoch: int) -> bytes:
    return _MAC_INPUT.pack(epoch, stigmergy, msg[0] & KEY_MAX, msg[1], msg[2], msg[3])


def tagged_newer(epoch: int, timestamp: int, than_epoch: int, than_timestamp: int) -> bool:
    """True when (epoch, timestamp) is newer than (than_epoch, than_timestamp): plain order, epoch first."""
    return (epoch, timestamp) > (than_epoch, than_timestamp)


def next_epoch(epoch: int, timestamp: int, next_timestamp: int) -> int:
    """The epoch of a write at `next_timestamp` replacing an entry at (epoch, timestamp): one more when the
    counter wrapped (65535 -> 1). A new key (timestamp 0) starts at `epoch`, 0 for a key never held."""
    if timestamp != TS_NONE and next_timestamp < timestamp:
        return epoch + 1
    return epoch


def encode_record(tagged: Tagged) -> bytes:
    """The 20 bytes of one authenticated message."""
    return encode(tagged.message) + _EPOCH.pack(tagged.epoch) + tagged.tag


def decode_record(data: bytes) -> Tagged:
    """One authenticated message from its 20 bytes; DecodeError for any other length."""
    if len(data) != RECORD_SIZE:
        raise DecodeError(f"an authenticated message is exactly {RECORD_SIZE} bytes, got {len(data)}")
    return Tagged(decode(data[:8]), _EPOCH.unpack_from(data, 8)[0], bytes(data[12:]))


def encode_batch(records: list[Tagged]) -> bytes:
    """BATCH_MARKER then the records, for media whose untagged unit is 8*N bytes."""
    return bytes([BATCH_MARKER]) + b"".join(map(encode_record, records))


def decode_batch(data: bytes) -> list[Tagged]:
    """The records of a tagged batch; DecodeError unless it is the marker and one or more whole records."""
    if len(data) < 1 + RECORD_SIZE or data[0] != BATCH_MARKER or (len(data) - 1) % RECORD_SIZE:
        raise DecodeError(f"a tagged batch is 0x{BATCH_MARKER:02X} then N >= 1 records of {RECORD_SIZE} bytes, "
                          f"got {len(data)} bytes")
    return [decode_record(data[i : i + RECORD_SIZE]) for i in range(1, len(data), RECORD_SIZE)]


class SwarmKeys:
    """What a gateway holds: the master secret, and the robot keys derived from it as writers are met."""

    def __init__(self, master: bytes, stigmergy: int = 0) -> None:
        if len(master) != KEY_SIZE:
            raise ValueError(f"a swarm master secret is {KEY_SIZE} bytes, got {len(master)}")
        self._master = master
        self.stigmergy = stigmergy
        # Each writer's keyed BLAKE2s state after its key block (copied per tag: 0.6x the cost of keying anew);
        # at most 65536 robots, a few hundred bytes each.
        self._ready: dict[int, Any] = {}

    @property
    def master(self) -> bytes:
        """The master secret (for the compiled engine, which derives and caches the writers' keys itself)."""
        return self._master

    def key_of(self, robot: int) -> bytes:
        return robot_key(self._master, robot)

    def _tag(self, msg: Message, epoch: int) -> bytes:
        robot = msg[3]
        ready = self._ready.get(robot)
        if ready is None:
            ready = self._ready[robot] = hashlib.blake2s(key=self.key_of(robot), digest_size=TAG_SIZE)
        mac = ready.copy()
        mac.update(_mac_input(self.stigmergy, msg, epoch))
        return mac.digest()

    def tag(self, msg: Message, epoch: int) -> Tagged:
        """`msg` tagged as its writer (`msg.robot`) would tag it."""
        return Tagged(msg, epoch, self._tag(msg, epoch))

    def verify(self, tagged: Tagged) -> bool:
        """True when the tag is the one its claimed writer's key gives (compared in constant time)."""
        return hmac.compare_digest(self._tag(tagged.message, tagged.epoch), tagged.tag)


def new_swarm_key_text() -> str:
    """A fresh master secret as a key file holds it: 64 hex digits and a newline."""
    return secrets.token_hex(KEY_SIZE) + "\n"


def read_swarm_key(path: str | os.PathLike[str]) -> bytes:
    """The master secret in `path`: 64 hex digits; InputFileError naming the file when it is not a small
    regular file only its owner may read, or holds anything else."""
    what = "the swarm key file"
    text = read_regular(path, _KEY_FILE_MAX_BYTES, what, private=True).decode("ascii", "replace").strip()
    try:
        master = bytes.fromhex(text) if len(text) == 2 * KEY_SIZE else b""
    except ValueError:
        master = b""
    if not master:
        raise InputFileError(f"{os.fspath(path)}: {what} must hold {2 * KEY_SIZE} hex digits (a {KEY_SIZE}-byte "
                             f"secret; `vstig keys --new FILE` writes one), got {len(text)} characters")
    return master
