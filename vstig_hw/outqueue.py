"""The outgoing queue: one pending message per key, newest wins, PUTs first.

The paper keeps "only the most up-to-date message for a key" so that frequent
reads cannot build a backlog. A replaced message keeps its place in line, so a
key that changes every step still gets its turn instead of starving.

This sits on the receive hot path, so it reads messages as their wire words
(`msg[0]` is op<<15 | key, `msg[2]` the timestamp) rather than by property.
"""

from __future__ import annotations

from collections import OrderedDict

from .timestamps import is_newer
from .wire import GET_BIT, KEY_MAX, Message

__all__ = ["OutQueue", "replaces", "same_entry"]


def same_entry(msg: Message, pending: Message) -> bool:
    """Whether two messages for one key carry the same entry (timestamp, value, robot), whatever their ops."""
    return msg[2] == pending[2] and msg[1] == pending[1] and msg[3] == pending[3]


def replaces(msg: Message, pending: Message) -> bool:
    """Whether `msg` takes the place of `pending`, the message waiting for the same key (SPEC section 5).

    At the same timestamp the pending message stays if it carries the same
    entry, whatever the ops: a GET of an entry repairs every neighbour a PUT
    of it does, and also makes newer neighbours answer, while a pending PUT
    already leaves before every GET. If it carries another entry, that entry
    lost a conflict since (every message queued carries the sender's entry
    of the moment), so `msg` replaces it and the loser is never sent.
    """
    if msg[2] == pending[2]:
        return msg[1] != pending[1] or msg[3] != pending[3]
    return is_newer(msg[2], pending[2])


class OutQueue:
    def __init__(self) -> None:
        self._puts: OrderedDict[int, Message] = OrderedDict()
        self._gets: OrderedDict[int, Message] = OrderedDict()

    def __len__(self) -> int:
        return len(self._puts) + len(self._gets)

    def push(self, msg: Message) -> bool:
        """Queue `msg` unless a message at least as new for its key is pending (see `replaces`); True if queued."""
        head = msg[0]
        key = head & KEY_MAX
        is_get = head & GET_BIT
        puts = self._puts
        pending = puts.get(key)
        if pending is None:
            pending = self._gets.get(key)
        if pending is not None:
            if not replaces(msg, pending):
                return False
            if pending[0] & GET_BIT != is_get:
                (self._gets if is_get == 0 else puts).pop(key)
        (self._gets if is_get else puts)[key] = msg
        return True

    def pending(self, key: int) -> Message | None:
        """The message waiting for `key`, if any."""
        msg = self._puts.get(key)
        return self._gets.get(key) if msg is None else msg

    def remove(self, key: int) -> None:
        """Take `key`'s waiting message out of line, if there is one."""
        if self._puts.pop(key, None) is None:
            self._gets.pop(key, None)

    def pop(self) -> Message:
        """The message whose turn it is (the oldest PUT, else the oldest GET), taken out of line."""
        return (self._puts or self._gets).popitem(last=False)[1]

    def drain(self, budget: int | None = None) -> list[Message]:
        """Up to `budget` messages (all if None), PUTs before GETs, oldest first."""
        if budget is None or budget >= len(self._puts) + len(self._gets):  # all of it (the common case)
            out = [*self._puts.values(), *self._gets.values()]
            self._puts.clear()
            self._gets.clear()
            return out
        if budget == 1:  # the paper's bandwidth, and the simulator's hot path
            queue = self._puts or self._gets
            return [queue.popitem(last=False)[1]] if queue else []
        if budget < 0:
            raise ValueError(f"budget must be >= 0, got {budget}")
        out = []
        for queue in (self._puts, self._gets):
            while queue and len(out) < budget:
                out.append(queue.popitem(last=False)[1])
        return out
