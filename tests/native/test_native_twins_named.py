"""The twins are named both ways, from one index, and the constants they share are equal.

vstig_hw/_vstig.pyi's docstring is the one index of the twins: each C file of vstig_hw/_cext, the types it
defines, and its Python references. Each reference names its C twin at the top of its docstring ("C twin:"),
each C file names its references at the top ("Reference:"). The constants both sides define are compared here
from the C's own #defines; a #define this file does not know fails until it is classified.
"""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[2]
CEXT = ROOT / "vstig_hw" / "_cext"

# C #define -> the Python constant it must equal ("module:name")
MIRRORED = {
    ("path.c", "READ_SIZE"): "vstig_hw.transports.serial:_READ_SIZE",
    ("path.c", "DRAIN_LIMIT"): "vstig_hw.transports.can:_DRAIN_LIMIT",
    ("path.c", "POLL_COUNTS_S"): "vstig_hw.transports.socketcan_drops:_INTERFACE_POLL_S",
    ("window.c", "PACE_BURST"): "vstig_hw.gateway.outlet:PACE_BURST",
    ("window.c", "RESERVE_SHARE"): "vstig_hw.gateway.outlet:RESERVE_SHARE",
    ("parts.c", "VX_INTAKE_BURST_TICKS"): "vstig_hw.gateway.parts:INTAKE_BURST_TICKS",
    ("outlet.h", "VX_LOCAL"): "vstig_hw.gateway.fairshare:LOCAL",
    ("guard.h", "VX_GUARD_MAX_LEARN"): "vstig_hw.gateway.compiled:MAX_LEARN",
    ("path.h", "VX_READ_PYTHON"): "vstig_hw.gateway.compiled:READS_PYTHON",
    ("path.h", "VX_READ_SERIAL"): "vstig_hw.gateway.compiled:READS_SERIAL",
    ("path.h", "VX_READ_SOCKETCAN"): "vstig_hw.gateway.compiled:READS_SOCKETCAN",
    ("path.h", "VX_READ_XBEE"): "vstig_hw.gateway.compiled:READS_XBEE",
    ("path.h", "VX_READ_UDP"): "vstig_hw.gateway.compiled:READS_UDP",
    ("path.h", "VX_READ_PYTHONCAN"): "vstig_hw.gateway.compiled:READS_PYTHONCAN",
    ("path.c", "STATE_POLL_S"): "vstig_hw.transports.can:_STATE_POLL_S",
    ("path.c", "ALONE_S"): "vstig_hw.transports.can:_ALONE_S",
    ("path.c", "DATAGRAMS_PER_READ"): "vstig_hw.transports.mavlink:_DATAGRAMS_PER_READ",
    ("path.c", "DATAGRAM"): "vstig_hw.transports.mavlink:_DATAGRAM",
    ("mavlink.h", "VX_STREAMS_KEPT"): "vstig_hw.framing.mavlink:STREAMS_KEPT",
    ("mavlink.h", "VX_NEW_STREAM_WINDOW"): "vstig_hw.framing.mavlink:NEW_STREAM_WINDOW",
    ("mavlink.h", "VX_EPOCH_2015"): "vstig_hw.framing.mavlink:_EPOCH_2015",
    ("roster.h", "VX_ROSTER_LINKS"): "vstig_hw.links.assemble:MAX_LINKS",
    ("roster.h", "VX_ROSTER_BEHIND_KEYS"): "vstig_hw.gateway.roster:MAX_BEHIND_KEYS",
    ("roster.c", "GAP_WEIGHT"): "vstig_hw.gateway.roster:_GAP_WEIGHT",
    ("tags.h", "VX_BATCH_MARKER"): "vstig_hw.auth:BATCH_MARKER",
    ("roster.c", "QUIET_PERIODS"): "vstig_hw.gateway.roster:QUIET_PERIODS",
    ("roster.c", "RATE_WINDOW"): "vstig_hw.gateway.roster:RATE_WINDOW",
}
# C's own: sizes of its buffers, its enums over libvstig's, names of the declared types (module.c)
C_ONLY = {
    "FEED_BATCH", "OUTLET", "NOT_NOTED", "UNNOTED", "XBEE_UNITS_ROOM", "VX_COUNT", "VX_SERIAL_MAX_BYTES",
    "VX_COBS8", "VX_EPUCK4", "VX_KILOBOT", "VX_CAN", "VX_XBEE", "VX_MAVLINK", "VX_FRAMINGS", "VX_REPLAY_BUCKETS",
    "VX_MAV_TX_ROOM", "NONE", "VX_GUARD_UNITS", "FREE_SLOT", "HEARD",
    "VX_PORT_PYTHON", "VX_PORT_SERIAL", "VX_PORT_SOCKETCAN", "VX_PORT_UDP", "MAVLINK_UDP", "PY_SSIZE_T_CLEAN",
    "LINEAR_RECORDS",
    "DELIVERY_STATE", "WAKEUP", "HANDLE", "DEVICE_TRANSPORT", "CAN_TRANSPORT", "XBEE_TRANSPORT", "SOCKETCAN_BUS",
    "LINK", "WRITER", "FAIR_QUEUE", "FAIR_FIFO", "GUARD", "ENGINE", "ENCODER", "LOCK", "CAN_MESSAGE_TYPE", "TIME",
    "VX_PORT_PYTHONCAN", "CAN_BUS", "PREAMBLE_MAX", "VX_XBEE_MAX_RECORDS", "COUNTERS", "VX_HOT", "VX_HOT_T",
}


