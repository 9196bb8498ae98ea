"""Process-wide tuning for a gateway that relays frames promptly (`favour_latency`)."""

from __future__ import annotations

import gc
import sys

__all__ = ["SWITCH_INTERVAL", "favour_latency"]

SWITCH_INTERVAL = 0.0005  # seconds: how soon a reader thread with a frame gets the GIL from another thread


def favour_latency() -> None:
    """Tune this process for relaying frames promptly; call it once everything is imported and built.

    * Hand the GIL between threads every 0.5 ms instead of CPython's 5 ms, so a
      frame a reader thread has just read does not wait up to 5 ms while
      another thread runs Python.
    * Freeze what exists now (modules, links) out of the garbage collector's
      sight (`gc.freeze`). A full collection stops every thread while it walks
      the heap: with the CLI's imports that took 23-32 ms, every few seconds at
      5,000 frames/s, and each one delayed ~150 frames. Afterwards it walks only
      what the gateway allocated since, which is small.

    `vstig bridge` calls this; it is process-wide, so the library never does it by itself.
    """
    sys.setswitchinterval(SWITCH_INTERVAL)
    gc.collect()  # garbage frozen now would never be freed
    gc.freeze()
