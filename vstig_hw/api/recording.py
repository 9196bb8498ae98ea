"""Captures from a program: `swarm.record(path)` writes what the swarm's links hear, as `vstig record` does.

The same writers and the same rules: the format follows the extension (CAN
logs by theirs, serial and zenoh our line formats, `.mcap` for links of several
media, with the mcap extra); an existing file is never replaced unless
`overwrite`; `max_bytes` rotates to numbered files. Units are written on the
gateway thread as they are read, and flushed every control step.

What the gateway sends is recorded too (direction `tx`, when the device took it) where its outlets are the
Python ones (`Node.compiled` False: `vstig bridge --record` builds its Node so); the compiled outlets write
to the device themselves. The gateway's own decisions go in as notes (capture.decision_notes) in the formats
that keep notes: each tick, every link's drop counters and tx_overflow that grew, the engine's conflicts, and
the messages the guard refused (at most REFUSALS_PER_TICK named a tick).
"""

from __future__ import annotations

import os
import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

from ..capture.decision_notes import ENGINE_NOTES, QUEUED, REFUSALS_PER_TICK, counted_note, noted_counter, refusal_note
from ..capture.decoded import Decoder, default_framings
from ..capture.files import RotatingCapture
from ..capture.plan import capture_medium
from ..capture.records import Record
from ..engine import Outcome
from ..gateway.node import Node
from ..links.link import Heard, Link
from ..outputs import drop_setid, refuse_symlink

__all__ = ["Recording", "link_medium"]


def link_medium(link: Link[Any]) -> str:
    """The capture medium of a link's units: can, zenoh or serial (bytes)."""
    return link.capture_medium


class Recording:
    """One capture running; `stop()` ends it (the swarm's close does too). `records` and `files` say what it wrote."""

    def __init__(self, node: Node, path: str | os.PathLike[str], *, overwrite: bool = False,
                 max_bytes: int | None = None) -> None:
        path = os.fspath(path)
        medium = capture_medium(path, [link_medium(link) for link in node.links])
        if max_bytes is not None and (isinstance(max_bytes, bool) or not isinstance(max_bytes, int) or max_bytes < 1):
            raise ValueError(f"max_bytes must be a positive number of bytes (or None), got {max_bytes!r}")
        refuse_symlink(path)  # even with overwrite: a link would be written through
        if os.path.lexists(path) and not overwrite:
            raise FileExistsError(f"{path} exists: a capture is never replaced unless overwrite=True")
        drop_setid(path)
        if medium == "mcap":
            from ..extras import require

            require("mcap", f"a recording to {path}")
        self.path = path
        self._closing = threading.Lock()
        self._capture = RotatingCapture(path, medium, max_bytes, Decoder(default_framings()))
        self.stopped = False
        self._writing = threading.Lock()  # the links' writer threads record sends beside the node's thread
        self._node = node
        self._counted = [Counter(link.counters) for link in node.links]  # each link's counters at the last tick
        self._conflicts = self._engine_conflicts()
        self._refusals_named = 0  # this tick
        self._waiting = [0] * len(node.outlets)  # messages each outlet held at the last tick
        self.sends_recorded = not node.compiled
        self._untaps = [outlet.writer.tap(self._sent_on(outlet.link)) for outlet in node.outlets] \
            if self.sends_recorded else []
        # The node closes it once every unit it read is written (a stop delivers or counts).
        self._listening = node.listen(unit=self._write, refused=self._refused, tick=self._flush,
                                      closed=self.stop)

    @property
    def records(self) -> int:
        """Units written so far."""
        return self._capture.records

    @property
    def files(self) -> list[str]:
        """The files written (more than one once `max_bytes` rotated)."""
        return list(self._capture.files)

    def stop(self) -> None:
        """Stop recording and close the file (safe to call twice)."""
        self._listening.cancel()  # once it returns, no unit is being written any more
        for untap in self._untaps:
            untap()
        with self._closing:
            if self.stopped:
                return
            self._note_decisions()  # what was counted since the last tick
            with self._writing:
                self.stopped = True
                self._capture.close()

    def __enter__(self) -> Recording:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _write(self, source: Link[Any], t: float, unit: Any, direction: str = "rx") -> None:
        framing = source.capture_name
        with self._writing:
            if not self.stopped:  # stopped from a listener in the middle of a batch
                self._capture.write(Record(t, source.name, framing, unit, direction))

    def _sent_on(self, link: Link[Any]) -> Callable[[Any], None]:
        def sent(unit: Any) -> None:  # on the node's thread or the link's writer thread
            self._write(link, time.time(), unit, "tx")

        return sent

    def _note(self, text: str) -> None:
        with self._writing:
            if not self.stopped:
                self._capture.note(text)

    def _refused(self, heard: Heard, reason: str) -> None:
        if self._refusals_named < REFUSALS_PER_TICK:
            self._refusals_named += 1
            msg = heard.message
            self._note(refusal_note(heard.t, heard.link, reason, heard.sender, msg.key, msg.timestamp, msg.robot))

    def _engine_conflicts(self) -> int:
        engine = self._node.engine
        return 0 if engine is None else engine.counts[Outcome.CONFLICT]

    def _note_decisions(self) -> None:
        """A note for each decision counter that grew since the last tick (on the node's thread, under its lock)."""
        now = time.time()
        for link, before in zip(self._node.links, self._counted, strict=True):
            counters = link.counters.copy()  # one step: a writer thread may add a counter meanwhile
            for name, count in counters.items():
                if count != before[name] and noted_counter(name):
                    self._note(counted_note(now, link.name, name, count - before[name]))
            before.update(counters - before)
        for index, outlet in enumerate(self._node.outlets):  # a backlog is a state: noted when it changes
            waiting = len(outlet) + len(outlet.writer)
            if waiting != self._waiting[index]:
                self._note(counted_note(now, outlet.link.name, QUEUED, waiting))
                self._waiting[index] = waiting
        conflicts = self._engine_conflicts()
        if conflicts != self._conflicts:
            self._note(counted_note(now, ENGINE_NOTES, "conflict", conflicts - self._conflicts))
            self._conflicts = conflicts
        self._refusals_named = 0

    def _flush(self, node: Node) -> None:
        self._note_decisions()
        with self._writing:
            if not self.stopped:
                self._capture.flush()
