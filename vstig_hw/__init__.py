"""vstig-hw: put a lab PC into a robot swarm's virtual stigmergy through real radios."""

from .engine import Entry, Outcome, Stigmergy
from .wire import DecodeError, Message, Op, decode, encode

__version__ = "0.1.0"

__all__ = ["DecodeError", "Entry", "Message", "Op", "Outcome", "Stigmergy", "__version__", "decode", "encode"]
