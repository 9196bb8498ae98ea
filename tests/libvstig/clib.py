"""libvstig through ctypes, in the shapes of the Python reference: an engine with `Stigmergy`'s interface, an
outgoing queue with `OutQueue`'s, the jump guard, the serial receivers and the CAN framing.

Nothing here decides anything the library should: each call goes to the C function that does the work, and
only turns C's results into the Python types (an outcome into `Outcome`, a refused conflict winner into the
exception the Python engine raises for it, naming what the resolver returned).
"""

from __future__ import annotations

import ctypes
import subprocess
from collections.abc import Callable, Iterable, Iterator
from ctypes import POINTER, Structure, byref, c_size_t, c_uint8, c_uint16, c_uint32, c_void_p
from pathlib import Path
from typing import Any

from vstig_hw import Entry, Message, Op, Outcome
from vstig_hw.counters import Counters
from vstig_hw.engine import ConflictLost, ConflictResolver, higher_robot_wins, larger_value_wins, sum_merge
from vstig_hw.wire import KEY_MAX, U16_MAX, check_field

ROOT = Path(__file__).resolve().parents[2]
LIBVSTIG = ROOT / "firmware_spec" / "libvstig"
STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]
# Undefined behaviour stops the test process (ASan needs to be loaded first, so it runs in the driver).
SANITIZE = ["-fsanitize=undefined", "-fno-sanitize-recover=all"]

BAD_WINNER = 8
FULL = 7
DROP_NAMES = ("cobs", "crc", "bad_length", "overlong", "bad_index", "collision", "check", "stale", "duplicate",
              "foreign_type", "bad_version", "error_frame", "unknown_id", "remote_frame", "bad_dlc", "op_mismatch")


