# Types of the compiled data path (vstig_hw/_cext, built by setup.py). Each type has the interface of the Python
# class it stands in for, and tests/native holds the two equal; the stub says so by naming that class as its base
# (the compiled types do not really subclass it: nothing checks them with isinstance).
from collections.abc import Sequence
from typing import Any

from .counters import Counters
from .engine import Entry, Outcome, Stigmergy
from .gateway.guard import Guard
from .wire import Message

KEYS: int

def setup(message: type[Message], entry: type[Entry], outcomes: tuple[Outcome, ...],
          rules: tuple[Any, Any, Any]) -> None: ...

class Engine(Stigmergy): ...

class JumpGuard(Guard):
    def __init__(self, max_jump: int, learn: float | None = None) -> None: ...
    def view(self, key: int) -> tuple[int, int, int] | None: ...

class Receiver:
    def __init__(self, framing: str, drops: Counters, *, expiry_ticks: int = 3, kilobot_type: int = 0x56,
                 extended: bool = False, base: int | None = None, stigmergy: int = 0) -> None: ...
    def feed(self, unit: Any) -> list[Message]: ...
    def tick(self) -> None: ...
    def reset(self) -> None: ...

class Encoder:
    def __init__(self, framing: str, *, kilobot_type: int = 0x56, extended: bool = False, base: int | None = None,
                 stigmergy: int = 0, sender: int = 0, fd: bool = False, brs: bool = True,
                 frame_type: Any = None) -> None: ...
    def encode_batch(self, messages: Sequence[Message]) -> list[Any]: ...
