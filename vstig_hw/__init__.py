"""vstig-hw: put a lab PC into a robot swarm's virtual stigmergy through real radios."""

from importlib import import_module
from typing import TYPE_CHECKING, Any

from .wire import DecodeError, Message, Op, decode, encode

if TYPE_CHECKING:
    from .api import CaptureError, Change, HearsItself, NotTaken, Swarm, SwarmClosed, TransportError, join
    from .engine import Entry, Outcome, Stigmergy

__version__ = "0.1.0"

__all__ = ["CaptureError", "Change", "DecodeError", "Entry", "HearsItself", "Message", "NotTaken", "Op", "Outcome",
           "Stigmergy", "Swarm", "SwarmClosed", "TransportError", "__version__", "decode", "encode", "join"]

# The engine and the Python API load when first used, so `import vstig_hw` stays light: a command that
# only reads captures never loads the engine, and nothing starts threads or imports link modules.
_ENGINE = ("Entry", "Outcome", "Stigmergy")
_API = ("CaptureError", "Change", "HearsItself", "NotTaken", "Swarm", "SwarmClosed", "TransportError", "join")


def __getattr__(name: str) -> Any:
    if name in _ENGINE:
        from . import engine

        return getattr(engine, name)
    if name in _API:
        from . import api

        return getattr(api, name)
    if name == "aio":
        return import_module(".aio", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
