"""The framing contract: link units <-> Messages, pure and counted.

A framing is a small pure class: no device, no thread, no clock. `encode` turns
one Message into the units the transport writes (bytes for a UART, frames for
CAN); `feed` takes whatever unit the transport read and returns the Messages now
complete. Anything that cannot be a message is dropped and counted in `drops`
by reason, never raised.

Every framing subclasses `Framing` (python-can's `BusABC` is the model): `encode`
and `feed` are its own; the optional calls a medium may offer are declared here
with the default a medium without them gets, so the gateway calls them
unconditionally and mypy checks a new medium against them:

* `encode_batch`: several messages in as few units as the medium allows (CAN FD,
  zenoh samples, BuzzKH4 frames); default, one `encode` after another. For one
  message it must give what `encode` gives (a link sends a lone message with `encode`);
* `sender_of`: the node that transmitted a unit, where the medium names it (CAN
  IDs, zenoh keys, BuzzKH4 frame headers; `names_senders` says it does); default None;
* `source_of`: who really sent a unit, where the medium says more than the sender
  it claims (a zenoh session; `names_sources` says it does); default None;
* `link_quality_of`: RSSI or link quality of a unit, where the medium reports it per
  unit (`reports_link_quality` says it does; no framing does today: an XBee Receive
  Packet, 0x90, carries no RSSI); default None, and the roster shows none;
* `transmit_only`: nothing ever comes back (an overhead controller): `feed`
  raises TransmitOnlyError, and a link built on it never decodes;
* `carries_tags`: the medium has room for authenticated messages, a message with its
  writer's epoch and tag (SPEC.md 10.5: cobs8, CAN FD, XBee, zenoh, MAVLink, ROS 2); a
  framing without room (classic CAN, e-puck words, Kilobot IR) says False, and a link
  on it cannot require tags. `encode_tagged` puts records in units (default: raises
  NoRoomForTags); `feed_tagged` gives each message of a unit with its record, None when it
  came untagged (default: `feed`'s messages, all untagged). `feed` keeps a tagged unit's
  messages without their tags (a link with auth off);
* `capture_medium`, `capture_name`: the capture format its units go into without .mcap (can, zenoh;
  default serial, bytes in our line capture) and the framing name its records carry there (CAN logs have
  no framing field: "can" whatever the frames; default `name`);
* `replay_unit`: a recorded unit as replay writes it again (`replays_received`: a unit it received may be
  written back as is; XBee and MAVLink frames name their receiver or sender: re-encoded); default, the unit
  itself where the record is in this framing;
* `narrow`: a unit cut down to carry only some of its messages, where the unit says more than its messages
  (an XBee frame its sender, a zenoh sample its key; `narrows` says it does); default None;
* `can_id`: the arbitration ID a message goes in, on a medium with IDs (CAN); default None.
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from typing import ClassVar, Generic, TypeVar

from ..auth import Tagged
from ..counters import Counters
from ..wire import Message, Op

__all__ = ["Framing", "NoRoomForTags", "SerialFraming"]


class NoRoomForTags(TypeError):
    """A framing without room for tags was asked to carry them (a link on it cannot require tags)."""

Unit = TypeVar("Unit")


class Framing(abc.ABC, Generic[Unit]):
    name: str
    drops: Counters
    transmit_only: ClassVar[bool] = False  # True: `feed` raises TransmitOnlyError (nothing comes back)
    names_senders: ClassVar[bool] = False  # True: `sender_of` reads who transmitted a unit from the unit itself
    names_sources: ClassVar[bool] = False  # True: `source_of` says more than the sender a unit claims
    reports_link_quality: ClassVar[bool] = False  # True: `link_quality_of` reads RSSI/quality from a unit
    carries_tags: bool = False  # True: room for a message's epoch and tag (SPEC.md 10.5); per instance: CAN FD has it
    capture_medium: ClassVar[str] = "serial"  # a key of capture.records.WRITERS
    replays_received: ClassVar[bool] = True  # False: a unit it received is re-encoded by replay, not written back
    narrows: ClassVar[bool] = False  # True: `narrow` keeps what a unit says beyond its messages

    @abc.abstractmethod
    def encode(self, msg: Message) -> list[Unit]:
        """The units that carry `msg`, in transmission order."""

    @abc.abstractmethod
    def feed(self, unit: Unit) -> list[Message]:
        """Messages completed by this unit (possibly none); bad input is counted in `drops`."""

    def tick(self) -> None:  # an optional call: most framings have nothing to expire
        """One control period passed (expires stale partial state; no-op for most framings)."""

    def encode_batch(self, messages: list[Message]) -> list[Unit]:
        """The units that carry `messages`, as few as the medium allows (default: one `encode` each)."""
        encode = self.encode
        return [unit for msg in messages for unit in encode(msg)]

    def encode_tagged(self, records: Sequence[Tagged]) -> list[Unit]:
        """The units that carry `records`, messages with their epochs and tags (`carries_tags`)."""
        raise NoRoomForTags(f"{self.name} has no room for tags (SPEC.md 10.5)")

    def feed_tagged(self, unit: Unit) -> list[tuple[Message, Tagged | None]]:
        """Each message this unit completes with its record, None for one that came untagged."""
        return [(msg, None) for msg in self.feed(unit)]

    def sender_of(self, unit: Unit) -> int | None:
        """The transmitting node's id, where the medium names it (CAN IDs do); None otherwise."""
        return None

    def source_of(self, unit: Unit) -> str | None:
        """Who really sent `unit`, where the medium says more than the sender it claims; None otherwise."""
        return None

    def link_quality_of(self, unit: Unit) -> int | None:
        """The RSSI or link quality the medium reports with `unit` (`reports_link_quality`); None otherwise."""
        return None

    @property
    def capture_name(self) -> str:
        """The framing name its units' records carry in a capture."""
        return self.name

    def replay_unit(self, unit: Unit, recorded_as: str, direction: str) -> Unit | None:
        """`unit`, recorded in framing `recorded_as` going `direction` (rx, tx), as replay writes it as is onto a
        link of this framing; None: replay re-encodes its messages instead."""
        if recorded_as != self.capture_name or not (direction == "tx" or self.replays_received):
            return None
        return unit

    def narrow(self, unit: Unit, messages: list[Message]) -> Unit | None:
        """`unit` carrying only `messages` (some of its own), keeping what else it says (`narrows`); None for
        none, and where the medium's units say nothing beyond their messages (re-encode those instead)."""
        return None

    def can_id(self, op: Op, sender: int) -> int | None:
        """The arbitration ID a message of `op` from `sender` goes in, on a medium with IDs; None otherwise."""
        return None


class SerialFraming(Framing[bytes]):
    """A framing for a UART byte stream, with the line defaults a serial link needs."""

    default_baud: ClassVar[int]  # the line speed its radios use unless told otherwise
    preamble: ClassVar[bytes]  # written before the first frame after every (re)open of the port

    @abc.abstractmethod
    def reset(self) -> None:
        """Forget any partial frame (the port was reopened: what came before is not continued)."""
