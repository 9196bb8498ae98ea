"""libvstig builds where a firmware author builds it, holds no state of its own, and says no when it is full.

The Makefile builds it for the host and, with avr-gcc, for the Kilobot's ATmega328P, warnings as errors and
pedantic; the objects have no writable data (every structure is the caller's); a table, a queue or a guard at
its compile-time capacity refuses and counts, never overwrites; a caller built with other capacities than the
library is refused at init.
"""

from __future__ import annotations

import ctypes
import re
import subprocess
from ctypes import byref, c_uint16
from pathlib import Path

import pytest
from clib import LIBVSTIG, STRICT, CGuard, CMsg, COutQueue, CStigmergy, Lib
from required import require_tool

from vstig_hw import Message, Op, Outcome


def _make(*args: str) -> None:
    done = subprocess.run([require_tool("make"), "-s", "-C", str(LIBVSTIG), *args], capture_output=True, text=True,
                          timeout=300, check=False)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]


@pytest.fixture(scope="module")
def host_build(tmp_path_factory: pytest.TempPathFactory) -> Path:
    require_tool("gcc")
    folder = tmp_path_factory.mktemp("host")
    _make(f"BUILD={folder}", "CC=gcc", "host")
    return folder / "host"


def test_the_makefile_builds_the_library_and_writes_only_where_told(host_build: Path) -> None:
    assert (host_build / "libvstig.a").stat().st_size > 0
    assert not (LIBVSTIG / "build").exists()


def test_no_object_holds_writable_data(host_build: Path) -> None:
    """No global state: no object in .data or .bss (read-only tables only), so two engines, or two gateways'
    links, never share a byte."""
    table = subprocess.run([require_tool("objdump", "binutils"), "-t", str(host_build / "libvstig.a")],
                           capture_output=True, text=True, check=True).stdout
    objects = [line.split() for line in table.splitlines() if " O " in line]
    writable = [o for o in objects if o[3] in (".data", ".bss", "*COM*") or (o[3].startswith((".data.", ".bss."))
                and not o[3].startswith(".data.rel.ro"))]
    assert objects and not writable, writable  # drop_names is there, read-only


def test_it_builds_for_an_atmega328p_warnings_as_errors(tmp_path: Path) -> None:
    require_tool("avr-gcc", "gcc-avr and avr-libc")
    _make(f"BUILD={tmp_path}", "KEYS=16", "avr", "robot")
    elf = tmp_path / "avr" / "avr_robot.elf"
    header = subprocess.run([require_tool("avr-objdump", "binutils-avr"), "-f", str(elf)], capture_output=True,
                            text=True, check=True).stdout
    assert "elf32-avr" in header


def test_the_readme_main_loop_compiles_for_the_host_and_the_avr(tmp_path: Path) -> None:
    text = (LIBVSTIG / "README.md").read_text(encoding="utf-8")
    (snippet,) = re.findall(r"```c\n(.*?)```", text, flags=re.S)
    source = tmp_path / "robot.c"
    source.write_text(snippet, encoding="utf-8")
    for compiler in (require_tool("gcc"), require_tool("avr-gcc", "gcc-avr and avr-libc")):
        target = ["-mmcu=atmega328p"] if "avr" in compiler else []
        done = subprocess.run([compiler, *target, *STRICT, "-DVSTIG_KEYS=16u", "-I", str(LIBVSTIG), "-c",
                               str(source), "-o", str(tmp_path / "robot.o")], capture_output=True, text=True,
                              check=False)
        assert done.returncode == 0, done.stderr


def test_a_full_table_refuses_a_new_key_and_counts_it(small_lib: Lib) -> None:
    assert small_lib.keys == 4
    engine = CStigmergy.on(small_lib)(1)
    for key in range(4):
        engine.put(key, key)
    with pytest.raises(MemoryError):
        engine.put(9, 9)
    with pytest.raises(MemoryError):
        engine.receive(Message(Op.PUT, 10, 1, 5, 2))
    assert engine.size() == 4 and engine.entry(9) is None and engine.entry(10) is None
    assert small_lib.dll.shim_engine_count(engine._memory, 7) == 1  # VSTIG_FULL, counted beside the outcomes
    assert engine.receive(Message(Op.PUT, 3, 7, 9, 2)) is Outcome.STORED  # a key it holds still moves
    assert engine.entry(3) == (7, 9, 2)


