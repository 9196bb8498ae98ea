"""Counts and ids as people read them in the CLI's output and the library's messages."""

from __future__ import annotations

__all__ = ["counted", "shown_sender"]


def counted(count: int, noun: str, plural: str | None = None) -> str:
    """`1 message`, `2 messages`, `0 messages`: the count and its noun in the right number
    (`plural` for a noun that does not take an s: `counted(n, "entry", "entries")`)."""
    return f"{count} {noun if count == 1 else plural or noun + 's'}"


def shown_sender(sender: int) -> str:
    """A sender as people write it, and as --sender takes it back: a node id (CAN, zenoh) in decimal,
    an XBee module's 64-bit address in hex, as printed on the module."""
    return str(sender) if sender <= 0xFFFF else f"0x{sender:016X}"
