"""A link: one transport plus one framing, the unit the gateway wires together; and the spec that names one."""

from __future__ import annotations

import abc
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, Generic, Protocol, TypeVar, runtime_checkable

from ..auth import Tagged
from ..counters import Counters
from ..framing.base import Framing
from ..tagged import AuthPolicy
from ..transports.base import PeerClock, Transport
from ..wire import Message, Op

Unit = TypeVar("Unit")


@dataclass(frozen=True, slots=True)
class Heard:
    """One message received on a link, with when and (where the medium tells) from whom."""

    message: Message
    link: str
    t: float
    sender: int | None = None


class Link(Generic[Unit]):
    """One transport plus one framing: what the gateway and replay read, decode and write through.

    The gateway, the Python API and the CLI never reach past a Link into its framing or
    transport: they read (`read`, or the device's callback via `deliver_to`), decode
    (`decode`), name senders (`sender_of`, `source_of`) and write (`units_of`,
    `write_nowait`, `write`) through these, which are the framing's and transport's own
    methods bound once here, so they cost no call of their own on the hot path; and they
    ask what else the medium knows through the properties and methods below. Two places
    reach past it by design, and only they: the compiled path's choice of its Receiver,
    Encoder and read (gateway/compiled.py: the C twin is built from the framing's
    parameters and reads the transport's declared CompiledHandle), and the ROS 2 part
    (gateway/ros2.py: it publishes through the ROS 2 transport and stamps its framing).
    tests/unit/test_link_boundary.py holds every other module of gateway/, api/ and cli/ to it.

    `one_domain`: every node on the medium hears every frame any of them sends (a CAN bus, a
    blabbermouth relay), so an engine gateway does not echo an entry back onto the link it came
    from (docs/explanation/design.md, "Echo suppression"). False, the safe default, where a robot may be out of
    another's range (radios): there the re-broadcast carries the entry a hop further.
    """

    # declared: the compiled data path (vstig_hw/_cext) reads these too
    name: str
    transport: Transport[Unit]
    one_domain: bool
    counters: Counters

    def __init__(self, name: str, transport: Transport[Unit], framing: Framing[Unit], *,
                 one_domain: bool = False) -> None:
        self.name = name
        self.transport = transport
        self.framing = framing
        self.one_domain = one_domain
        self.counters = Counters()
        self.auth = AuthPolicy.OFF  # its spec's auth= (set as links are assembled): a gateway with a swarm key keeps it
        # Each message's record, on a link that sends its entries' proofs (set by a Node with the swarm key)
        self.record_of: Callable[[Message], Tagged | None] | None = None
        self.opened = False  # open() was called and close() was not: a Link may come already open
        # The device and the framing, as the gateway and replay use them (bound once: see the class docstring).
        self.read: Callable[[float], list[Unit]] = transport.read  # units within a timeout (maybe none)
        self.write: Callable[[Unit], None] = transport.write  # one unit; may wait on the device
        self.write_nowait: Callable[[Unit], Unit | None] = transport.write_nowait  # never waits: what was not taken
        self.deliver_to = transport.deliver_to  # the device's own thread hands over what it heard (or not)
        # The messages a unit completes: the framing's `feed`; a transmit-only framing's units are counted.
        self.decode: Callable[[Unit], list[Message]] = self._undecodable if framing.transmit_only else framing.feed
        self.sender_of: Callable[[Unit], int | None] = framing.sender_of  # where the medium names senders
        self.source_of: Callable[[Unit], str | None] = framing.source_of  # who really sent it, where that is more
        # The messages a unit completes, each with its record where it carries a tag (`carries_tags`).
        self.feed_tagged: Callable[[Unit], list[tuple[Message, Tagged | None]]] = framing.feed_tagged

    @property
    def transmit_only(self) -> bool:
        """Nothing comes back on this link (an overhead controller): no neighbour can answer here."""
        return self.framing.transmit_only

    @property
    def listening(self) -> tuple[str, ...]:
        """The endpoints others reach this link by (a zenoh link's listeners); none for most media."""
        return self.transport.listening

    @property
    def about(self) -> str:
        """Where the link listens and connects, in one line ("": nothing to say)."""
        return self.transport.about

    @property
    def unreached(self) -> str | None:
        """Where the link was told to connect and reaches nobody now (a zenoh link's connect=), or None."""
        return self.transport.unreached

    # -- what the medium knows, asked through the link (the framing's and the transport's declarations) --------
    @property
    def connected(self) -> bool:
        """Whether the device is there now."""
        return self.transport.connected

    @property
    def clock(self) -> PeerClock | None:
        """What measures the peers' clocks over the device (Zenoh's round trips), where it can."""
        return self.transport.clock

    @property
    def names_senders(self) -> bool:
        """Whether `sender_of` reads who transmitted a unit from the unit itself."""
        return self.framing.names_senders

    @property
    def names_sources(self) -> bool:
        """Whether `source_of` says more than the sender a unit claims (a zenoh session)."""
        return self.framing.names_sources

    @property
    def carries_tags(self) -> bool:
        """Whether the medium has room for a message's epoch and tag (SPEC.md 10.5)."""
        return self.framing.carries_tags

    @property
    def capture_medium(self) -> str:
        """The capture format its units go into without .mcap (a key of capture.records.WRITERS)."""
        return self.framing.capture_medium

    @property
    def capture_name(self) -> str:
        """The framing name its units' records carry in a capture."""
        return self.framing.capture_name

    def replay_unit(self, unit: Unit, recorded_as: str, direction: str) -> Unit | None:
        """A recorded unit as replay writes it as is onto this link (`Framing.replay_unit`); None: re-encode."""
        return self.framing.replay_unit(unit, recorded_as, direction)

    def can_id(self, op: Op, sender: int) -> int | None:
        """The arbitration ID a message of `op` from `sender` goes in, on a medium with IDs; None otherwise."""
        return self.framing.can_id(op, sender)

    def open(self) -> None:
        """Open the device; a link already open stays as it is (a Link object may be handed over open)."""
        if not self.opened:
            self.transport.open()
            self.opened = True

    def close(self) -> None:
        self.opened = False
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
        framing = self.framing
        if self.record_of is not None:
            units = self._tagged_units(messages, self.record_of)
        # One message (a quiet link's usual batch): its own units, without a batching call around them.
        elif len(messages) == 1:
            units = framing.encode(messages[0])
        else:
            units = framing.encode_batch(messages)
        if len(units) > 1 and isinstance(units[0], bytes):
            units = [b"".join(units)]  # type: ignore[list-item,arg-type]  # Unit is bytes here
        return units

    def _tagged_units(self, messages: list[Message], record_of: Callable[[Message], Tagged | None]) -> list[Unit]:
        """Each message with its entry's record; one without a verified proof goes untagged, or on a link that
        requires tags not at all (`held_unverified`)."""
        records, plain = [], []
        for msg in messages:
            record = record_of(msg)
            if record is not None:
                records.append(record)
            elif self.auth is AuthPolicy.REQUIRE:
                self.counters["held_unverified"] += 1
            else:
                plain.append(msg)
        framing = self.framing
        return (framing.encode_tagged(records) if records else []) + (framing.encode_batch(plain) if plain else [])

    def receive(self, timeout: float) -> list[Heard]:
        """Messages completed within `timeout` seconds, read and decoded as the gateway does."""
        heard: list[Heard] = []
        for unit in self.read(timeout):
            now = time.time()
            sender = self.sender_of(unit)
            heard.extend(Heard(msg, self.name, now, sender) for msg in self.decode(unit))
        self.counters["in"] += len(heard)
        return heard

    def tick(self) -> None:
        self.framing.tick()

    def stats(self) -> Counters:
        """in/out plus the framing's drops and the transport's counters, in one place."""
        merged = Counters(self.counters)
        merged.update({f"drop_{reason}": n for reason, n in self.framing.drops.items()})
        merged.update(self.transport.counters)
        return merged

    def _undecodable(self, unit: Unit) -> list[Message]:
        """A transmit-only link's units (bytes from a stock overhead controller): counted, never decoded."""
        self.counters["drop_undecodable"] += 1
        return []


