"""What a medium can do is declared on its base class, never switched on or probed for outside the media.

cli/, vstig_hw/api/ and vstig_hw/capture/ ask a link spec, a framing, a transport or a capture writer through
what `LinkSpec`, `Framing`, `Transport` and `CaptureWriter` declare. An AST walk of those folders fails on an
isinstance/issubclass/type()/match switch on a media class (every subclass of those bases in the library, checked
against the link and capture registries) and on a getattr/hasattr probe of a capability the bases declare.
"""

from __future__ import annotations

import abc
import ast
from collections.abc import Iterator
from functools import cache
from pathlib import Path

import pytest

import vstig_hw
from vstig_hw.capture.records import CAN_FRAMING, WRITERS
from vstig_hw.capture.writer import CaptureWriter
from vstig_hw.framing.base import Framing
from vstig_hw.framing.can import CAPTURE_NAME
from vstig_hw.links import LinkSpec, examples, parse
from vstig_hw.transports.base import Transport

ROOT = Path(vstig_hw.__file__).resolve().parents[1]
CHECKED = (ROOT / "cli", ROOT / "vstig_hw" / "api", ROOT / "vstig_hw" / "capture")
MEDIA_PACKAGES = ("framing", "dialects", "transports", "links", "capture")
BASES = (LinkSpec, Framing, Transport, CaptureWriter)


def _classes(folder: Path) -> Iterator[ast.ClassDef]:
    for path in sorted(folder.rglob("*.py")):
        yield from (node for node in ast.walk(ast.parse(path.read_text())) if isinstance(node, ast.ClassDef))


def _base_names(node: ast.ClassDef) -> set[str]:
    names = set()
    for base in node.bases:
        base = base.value if isinstance(base, ast.Subscript) else base  # Framing[bytes]
        names.add(base.attr if isinstance(base, ast.Attribute) else getattr(base, "id", ""))
    return names


@cache
def media_classes() -> frozenset[str]:
    """Every class in the library that is (transitively) one of BASES (not the bases: asking for one is no
    switch), by name."""
    bases: dict[str, set[str]] = {}
    for package in MEDIA_PACKAGES:
        for node in _classes(ROOT / "vstig_hw" / package):
            bases.setdefault(node.name, set()).update(_base_names(node))
    media = {base.__name__ for base in BASES}
    grown = True
    while grown:
        found = {name for name, parents in bases.items() if parents & media}
        grown = not found <= media
        media |= found
    return frozenset(media - {base.__name__ for base in BASES})


def capabilities() -> set[str]:
    """What the bases declare beyond what every medium must implement itself (their abstract members)."""
    plain = set(dir(abc.ABC))
    return {name for base in BASES for name in dir(base)
            if not name.startswith("_") and name not in plain and name not in base.__abstractmethods__}


def _names(node: ast.expr) -> Iterator[str]:
    for part in node.elts if isinstance(node, ast.Tuple) else [node]:
        if isinstance(part, ast.Name):
            yield part.id
        elif isinstance(part, ast.Attribute):
            yield part.attr
        elif isinstance(part, ast.Constant) and isinstance(part.value, str):  # type(x).__name__ == "ZenohFraming"
            yield part.value


def violations(source: str, where: str, media: frozenset[str], declared: set[str]) -> list[str]:
    found = []
    for node in ast.walk(ast.parse(source)):
        named: set[str] = set()
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and len(node.args) >= 2:
            if node.func.id in ("isinstance", "issubclass"):
                named = set(_names(node.args[1])) & media
            elif node.func.id in ("getattr", "hasattr") and isinstance(node.args[1], ast.Constant) \
                    and node.args[1].value in declared:
                found.append(f"{where}:{node.lineno}: {node.func.id}(..., {node.args[1].value!r}): declared on a base")
        elif isinstance(node, ast.Compare):
            named = {name for side in (node.left, *node.comparators) for name in _names(side)} & media
            named = named if _mentions_type(node) else set()
        elif isinstance(node, ast.MatchClass):
            named = set(_names(node.cls)) & media
        found.extend(f"{where}:{getattr(node, 'lineno', 0)}: switches on {name}" for name in sorted(named))
    return found


def _mentions_type(node: ast.Compare) -> bool:
    """A comparison of a type(): `type(x) is C`, `type(x).__name__ == "C"`."""
    return any(isinstance(call, ast.Call) and isinstance(call.func, ast.Name) and call.func.id == "type"
               for side in (node.left, *node.comparators) for call in ast.walk(side))


def test_the_media_classes_include_every_registered_medium() -> None:
    media = media_classes()
    specs = {type(parse(spec)).__name__ for specs in examples().values() for spec in specs}
    writers = {name for _, name in WRITERS.values()}
    framings = {"Cobs8Framing", "CanFraming", "XBeeFraming", "ZenohFraming", "MavlinkFraming", "BuzzKh4Framing"}
    transports = {"SerialTransport", "CanTransport", "ZenohTransport", "XBeeTransport", "DeviceTransport"}
    assert specs | writers | framings | transports <= media, sorted((specs | writers | framings | transports) - media)
    assert {"capture_medium", "narrow", "note", "clock", "stigmergy", "deployment", "replay_unit"} <= capabilities()


@pytest.mark.parametrize("folder", CHECKED, ids=lambda folder: str(folder.relative_to(ROOT)))
def test_no_switch_on_a_medium_and_no_probe_for_a_declared_capability(folder: Path) -> None:
    media, declared = media_classes(), capabilities()
    found = [line for path in sorted(folder.rglob("*.py"))
             for line in violations(path.read_text(), str(path.relative_to(ROOT)), media, declared)]
    assert not found, "ask the declaration instead:\n" + "\n".join(found)


def test_the_walk_finds_each_kind_of_switch_and_probe() -> None:
    planted = '''
if isinstance(spec, (str, CanSpec)): pass
if isinstance(link.framing, framing.can.CanFraming): pass
if type(link.framing).__name__ == "ZenohFraming": pass
if type(transport) is SerialTransport: pass
clock = getattr(link.transport, "clock", None)
if hasattr(writer, "note"): pass
match spec:
    case ZenohSpec(): pass
kept = isinstance(value, int) and getattr(file, "name", "") and getattr(reader, "file", None)
'''
    found = violations(planted, "planted", media_classes(), capabilities())
    assert [line.split(": ", 1)[1] for line in found] == [
        "switches on CanSpec", "switches on CanFraming", "switches on ZenohFraming", "switches on SerialTransport",
        "getattr(..., 'clock'): declared on a base", "hasattr(..., 'note'): declared on a base",
        "switches on ZenohSpec"], found


def test_a_can_record_carries_the_framing_name_can_captures_are_read_with() -> None:
    assert CAPTURE_NAME == CAN_FRAMING