def test_a_full_queue_refuses_and_counts_and_keeps_what_it_holds(small_lib: Lib) -> None:
    queue = COutQueue.on(small_lib)()
    held = [Message(Op.PUT, key, 1, 1, 1) for key in range(4)]
    for msg in held:
        assert queue.push(msg)
    with pytest.raises(MemoryError):
        queue.push(Message(Op.GET, 99, 0, 0, 1))
    assert queue.full == 1
    assert queue.push(Message(Op.PUT, 2, 5, 2, 1))  # a key it holds is still replaced by newer news
    assert queue.drain() == [*held[:2], Message(Op.PUT, 2, 5, 2, 1), held[3]]
    engine = CStigmergy.on(small_lib)(1)
    for key in range(4):
        engine.get(100 + key)  # four unknown keys asked for fill the engine's queue
    engine.put(1, 1)  # stored, but no room to send it: counted, never an overwrite of a pending message
    assert small_lib.dll.shim_engine_queue_full(engine._memory) == 1
    assert [m.key for m in engine.drain()] == [100, 101, 102, 103]


def test_a_full_guard_refuses_keys_it_cannot_track(small_lib: Lib) -> None:
    guard = CGuard(small_lib, 255, 1000)
    for key in range(4):
        assert guard.check(Message(Op.PUT, key, 1, 1, 1), 0) == 0
    assert guard.check(Message(Op.PUT, 7, 1, 1, 1), 0) == 2  # VSTIG_GUARD_FULL
    assert guard.full == 1
    assert guard.check(Message(Op.PUT, 1, 1, 300, 1), 0) == 1  # a tracked key is still guarded: a jump


def test_init_refuses_a_caller_built_with_other_capacities(lib: Lib, small_lib: Lib) -> None:
    """The init macros pass the caller's sizeof: a struct laid out for 4 keys handed to a 32768-key library."""
    memory = small_lib.block("engine")
    assert lib.dll.vstig_engine_init_sized(memory, len(memory), 1, None, None, None) == -1  # VSTIG_ERR_CONFIG
    queue = small_lib.block("outqueue")
    assert lib.dll.vstig_outqueue_init_sized(queue, len(queue)) == -1
    guard = small_lib.block("guard")
    assert lib.dll.vstig_guard_init_sized(guard, len(guard), 255, 1000, 0xFFFFFFFF) == -1


def test_out_of_range_arguments_are_refused(lib: Lib) -> None:
    assert CGuard(lib, 0, 1000).status == -2
    assert CGuard(lib, 0x8000, 1000).status == -2
    assert CGuard(lib, 255, 0).status == -2
    engine = CStigmergy.on(lib)(1)
    assert lib.dll.vstig_engine_put(engine._memory, 0x8000, 1) == -2
    assert lib.dll.vstig_engine_get(engine._memory, 0x8000, byref(c_uint16())) == -2
    assert engine.pending() == 0
    assert lib.dll.vstig_serial_rx_init(lib.block("serial_rx"), 3, 0, None) == -2
    assert lib.dll.vstig_serial_rx_init(lib.block("serial_rx"), 2, 0x80, None) == -2
    assert lib.dll.vstig_serial_rx_init(lib.block("serial_rx"), 1, 0, None) == -2  # epuck4 without a reassembler


def test_a_batch_gives_what_one_message_at_a_time_gives(lib: Lib) -> None:
    messages = [Message(Op.PUT, 1, 5, 2, 7), Message(Op.GET, 1, 0, 1, 3), Message(Op.PUT, 1, 6, 2, 9),
                Message(Op.GET, 2, 0, 0, 3), Message(Op.PUT, 3, 1, 0, 3)]
    one, batch = CStigmergy.on(lib)(1), CStigmergy.on(lib)(1)
    assert batch.receive_many(messages) == [one.receive(m) for m in messages] == [
        Outcome.STORED, Outcome.ANSWERED, Outcome.CONFLICT, Outcome.UNKNOWN, Outcome.INVALID]
    assert batch.drain() == one.drain()
    assert ctypes.sizeof(CMsg) == 10
