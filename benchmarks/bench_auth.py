"""Tags (issue 50, SPEC.md section 10): what checking and keeping them costs a gateway, and a tag on an AVR.

* A gateway's engine with tags beside it (`TaggedStigmergy`, a link that requires tags: every message's tag
  checked, each drained message given its record) against the plain engine on the same traffic (auth off).
  Both are the Python reference (the compiled twin is the relay's figure below).
* A gateway's relay, link to link (two CAN FD links on python-can's virtual bus, each read handed to the Node's
  delivery as its reader thread hands it): thread CPU per message with both links auth=require and the swarm key,
  against auth off, on the compiled path (the gateway's usual) and on the Python one; and with tags checked on the
  way in only (the check's own cost: a tagged CAN FD relay also sends a frame a message, SPEC.md 10.5).
* A robot radio lab's relay: `vstig bridge` (engine mode, compiled path) between two cobs8 ptys, both links
  auth=require with the swarm key against auth off, at one message a read (2,000 messages/s, one a write: the radio
  regime) and at ten: the process's CPU per message (rounds alternated, medians) and callgrind instructions per
  message, in one run. Unlike CAN FD, a tagged cobs8 frame carries one record where an untagged one carries one
  message: the frames per message are the same, only the bytes (24 against 12) and the tag's work differ.
* libvstig on a simulated ATmega328P (simavr, avr-gcc -Os): cycles per tag and per tag check, against one
  cobs8 frame of one message; flash and static RAM of vstig_auth, against the chip's.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import can

from vstig_hw import Stigmergy
from vstig_hw.auth import SwarmKeys
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.gateway import Node
from vstig_hw.links.assemble import assemble_links
from vstig_hw.tagged import AuthPolicy, TaggedStigmergy
from vstig_hw.wire import Message, Op

from .bench_datapath import COUNT, VSTIG, Frame, _median_run, _relay_run, cobs8_frame, instructions_per_msg
from .bench_wire import realistic_mix
from .registry import Result, benchmark, rate

_N = 20_000
_MASTER = bytes(range(32))
HERE = Path(__file__).resolve().parent
LIBVSTIG = HERE.parent / "firmware_spec" / "libvstig"
RUNS = 40
FLASH, SRAM = 32768, 2048  # ATmega328P


@benchmark("auth")
def relay_cpu_require_vs_off() -> Iterator[Result]:
    """Thread CPU per relayed message, links auth=require with the swarm key against auth off, on the compiled path
    (the gateway's usual) and the Python one; rounds alternated, medians."""
    keys = SwarmKeys(_MASTER)
    robot = CanFraming(CanIdScheme(), 5, fd=True)
    messages = [Message(Op.PUT, key, key, 1, 5) for key in range(1, 4001)]
    tagged = [robot.encode_tagged([keys.tag(msg, 0)]) for msg in messages]
    plain = [robot.encode(msg) for msg in messages]
    runs: dict[str, list[float]] = {}
    for round_ in range(ROUNDS):  # alternated: a busy spell weighs on every configuration alike
        for name, (policy_in, policy_out, units, pure) in _RELAYS.items():
            sent = tagged if units == "tagged" else plain
            runs.setdefault(name, []).append(_relay_us(policy_in, policy_out, sent, keys, pure, round_))
    us = {name: statistics.median(times) for name, times in runs.items()}
    yield Result("auth.relay_cpu_require_vs_off", us["require"], "us", "auth off, compiled path", us["off"])
    yield Result("auth.relay_cpu_require_in_vs_off", us["require_in"], "us", "auth off, compiled path", us["off"])
    yield Result("auth.relay_cpu_require_vs_off_python", us["require_python"], "us", "auth off, Python path",
                 us["off_python"])


# name -> (auth of link A, auth of link B, what robots send, pure). `require_in`: tags checked on the way in, the
# relay onto a link with auth off (frames packed as without tags): the check's own cost, without the CAN FD rule of
# one record a frame (SPEC.md 10.5) that makes a tagged relay send 8 frames where an untagged one packs 8 messages.
_RELAYS = {"off": ("off", "off", "plain", False), "require": ("require", "require", "tagged", False),
           "require_in": ("require", "off", "tagged", False), "off_python": ("off", "off", "plain", True),
           "require_python": ("require", "require", "tagged", True)}
ROUNDS = 5


def _relay_us(policy_in: str, policy_out: str, units: list[list[can.Message]], keys: SwarmKeys, pure: bool,
              round_: int) -> float:
    """Thread CPU (us) per message the Node relays from link A to link B, each read handed over as a reader thread
    hands it (the compiled delivery where the Node has it); fresh buses and engine: every write is new to it."""
    tag = f"{os.getpid()}-{policy_in}-{policy_out}-{pure}-{round_}"
    links = assemble_links([f"can:virtual:bench-auth-a-{tag}?fd=1&auth={policy_in}",
                            f"can:virtual:bench-auth-b-{tag}?fd=1&auth={policy_out}"], 200)
    checks = "require" in (policy_in, policy_out)
    with Node(links, 200, budget=None, swarm_keys=keys if checks else None, pure=pure) as node:
        if node.compiled == pure:
            raise AssertionError(f"auth={policy_in}/{policy_out}: the Node is not on the path measured (pure={pure})")
        start = time.thread_time()
        for batch in range(0, len(units), 16):
            node._delivery.take(0, time.time(), [unit for frames in units[batch:batch + 16] for unit in frames])
        spent = (time.thread_time() - start) / len(units) * 1e6
        stats = node.stats()
    relayed = stats[links[1].name]["out"]
    if relayed < len(units):  # the figure is a relay's only if every write went through
        raise AssertionError(f"auth={policy_in}/{policy_out}: {relayed} of {len(units)} writes relayed: {stats}")
    return spent


@contextlib.contextmanager
def _key_file(master: bytes) -> Iterator[Path]:
    """The swarm key in a file of mode 0600, as `--swarm-key` takes it."""
    with tempfile.TemporaryDirectory(prefix="vstig-bench-auth-") as tmp:
        path = Path(tmp) / "swarm.key"
        path.write_text(master.hex() + "\n", encoding="ascii")
        path.chmod(0o600)
        yield path


def _pty_bridge(policy: str, key_file: Path) -> Callable[[str, str], list[str]]:
    """`vstig bridge` of two cobs8 ptys in engine mode (as bench_datapath's engine relay), both links `policy`."""
    key = ("--swarm-key", str(key_file)) if policy != "off" else ()
    return lambda a, b: [VSTIG, "bridge", f"serial:{a}?framing=cobs8&auth={policy}",
                         f"serial:{b}?framing=cobs8&auth={policy}", "--robot-id", "200", "--budget", "2000",
                         "--no-refresh", *key]


def _tagged_frame(keys: SwarmKeys) -> Frame:
    """Robot 7's cobs8 frame of a message's record (SPEC.md 10.5), tagged with its key."""
    cobs8 = make_serial_framing("cobs8")
    return lambda msg: cobs8.encode_tagged([keys.tag(msg, 0)])[0]


PTY_ROUNDS = 3


@benchmark("auth")
def pty_relay_require_vs_off() -> Iterator[Result]:
    """A cobs8 pty -> pty bridge with both links auth=require against auth off, at one and at ten messages a read:
    CPU per message (PTY_ROUNDS rounds, each relay once a round in turn, each keeping its run of median CPU) and
    instructions per message (callgrind). Every message must reach the far pty."""
    keys = SwarmKeys(_MASTER)
    frames = {"off": cobs8_frame, "require": _tagged_frame(keys)}
    with _key_file(_MASTER) as key_file:
        relays = {policy: (_pty_bridge(policy, key_file), True, {}) for policy in frames}
        runs: dict[tuple[str, int], list[tuple[float, float, tuple[float, ...], int]]] = {}
        for _ in range(PTY_ROUNDS):
            for per_read in (1, 10):
                for policy, relay in relays.items():
                    run = _relay_run(*relay, per_read=per_read, frame=frames[policy])
                    if run[3] < COUNT:
                        raise AssertionError(f"auth={policy}, {per_read} a read: {run[3]} of {COUNT} relayed")
                    runs.setdefault((policy, per_read), []).append(run)
        for per_read, label in ((1, ""), (10, "_ten_per_read")):
            off, require = (_median_run(runs[policy, per_read])[0] * 1e6 for policy in ("off", "require"))
            yield Result(f"auth.pty_relay_cpu_require_vs_off{label}", require, "us", "auth off CPU/msg", off)
        for per_read, label in ((1, ""), (10, "_ten_per_read")):
            per_msg = instructions_per_msg("auth.pty_relay_instructions", relays, per_read, frames)
            if per_msg is None:
                return
            yield Result(f"auth.pty_relay_instructions_require_vs_off{label}", per_msg["require"], "instr",
                         "auth off instr/msg", per_msg["off"])


@benchmark("auth")
def gateway_with_tags_vs_without() -> Iterator[Result]:
    """Messages/s through the engine alone, and through TaggedStigmergy with every tag checked (require)."""
    keys = SwarmKeys(_MASTER)
    messages = realistic_mix(_N)
    records = [(m, *keys.tag(m, 0)[1:]) for m in messages]

    def off() -> int:
        engine = Stigmergy(200)
        for msg in messages:
            engine.receive(msg)
        engine.drain()
        return _N

    def require() -> int:
        node = TaggedStigmergy(Stigmergy(200), keys)
        for msg, epoch, tag in records:
            node.receive(msg, AuthPolicy.REQUIRE, epoch, tag)
        for msg in node.engine.drain():
            node.record_of(msg)
        return _N

    plain, tagged = rate(off), rate(require)
    yield Result("auth.us_per_message_require", 1e6 / tagged, "us", "engine alone (auth off)", 1e6 / plain)


def _avr_tools() -> tuple[str, str] | None:
    avr_gcc, gcc = shutil.which("avr-gcc"), shutil.which("gcc")
    if avr_gcc is None or gcc is None or not Path("/usr/include/simavr/sim_avr.h").exists():
        return None
    return avr_gcc, gcc


def _cycles(board: Path, avr_gcc: str, folder: Path, what: int, runs: int) -> int:
    elf = folder / f"tag_{what}_{runs}.elf"
    sources = [str(HERE / "auth_tag_cycles.c"), *map(str, sorted(LIBVSTIG.glob("vstig_*.c")))]
    subprocess.run([avr_gcc, "-mmcu=atmega328p", "-std=c99", "-Os", "-ffunction-sections", "-fdata-sections",
                    f"-DWHAT={what}", f"-DRUNS={runs}", "-I", str(LIBVSTIG), "-o", str(elf), *sources,
                    "-Wl,--gc-sections"], check=True, capture_output=True, timeout=300)
    done = subprocess.run([str(board), str(elf)], check=True, capture_output=True, text=True, timeout=300)
    return int(done.stdout.split()[-1])


def _per_run(board: Path, avr_gcc: str, folder: Path, what: int) -> float:
    return (_cycles(board, avr_gcc, folder, what, RUNS + 1) - _cycles(board, avr_gcc, folder, what, 1)) / RUNS


def _auth_sizes(avr_gcc: str, folder: Path) -> tuple[int, int]:
    """(flash, static RAM) of vstig_auth.o for the ATmega328P: text + progmem + rodata, data + bss + rodata."""
    obj = folder / "vstig_auth.o"
    subprocess.run([avr_gcc, "-mmcu=atmega328p", "-std=c99", "-Os", "-c", str(LIBVSTIG / "vstig_auth.c"), "-o",
                    str(obj)], check=True, capture_output=True, timeout=300)
    sizes = {name: int(size) for name, size in
             re.findall(r"^(\.\S+)\s+(\d+)", subprocess.run(["avr-size", "-A", str(obj)], check=True,
                                                            capture_output=True, text=True).stdout, re.M)}
    ram = sizes.get(".data", 0) + sizes.get(".bss", 0) + sizes.get(".rodata", 0)  # AVR copies .rodata to RAM
    return sizes.get(".text", 0) + sizes.get(".progmem.data", 0) + sizes.get(".rodata", 0), ram


@benchmark("auth")
def avr_cycles_per_tag() -> Iterator[Result]:
    """Cycles per tag and per check on the ATmega328P beside one cobs8 frame; vstig_auth's flash and RAM."""
    tools = _avr_tools()
    if tools is None:
        print("  auth.avr: skipped (needs avr-gcc, gcc and libsimavr-dev)", file=sys.stderr)
        return
    avr_gcc, gcc = tools
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        board = folder / "simavr_cycles"
        subprocess.run([gcc, "-O2", "-o", str(board), str(HERE / "simavr_cycles.c"), "-lsimavr"], check=True,
                       capture_output=True, timeout=300)
        frame = _per_run(board, avr_gcc, folder, 0)
        yield Result("auth.avr_cycles_per_tag", _per_run(board, avr_gcc, folder, 1), "cycles",
                     "one cobs8 frame", frame)
        yield Result("auth.avr_cycles_per_check", _per_run(board, avr_gcc, folder, 2), "cycles",
                     "one cobs8 frame", frame)
        flash, ram = _auth_sizes(avr_gcc, folder)
    yield Result("auth.avr_flash", flash, "bytes", "ATmega328P flash", FLASH)
    yield Result("auth.avr_static_ram", ram, "bytes", "ATmega328P SRAM", SRAM)
