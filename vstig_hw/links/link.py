"""A link: one transport plus one framing, the unit the gateway wires together; and the spec that names one."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Generic, Protocol, TypeVar, runtime_checkable

from ..counters import Counters
from ..framing.base import Framing
from ..transports.base import Transport
from ..wire import Message

Unit = TypeVar("Unit")


@dataclass(frozen=True, slots=True)
class Heard:
    """One message received on a link, with when and (where the medium tells) from whom."""

    message: Message
    link: str
    t: float
    sender: int | None = None


class Link(Generic[Unit]):
    """`one_domain`: every node on the medium hears every frame any of them sends (a CAN bus, a
    blabbermouth relay), so an engine gateway does not echo an entry back onto the link it came
    from (docs/explanation/design.md, "Echo suppression"). False, the safe default, where a robot may be out of
    another's range (radios): there the re-broadcast carries the entry a hop further."""

    def __init__(self, name: str, transport: Transport[Unit], framing: Framing[Unit], *,
                 one_domain: bool = False) -> None:
        self.name = name
        self.transport = transport
        self.framing = framing
        self.one_domain = one_domain
        self.counters = Counters()
        # What the framing offers beyond Framing, looked up once: a missing attribute costs an exception per look.
        self._encode_batch = getattr(framing, "encode_batch", None)
        self._sender_of = getattr(framing, "sender_of", None)
        self.source_of = getattr(framing, "source_of", None)  # who really sent a unit, where more than the link

    def open(self) -> None:
        self.transport.open()

    def close(self) -> None:
        self.transport.close()

    def send(self, msg: Message) -> None:
        for unit in self.framing.encode(msg):
            self.transport.write(unit)
        self.counters["out"] += 1

    def send_many(self, messages: list[Message]) -> None:
        """Send several messages at once, in as few writes as the medium allows.

        Framings that batch (CAN FD) pack them into fewer frames. On a byte stream
        (every serial framing) the units are joined into one write: the bytes on the
        wire are the same, and one system call instead of one per message keeps the
        gateway's loop from handing the GIL to a busy reader thread at each of them.
        """
        write = self.transport.write
        for unit in self.units_of(messages):
            write(unit)
        self.counters["out"] += len(messages)

    def units_of(self, messages: list[Message]) -> list[Unit]:
        """The units that carry `messages`, as few as the medium allows (see `send_many`)."""
        encode_batch = self._encode_batch
        if encode_batch is not None:
            units: list[Unit] = encode_batch(messages)
        else:
            encode = self.framing.encode
            units = [unit for msg in messages for unit in encode(msg)]
        if len(units) > 1 and isinstance(units[0], bytes):
            units = [b"".join(units)]  # type: ignore[list-item,arg-type]  # Unit is bytes here
        return units

    def receive(self, timeout: float) -> list[Heard]:
        """Messages completed within `timeout` seconds."""
        heard: list[Heard] = []
        for unit in self.transport.read(timeout):
            now = time.time()
            sender = self.sender_of(unit)
            heard.extend(Heard(msg, self.name, now, sender) for msg in self.framing.feed(unit))
        self.counters["in"] += len(heard)
        return heard

    def sender_of(self, unit: Any) -> int | None:
        """The transmitting node, where the medium names it (CAN IDs do); None otherwise."""
        sender = self._sender_of
        return sender(unit) if sender else None

    def tick(self) -> None:
        self.framing.tick()

    def stats(self) -> Counters:
        """in/out plus the framing's drops and the transport's counters, in one place."""
        merged = Counters(self.counters)
        merged.update({f"drop_{reason}": n for reason, n in self.framing.drops.items()})
        merged.update(self.transport.counters)
        return merged


@runtime_checkable
class LinkSpec(Protocol):
    """A parsed link spec (`links.parse`): every medium's spec dataclass has these."""

    @property
    def kind(self) -> str:
        """The scheme it was written with (can, serial, kilobot-ohc...)."""
        ...

    @property
    def name(self) -> str:
        """A short, space-free name for status lines and captures."""
        ...

    def build(self, name: str | None = None, *, robot_id: int = 0, listen_only: bool = False) -> Link[Any]:
        """The Link (not yet open); `robot_id` is the sender a link transmits under where the medium names one."""
        ...


@runtime_checkable
class NamesSenders(Protocol):
    """A spec whose medium carries the sender's robot id in a field of limited width (CAN arbitration IDs)."""

    def check_sender(self, robot_id: int) -> None:
        """ValueError, one line naming the link, when `robot_id` does not fit the sender field."""
        ...
