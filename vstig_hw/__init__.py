"""vstig-hw: put a lab PC into a robot swarm's virtual stigmergy through real radios."""

from typing import TYPE_CHECKING, Any

from .wire import DecodeError, Message, Op, decode, encode

if TYPE_CHECKING:
    from .engine import Entry, Outcome, Stigmergy

__version__ = "0.1.0"

__all__ = ["DecodeError", "Entry", "Message", "Op", "Outcome", "Stigmergy", "__version__", "decode", "encode"]

_ENGINE = ("Entry", "Outcome", "Stigmergy")


def __getattr__(name: str) -> Any:
    """The engine's names, imported on first use: a command that only reads captures never loads the engine."""
    if name in _ENGINE:
        from . import engine

        return getattr(engine, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
