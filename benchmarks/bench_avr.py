"""libvstig on a Kilobot's ATmega328P: flash and RAM of the example robot firmware for N keys, beside the chip's.

The firmware (firmware_spec/libvstig/examples/avr_robot.c: engine, outgoing queue, cobs8 on the UART, the paper's
program) is built by libvstig's Makefile with avr-gcc -Os for each table size. Flash is .text + .data; RAM is
what is reserved statically (.data + .bss; the stack comes on top); libvstig's flash is its own input sections
in the link map; the engine's RAM is the size of the firmware's `vstig_engine_t` (table and queue).
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

from .registry import Result, benchmark

LIBVSTIG = Path(__file__).resolve().parents[1] / "firmware_spec" / "libvstig"
FLASH = 32768  # ATmega328P
SRAM = 2048
KEYS = (8, 16, 32, 64)
_MAP_LINE = re.compile(r"^\s*(?:(\.\S+)\s+)?0x[0-9a-f]+\s+0x([0-9a-f]+)\s+\S*libvstig\.a\(")


def _build(folder: Path, keys: int) -> Path:
    subprocess.run(["make", "-s", "-C", str(LIBVSTIG), f"BUILD={folder}", f"KEYS={keys}", "robot"], check=True,
                   capture_output=True, timeout=300)
    return folder / "avr" / "avr_robot.elf"


def _sections(elf: Path) -> dict[str, int]:
    out = subprocess.run(["avr-size", "-A", str(elf)], check=True, capture_output=True, text=True).stdout
    return {parts[0]: int(parts[1]) for line in out.splitlines() if len(parts := line.split()) == 3
            and parts[1].isdigit()}


def _library_flash(elf: Path) -> int:
    """Bytes of libvstig's own code and constants the linker kept (the map after discarded sections)."""
    kept = Path(f"{elf}.map").read_text().split("Linker script and memory map", 1)[1]
    return sum(int(m.group(2), 16) for line in kept.splitlines() if (m := _MAP_LINE.match(line)))


def _object_size(elf: Path, prefix: str) -> int:
    out = subprocess.run(["avr-nm", "-S", str(elf)], check=True, capture_output=True, text=True).stdout
    return next(int(parts[1], 16) for line in out.splitlines() if len(parts := line.split()) == 4
                and parts[3].split(".")[0] == prefix)


@benchmark("avr")
def sizes() -> Iterator[Result]:
    if shutil.which("avr-gcc") is None or shutil.which("make") is None:
        print("avr: skipped, avr-gcc (gcc-avr, avr-libc) or make is not installed (tests/sysdeps.sh)", file=sys.stderr)
        return
    with tempfile.TemporaryDirectory() as scratch:
        for keys in KEYS:
            elf = _build(Path(scratch) / str(keys), keys)
            sections = _sections(elf)
            if keys == 16:
                yield Result("avr.robot_flash", sections[".text"] + sections.get(".data", 0), "B",
                             "ATmega328P flash", FLASH)
                yield Result("avr.libvstig_flash", _library_flash(elf), "B", "ATmega328P flash", FLASH)
            yield Result(f"avr.keys{keys}.robot_ram", sections.get(".data", 0) + sections.get(".bss", 0), "B",
                         "ATmega328P SRAM", SRAM)
            yield Result(f"avr.keys{keys}.engine_ram", _object_size(elf, "engine"), "B", "ATmega328P SRAM", SRAM)