class LinkSpec(abc.ABC):
    """A parsed link spec (`links.parse`): every medium's spec dataclass subclasses it.

    `kind`, `name` and `build` are each medium's own; what only some media know is declared here with the
    answer a medium without it gives, so a command asks every spec the same question (python-can's `BusABC`
    is the model):

    * `capture_medium`: the capture format its units go into without .mcap (can, zenoh; default serial);
    * `stigmergy`, `for_table`: the table it carries (default 0) and the spec that carries another table on
      the same medium (29-bit CAN IDs, a zenoh key space); default, a ValueError naming the link;
    * `lossless`: the spec for a command that must not lose what it sends (Zenoh BLOCKs); default, itself;
    * `deployment`, `files_read`: a dialect link's deployment file, and every file building it reads;
    * `reach_note`: one line to tell the user about where it reaches (a bus only this process hears);
    * `auth`: the link's policy for untagged messages and bad tags (every kind's `auth=`, SPEC.md 10.6).
    """

    __slots__ = ()
    capture_medium: ClassVar[str] = "serial"  # a key of capture.records.WRITERS: bytes in our line capture
    auth: AuthPolicy = AuthPolicy.OFF  # each medium's spec has the field: `registry.parse` sets it

    @property
    @abc.abstractmethod
    def kind(self) -> str:
        """The scheme it was written with (can, serial, kilobot-ohc...)."""

    @property
    @abc.abstractmethod
    def name(self) -> str:
        """A short, space-free name for status lines and captures."""

    @abc.abstractmethod
    def build(self, name: str | None = None, *, robot_id: int = 0, listen_only: bool = False) -> Link[Any]:
        """The Link (not yet open); `robot_id` is the sender a link transmits under where the medium names one."""

    @property
    def stigmergy(self) -> int:
        """The table (Buzz's stigmergy id) its link carries: 0 where the medium has no field for it."""
        return 0

    def for_table(self, table: int, listening: tuple[str, ...] = ()) -> LinkSpec:
        """The spec that carries `table` beside this one's (`listening`: where this one's open link listens);
        ValueError, one line naming the link, where the medium carries one table."""
        raise ValueError(f"stigmergy: {self.kind}:{self.name} carries one table (a {self.kind} link has no "
                         "stigmergy field); a second table needs CAN with extended=1 or zenoh")

    def lossless(self, opening: float | None = None) -> LinkSpec:
        """The spec for a command that must not lose what it sends (put, get, replay); `opening`: the seconds a
        one-shot command lets the link take to open. Default: itself (the medium loses nothing it took)."""
        return self

    @property
    def deployment(self) -> str | None:
        """The deployment TOML file that maps a robot dialect's keys to ours, for links that speak one."""
        return None

    @property
    def files_read(self) -> tuple[str, ...]:
        """The files building its link reads (a deployment, a Zenoh config, a DDS profile)."""
        return (self.deployment,) if self.deployment else ()

    @property
    def reach_note(self) -> str | None:
        """A line for the user once its link is built, where it reaches less than they may think; else None."""
        return None


@runtime_checkable
class NamesSenders(Protocol):
    """A spec whose medium carries the sender's robot id in a field of limited width (CAN arbitration IDs)."""

    def check_sender(self, robot_id: int) -> None:
        """ValueError, one line naming the link, when `robot_id` does not fit the sender field."""
        ...
