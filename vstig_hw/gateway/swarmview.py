"""What a sniffer learns from traffic: per key, the newest entry and who still lags behind.

Pure bookkeeping fed `Heard` messages; the `sniff` command draws it. A sender
holds a stale view of a key when the last message it sent for that key carried
an older timestamp than the newest one seen (only where the link names senders,
as CAN IDs do).

Two writes with the same timestamp from different robots are a conflict: the
view settles it with the engine's rule (`higher_robot_wins` unless told
otherwise), so it shows what every robot's engine will hold, and counts it once,
however often either side is relayed afterwards.

A message a guard refused (`refuse`) is counted under its key, with the latest
one and why; it never changes the entry shown.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..engine import ConflictResolver, Entry, higher_robot_wins
from ..links.link import Heard
from ..timestamps import is_newer
from ..wire import Message, Op

__all__ = ["KeyView", "SwarmView"]


@dataclass
class KeyView:
    value: int = 0
    timestamp: int = 0
    robot: int = 0
    last_seen: float = 0.0
    puts: int = 0
    gets: int = 0
    conflicts: int = 0
    sender_ts: dict[int, int] = field(default_factory=dict)  # sender -> timestamp of its last message
    contenders: set[int] = field(default_factory=set)  # robots that wrote the shown timestamp
    refused: int = 0  # messages a guarded bridge would refuse (shown, never part of the entry)
    last_refused: str = ""  # the latest of them and why, e.g. "jump: ts 32767 robot 9"
    refused_reason: str = ""  # why the latest was refused, its drop counter without `drop_`: "jump"

    @property
    def has_entry(self) -> bool:
        """False for a key only ever asked for (empty GETs): its value, timestamp and robot mean nothing yet."""
        return self.timestamp != 0  # a PUT never carries timestamp 0 (SPEC section 2)

    def stale_senders(self) -> list[int]:
        return sorted(s for s, ts in self.sender_ts.items() if is_newer(self.timestamp, ts))


class SwarmView:
    def __init__(self, onconflict: ConflictResolver = higher_robot_wins) -> None:
        self.keys: dict[int, KeyView] = {}
        self.messages = 0
        self.onconflict = onconflict

    def add(self, heard: Heard) -> None:
        self.add_message(heard.message, heard.t, heard.sender)

    def add_message(self, msg: Message, t: float, sender: int | None) -> None:
        """`add` without a `Heard` to build: the live view's path, per message of a busy gateway."""
        view = self._seen(msg.key, t)
        if msg.op is Op.PUT:
            view.puts += 1
        else:
            view.gets += 1
        if sender is not None:
            view.sender_ts[sender] = msg.timestamp
        if msg.timestamp == 0:
            return  # an empty GET: says nothing about the entry
        if is_newer(msg.timestamp, view.timestamp):
            view.value, view.timestamp, view.robot = msg.value, msg.timestamp, msg.robot
            view.contenders = {msg.robot}
        elif msg.timestamp == view.timestamp and msg.robot != view.robot:
            if msg.robot not in view.contenders:  # a new write, not a relay of one already seen
                view.contenders.add(msg.robot)
                view.conflicts += 1
            local = Entry(view.value, view.timestamp, view.robot)
            winner = self.onconflict(msg.key, local, Entry(msg.value, msg.timestamp, msg.robot))
            view.value, view.robot = winner[0], winner[2]  # the winner keeps the timestamp, as in the engine

    def refuse(self, heard: Heard, reason: str) -> None:
        """A message a guard refused (`reason` its drop counter): counted and described, the entry unchanged."""
        msg = heard.message
        view = self._seen(msg.key, heard.t)
        view.refused += 1
        view.refused_reason = reason.removeprefix("drop_")
        view.last_refused = f"{view.refused_reason}: {msg.op.name} ts {msg.timestamp} robot {msg.robot}"

    def _seen(self, key: int, t: float) -> KeyView:
        view = self.keys.get(key)
        if view is None:
            view = self.keys[key] = KeyView()
        self.messages += 1
        view.last_seen = t
        return view