def build(gcc: str, folder: Path, keys: int = 32768, name: str = "libvstig") -> Path:
    """libvstig and the shim as one shared library with `keys` places in every table."""
    out = folder / f"{name}_{keys}.so"
    sources = [*sorted(LIBVSTIG.glob("vstig_*.c")), Path(__file__).with_name("shim.c")]
    done = subprocess.run([gcc, *STRICT, *SANITIZE, "-O2", "-g", "-fPIC", "-shared", f"-DVSTIG_KEYS={keys}u",
                           "-I", str(LIBVSTIG), "-o", str(out), *map(str, sources)],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, f"building {out.name} failed:\n{done.stderr}"
    return out


class CMsg(Structure):
    _fields_ = [("op", c_uint8), ("key", c_uint16), ("value", c_uint16), ("timestamp", c_uint16),
                ("robot", c_uint16)]

    @classmethod
    def of(cls, msg: Message) -> CMsg:
        return cls(int(msg.op), msg.key, msg.value, msg.timestamp, msg.robot)

    def message(self) -> Message:
        return Message(Op(self.op), self.key, self.value, self.timestamp, self.robot)


class CEntry(Structure):
    _fields_ = [("value", c_uint16), ("timestamp", c_uint16), ("robot", c_uint16)]

    def entry(self) -> Entry:
        return Entry(self.value, self.timestamp, self.robot)


class CFrame(Structure):
    _fields_ = [("id", c_uint32), ("extended", c_uint8), ("fd", c_uint8), ("brs", c_uint8), ("rtr", c_uint8),
                ("error", c_uint8), ("len", c_uint8), ("data", c_uint8 * 64)]


RESOLVER = ctypes.CFUNCTYPE(c_uint8, c_void_p, c_uint16, POINTER(CEntry), POINTER(CEntry), POINTER(CEntry))
LOST = ctypes.CFUNCTYPE(None, c_void_p, c_uint16, POINTER(CEntry))

_SIGNATURES: dict[str, tuple[Any, list[Any]]] = {
    "vstig_engine_init_sized": (ctypes.c_int, [c_void_p, c_size_t, c_uint16, c_void_p, c_void_p, c_void_p]),
    "vstig_engine_put": (ctypes.c_int, [c_void_p, c_uint16, c_uint16]),
    "vstig_engine_get": (ctypes.c_int, [c_void_p, c_uint16, POINTER(c_uint16)]),
    "vstig_engine_entry": (c_uint8, [c_void_p, c_uint16, POINTER(CEntry)]),
    "vstig_engine_at": (c_uint8, [c_void_p, c_uint16, POINTER(c_uint16), POINTER(CEntry)]),
    "vstig_engine_receive": (ctypes.c_int, [c_void_p, POINTER(CMsg)]),
    "vstig_engine_receive_many": (None, [c_void_p, POINTER(CMsg), c_size_t, POINTER(c_uint8)]),
    "vstig_engine_drain": (c_size_t, [c_void_p, POINTER(CMsg), c_size_t]),
    "vstig_outqueue_init_sized": (ctypes.c_int, [c_void_p, c_size_t]),
    "vstig_outqueue_push": (c_uint8, [c_void_p, POINTER(CMsg)]),
    "vstig_outqueue_drain": (c_size_t, [c_void_p, POINTER(CMsg), c_size_t]),
    "vstig_guard_init_sized": (ctypes.c_int, [c_void_p, c_size_t, c_uint16, c_uint16, c_uint32]),
    "vstig_guard_check": (c_uint8, [c_void_p, POINTER(CMsg), c_uint32]),
    "vstig_guard_view": (c_uint8, [c_void_p, c_uint16, POINTER(c_uint16), POINTER(c_uint16), POINTER(c_uint16)]),
    "vstig_can_init": (ctypes.c_int, [c_void_p, c_uint8, c_uint32, c_uint8, c_uint16, c_uint8, c_uint8]),
    "vstig_can_receive": (c_size_t, [c_void_p, POINTER(CFrame), POINTER(CMsg), POINTER(c_uint16)]),
    "vstig_can_encode": (c_size_t, [c_void_p, POINTER(CMsg), c_size_t, POINTER(CFrame)]),
    "vstig_serial_rx_init": (ctypes.c_int, [c_void_p, c_uint8, c_uint8, c_void_p]),
    "vstig_serial_receive": (c_size_t, [c_void_p, ctypes.c_char_p, c_size_t, POINTER(c_size_t), POINTER(CMsg),
                                        c_size_t]),
    "vstig_epuck4_init": (None, [c_void_p, c_uint8]),
    "vstig_epuck4_tick": (None, [c_void_p]),
    "vstig_epuck4_feed": (c_uint8, [c_void_p, c_uint32, POINTER(CMsg)]),
    "shim_engine_count": (c_uint32, [c_void_p, ctypes.c_uint]),
    "shim_engine_size": (c_uint16, [c_void_p]),
    "shim_engine_pending": (c_uint16, [c_void_p]),
    "shim_engine_queue_full": (c_uint32, [c_void_p]),
    "shim_queue_len": (c_uint16, [c_void_p]),
    "shim_queue_full": (c_uint32, [c_void_p]),
    "shim_guard_full": (c_uint32, [c_void_p]),
    "shim_can_drops": (POINTER(c_uint16 * 16), [c_void_p]),
    "shim_serial_drops": (POINTER(c_uint16 * 16), [c_void_p]),
    "shim_epuck4_drops": (POINTER(c_uint16 * 16), [c_void_p]),
    "shim_keys": (c_uint32, []),
    "shim_engine_entries": (c_uint16, [c_void_p, POINTER(c_uint16), POINTER(CEntry)]),
}


class Lib:
    """One build of libvstig, loaded; `sizeof[name]` is each structure's size in that build."""

    def __init__(self, path: Path) -> None:
        self.dll = ctypes.CDLL(str(path))
        for name, (result, args) in _SIGNATURES.items():
            function = getattr(self.dll, name)
            function.restype, function.argtypes = result, args
        self.sizeof = {name: getattr(self.dll, f"shim_sizeof_{name}")() for name in
                       ("engine", "outqueue", "guard", "can", "can_frame", "serial_rx", "epuck4")}
        self.keys = self.dll.shim_keys()
        assert self.sizeof["can_frame"] == ctypes.sizeof(CFrame), "CFrame does not match vstig_can_frame_t"

    def block(self, name: str) -> ctypes.Array[ctypes.c_char]:
        """Zeroed memory for one structure, owned by Python (the library never allocates)."""
        return ctypes.create_string_buffer(self.sizeof[name])


def _drops(counts: Any) -> Counters:
    found = Counters()
    for name, count in zip(DROP_NAMES, counts.contents, strict=True):
        if count:
            found[name] = count
    return found


# The C rules that equal the Python ones, by the Python function.
BUILT_IN = {higher_robot_wins: "vstig_higher_robot_wins", larger_value_wins: "vstig_larger_value_wins",
            sum_merge: "vstig_sum_merge"}


class CStigmergy:
    """libvstig's engine with `vstig_hw.Stigmergy`'s interface. `onconflict` may be one of the Python rules
    with a C twin (then the C rule runs, `c_rule=True`) or any Python callable, called back from C."""

    lib: Lib

    def __init__(self, robot_id: int, onconflict: ConflictResolver | None = None,
                 onconflictlost: ConflictLost | None = None, *, c_rule: bool = True) -> None:
        check_field("robot_id", U16_MAX, robot_id)
        self.robot_id = robot_id
        self.onconflict = onconflict or higher_robot_wins
        self.onconflictlost = onconflictlost
        self._memory = self.lib.block("engine")
        self._returned: object = None  # what the Python resolver last returned
        self._raised: BaseException | None = None
        rule = BUILT_IN.get(self.onconflict) if c_rule else None
        resolver = ctypes.cast(getattr(self.lib.dll, rule), c_void_p) if rule else RESOLVER(self._resolve)
        self._callbacks = (resolver, LOST(self._lost))  # kept alive as long as the engine
        status = self.lib.dll.vstig_engine_init_sized(self._memory, len(self._memory), robot_id,
                                                      ctypes.cast(resolver, c_void_p),
                                                      ctypes.cast(self._callbacks[1], c_void_p), None)
        assert status == 0, f"vstig_engine_init: {status}"

    @classmethod
    def on(cls, lib: Lib) -> type[CStigmergy]:
        """This class bound to one build of the library (to stand in for `Stigmergy`)."""
        return type(cls.__name__, (cls,), {"lib": lib})

    def _resolve(self, ctx: object, key: int, local: Any, remote: Any, chosen: Any) -> int:
        try:
            returned = self.onconflict(key, local.contents.entry(), remote.contents.entry())
        except BaseException as error:  # raised again once C returns: it cannot cross the callback
            self._raised = error
            return 0
        self._returned = returned
        if not isinstance(returned, tuple) or len(returned) != 3:
            return 0
        chosen.contents.value, chosen.contents.timestamp, chosen.contents.robot = returned
        return 1

    def _lost(self, ctx: object, key: int, lost: Any) -> None:
        if self.onconflictlost:
            self.onconflictlost(key, lost.contents.entry())

    def put(self, key: int, value: int) -> None:
        check_field("key", KEY_MAX, key)
        check_field("value", U16_MAX, value)
        status = self.lib.dll.vstig_engine_put(self._memory, key, value)
        if status != 0:
            raise MemoryError(f"vstig_engine_put: the table is full ({status})")

    def get(self, key: int) -> int | None:
        check_field("key", KEY_MAX, key)
        value = c_uint16()
        return value.value if self.lib.dll.vstig_engine_get(self._memory, key, byref(value)) == 1 else None

    def has(self, key: int) -> bool:
        return self.entry(key) is not None

    def size(self) -> int:
        return int(self.lib.dll.shim_engine_size(self._memory))

    def entry(self, key: int) -> Entry | None:
        found = CEntry()
        return found.entry() if self.lib.dll.vstig_engine_entry(self._memory, key, byref(found)) else None

    def entries(self) -> Iterator[tuple[int, Entry]]:
        keys, found = (c_uint16 * self.lib.keys)(), (CEntry * self.lib.keys)()
        n = self.lib.dll.shim_engine_entries(self._memory, keys, found)  # vstig_engine_at over every place
        return iter(sorted(zip(keys[:n], (e.entry() for e in found[:n]), strict=True)))

    @property
    def counts(self) -> dict[Outcome, int]:
        return {outcome: int(self.lib.dll.shim_engine_count(self._memory, outcome)) for outcome in Outcome}

    def receive(self, msg: Message) -> Outcome:
        self._raised = None
        outcome = self.lib.dll.vstig_engine_receive(self._memory, byref(CMsg.of(msg)))
        if self._raised is not None:
            raise self._raised
        if outcome == BAD_WINNER:
            returned = self._returned
            if not isinstance(returned, tuple) or len(returned) != 3:
                raise TypeError(f"onconflict must return an Entry(value, timestamp, robot), got {returned!r}")
            raise ValueError(f"onconflict returned {Entry(returned[0], returned[1], returned[2])} for key "
                             f"{msg.key}: a new value must name this robot or the writer of one of the entries")
        if outcome == FULL:
            raise MemoryError("vstig_engine_receive: the table is full")
        return Outcome(outcome)

    def receive_many(self, messages: list[Message]) -> list[Outcome]:
        batch = (CMsg * len(messages))(*map(CMsg.of, messages))
        outcomes = (c_uint8 * len(messages))()
        self.lib.dll.vstig_engine_receive_many(self._memory, batch, len(messages), outcomes)
        return [Outcome(o) for o in outcomes]

    def drain(self, budget: int | None = None) -> list[Message]:
        return _drain(self.lib.dll.vstig_engine_drain, self._memory, self.pending() if budget is None else budget)

    def pending(self) -> int:
        return int(self.lib.dll.shim_engine_pending(self._memory))


def _drain(function: Callable[..., int], memory: Any, budget: int) -> list[Message]:
    if budget < 0:
        raise ValueError(f"budget must be >= 0, got {budget}")
    out = (CMsg * max(budget, 1))()
    return [m.message() for m in out[: function(memory, out, budget)]]


class COutQueue:
    """libvstig's outgoing queue with `vstig_hw.outqueue.OutQueue`'s interface."""

    lib: Lib

    def __init__(self) -> None:
        self._memory = self.lib.block("outqueue")
        assert self.lib.dll.vstig_outqueue_init_sized(self._memory, len(self._memory)) == 0

    @classmethod
    def on(cls, lib: Lib) -> type[COutQueue]:
        return type(cls.__name__, (cls,), {"lib": lib})

    def __len__(self) -> int:
        return int(self.lib.dll.shim_queue_len(self._memory))

    def push(self, msg: Message) -> bool:
        result = self.lib.dll.vstig_outqueue_push(self._memory, byref(CMsg.of(msg)))
        if result == 2:
            raise MemoryError("vstig_outqueue_push: full")
        return bool(result)

    def drain(self, budget: int | None = None) -> list[Message]:
        return _drain(self.lib.dll.vstig_outqueue_drain, self._memory, len(self) if budget is None else budget)

    @property
    def full(self) -> int:
        return int(self.lib.dll.shim_queue_full(self._memory))


class CGuard:
    """libvstig's jump guard; `now` in 1/`units` seconds."""

    def __init__(self, lib: Lib, max_jump: int, units: int, learn: int | None = None) -> None:
        self.lib = lib
        self._memory = lib.block("guard")
        never = 0xFFFFFFFF
        self.status = lib.dll.vstig_guard_init_sized(self._memory, len(self._memory), max_jump, units,
                                                     never if learn is None else learn)

    def check(self, msg: Message, now: int) -> int:
        return int(self.lib.dll.vstig_guard_check(self._memory, byref(CMsg.of(msg)), now & 0xFFFFFFFF))

    def view(self, key: int) -> tuple[int, int, int] | None:
        ts, robot, value = c_uint16(), c_uint16(), c_uint16()
        if not self.lib.dll.vstig_guard_view(self._memory, key, byref(ts), byref(robot), byref(value)):
            return None
        return ts.value, robot.value, value.value

    @property
    def full(self) -> int:
        return int(self.lib.dll.shim_guard_full(self._memory))


class CCan:
    """libvstig's CAN framing for one scheme and node (`status` 0, or the refusal)."""

    def __init__(self, lib: Lib, extended: bool, base: int | None, stigmergy: int, sender: int, fd: bool = False,
                 brs: bool = True) -> None:
        self.lib = lib
        self._memory = lib.block("can")
        self.status = lib.dll.vstig_can_init(self._memory, extended, 0xFFFFFFFF if base is None else base,
                                             stigmergy, sender, fd, brs)

    def receive(self, frame: CFrame) -> tuple[list[Message], int]:
        out, sender = (CMsg * 8)(), c_uint16()
        n = self.lib.dll.vstig_can_receive(self._memory, byref(frame), out, byref(sender))
        return [m.message() for m in out[:n]], sender.value

    def encode(self, messages: list[Message]) -> list[CFrame]:
        frames = (CFrame * max(len(messages), 1))()
        n = self.lib.dll.vstig_can_encode(self._memory, (CMsg * max(len(messages), 1))(*map(CMsg.of, messages)),
                                          len(messages), frames)
        return list(frames[:n])

    @property
    def drops(self) -> Counters:
        return _drops(self.lib.dll.shim_can_drops(self._memory))


class CSerial:
    """A serial link's receiver over buffers (`framing`: 0 cobs8, 1 epuck4, 2 kilobot), at most `most` messages
    a call, as a gateway's compiled read would take them."""

    def __init__(self, lib: Lib, framing: int, kilobot_type: int = 0x56, expiry_ticks: int = 3,
                 most: int = 64) -> None:
        self.lib = lib
        self.most = most
        self._rx = lib.block("serial_rx")
        self._epuck4 = lib.block("epuck4")
        lib.dll.vstig_epuck4_init(self._epuck4, expiry_ticks)
        self.status = lib.dll.vstig_serial_rx_init(self._rx, framing, kilobot_type, self._epuck4)

    def feed(self, data: bytes) -> list[Message]:
        out, used, got = (CMsg * self.most)(), c_size_t(), []
        while data:
            n = self.lib.dll.vstig_serial_receive(self._rx, data, len(data), byref(used), out, self.most)
            got += [m.message() for m in out[:n]]
            data = data[used.value:]
        return got

    def tick(self) -> None:
        self.lib.dll.vstig_epuck4_tick(self._epuck4)

    @property
    def drops(self) -> Counters:
        drops = _drops(self.lib.dll.shim_serial_drops(self._rx))
        drops.update(_drops(self.lib.dll.shim_epuck4_drops(self._epuck4)))
        return drops


def frame_of(can_id: int, data: bytes, *, extended: bool = False, fd: bool = False, brs: bool = False,
             rtr: bool = False, error: bool = False) -> CFrame:
    frame = CFrame(can_id, extended, fd, brs, rtr, error, len(data))
    frame.data[: len(data)] = list(data)
    return frame


def messages_hex(messages: Iterable[Message]) -> list[str]:
    return [f"{m.op.name} {m.key} {m.value} {m.timestamp} {m.robot}" for m in messages]
