"""Captures from a program: `swarm.record(path)` writes what the swarm's links hear, as `vstig record` does.

The same writers and the same rules: the format follows the extension (CAN
logs by theirs, serial and zenoh our line formats, `.mcap` for links of several
media, with the mcap extra); an existing file is never replaced unless
`overwrite`; `max_bytes` rotates to numbered files. Units are written on the
gateway thread as they are read, and flushed every control step.
"""

from __future__ import annotations

import os
import threading
from typing import Any

from ..capture.decoded import Decoder, default_framings
from ..capture.files import RotatingCapture
from ..capture.plan import capture_medium
from ..capture.records import CAN_FRAMING, Record
from ..framing.can import CanFraming
from ..gateway.node import Node
from ..links.link import Link
from ..outputs import drop_setid, refuse_symlink

__all__ = ["Recording", "link_medium"]


def link_medium(link: Link[Any]) -> str:
    """The capture medium of a link's units: can, zenoh or serial (bytes)."""
    if isinstance(link.framing, CanFraming):
        return "can"
    return "zenoh" if type(link.framing).__name__ == "ZenohFraming" else "serial"


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
        # The node closes it once every unit it read is written (a stop delivers or counts).
        self._listening = node.listen(unit=self._write, tick=self._flush, closed=self.stop)

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
        with self._closing:
            if self.stopped:
                return
            self.stopped = True
            self._capture.close()

    def __enter__(self) -> Recording:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _write(self, source: Link[Any], t: float, unit: Any) -> None:
        if self.stopped:  # stopped from a listener in the middle of a batch
            return
        framing = CAN_FRAMING if isinstance(source.framing, CanFraming) else source.framing.name
        self._capture.write(Record(t, source.name, framing, unit))

    def _flush(self, node: Node) -> None:
        if not self.stopped:
            self._capture.flush()