def twins() -> dict[str, tuple[list[str], list[str]]]:
    """The index: C file -> (its types, its Python references), from _vstig.pyi's docstring."""
    docstring = ast.get_docstring(ast.parse((ROOT / "vstig_hw" / "_vstig.pyi").read_text())) or ""
    table = docstring.split("Twins (C file, its types, its Python references):", 1)[1].split("\n\n")[1]
    index: dict[str, tuple[list[str], list[str]]] = {}
    current = ""
    for token in table.split():
        if token.endswith(".c"):
            current = token
            index[current] = ([], [])
        elif token.endswith(".py"):
            index[current][1].append(token)
        elif token != "-":
            index[current][0].append(token)
    return index


def header(c_file: str) -> str:
    """A C file's opening comment, its lines joined."""
    text = (CEXT / c_file).read_text()
    return " ".join(line.strip().lstrip("/*").strip() for line in text[:text.index("*/")].splitlines())


def top_of_docstring(py_file: str) -> str:
    docstring = ast.get_docstring(ast.parse((ROOT / py_file).read_text())) or ""
    return " ".join(docstring.split("\n\n")[:2])


def test_the_index_names_every_c_file_and_files_that_exist() -> None:
    index = twins()
    assert sorted(index) == sorted(p.name for p in CEXT.glob("*.c"))
    missing = [py for _, refs in index.values() for py in refs if not (ROOT / py).is_file()]
    assert missing == []
    assert all(refs for _, refs in index.values())


@pytest.mark.parametrize("c_file", sorted(twins()))
def test_each_c_file_names_its_references_at_its_top(c_file: str) -> None:
    top = header(c_file)
    assert "Reference:" in top, f"{c_file} names no reference at its top"
    assert [py for py in twins()[c_file][1] if py not in top] == []


@pytest.mark.parametrize("py_file", sorted({py for _, refs in twins().values() for py in refs}))
def test_each_reference_names_its_c_twins_at_its_top(py_file: str) -> None:
    top = " ".join(top_of_docstring(py_file).split())
    assert "C twin:" in top, f"{py_file} names no C twin at the top of its docstring"
    named = [c for c, (_, refs) in twins().items() if py_file in refs]
    assert [c for c in named if f"vstig_hw/_cext/{c}" not in top] == []


def test_every_compiled_type_is_in_the_index_and_in_ext_h(compiled: ModuleType) -> None:
    types = sorted(name for name in dir(compiled) if isinstance(getattr(compiled, name), type))
    indexed = sorted(t for t_list, _ in twins().values() for t in t_list)
    assert types == indexed
    ext_h = (CEXT / "ext.h").read_text()
    listed = ext_h[:ext_h.index("*/")]
    assert [t for t in types if not re.search(rf"^ \*\s+{t}\s", listed, re.MULTILINE)] == []


def defines() -> dict[tuple[str, str], str]:
    """Every #define of the C, (file, name) -> its value as written (function-like macros: "")."""
    found = {}
    for path in sorted([*CEXT.glob("*.c"), *CEXT.glob("*.h")]):
        for match in re.finditer(r"^#define\s+(\w+)(\(?)[ \t]*([^\n]*?)\s*(?:/\*.*)?$", path.read_text(), re.M):
            name, function_like, value = match.groups()
            if name.startswith("VSTIG_EXT") and name.endswith("_H"):  # include guards
                continue
            found[(path.name, name)] = "" if function_like else value
    return found


def c_number(value: str) -> float:
    return float(re.sub(r"(?<=\d)[uUlL]+\b", "", value).strip("()"))


def python_constant(where: str) -> float:
    module, _, name = where.partition(":")
    value = getattr(importlib.import_module(module), name)
    assert isinstance(value, (int, float)) and not isinstance(value, bool), where
    return float(value)


def test_every_c_define_is_mirrored_or_the_c_s_own() -> None:
    unknown = [f"{file}:{name}" for file, name in defines() if (file, name) not in MIRRORED and name not in C_ONLY]
    assert unknown == [], f"classify these #defines in {Path(__file__).name}: mirrored (MIRRORED) or C_ONLY"
    assert [key for key in MIRRORED if key not in defines()] == []


@pytest.mark.parametrize(("where", "python"), sorted(MIRRORED.items()))
def test_a_mirrored_constant_is_equal_on_both_sides(where: tuple[str, str], python: str) -> None:
    assert c_number(defines()[where]) == python_constant(python), f"{where[0]}'s {where[1]} differs from {python}"


def test_a_changed_constant_is_found(monkeypatch: pytest.MonkeyPatch) -> None:
    # the comparison can fail: the Python side changed alone is a difference
    import vstig_hw.gateway.outlet as outlet
    monkeypatch.setattr(outlet, "PACE_BURST", outlet.PACE_BURST + 1)
    assert c_number(defines()[("window.c", "PACE_BURST")]) != python_constant("vstig_hw.gateway.outlet:PACE_BURST")
