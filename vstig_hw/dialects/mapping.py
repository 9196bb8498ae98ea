"""A deployment's mapping between the dialects' keys and values and our Message, read from TOML.

Our message carries a 15-bit key and 16 raw bits of value; Buzz carries typed
objects under string keys, BittyBuzz a typed 16-bit value under a script's string
id. A lab declares once which names it bridges, to which of our keys, and how our
16 bits read::

    [buzz]
    stigmergy = 1            # the id the scripts pass to stigmergy.create()
    dialect = "current"      # or "pre2017" (Buzz built before July 2017)

    [bittybuzz]
    symbols = "behavior.bo"  # the build's string table (.bo or .basm), relative to this file
    capacity = 4             # BBZVSTIG_CAP of the Kilobots' build

    [keys]
    leader = { key = 1, type = "int16" }
    light = { key = 2, type = "float16" }
    heading = { key = 3, type = "bbzfloat", bbz_id = 51 }   # an id given by hand wins

Value types: `int16`, `uint16`, `float16` (IEEE half) and `bbzfloat` (BittyBuzz's
16-bit float, so Kilobot floats cross bit for bit). A value of another kind than
its key's type, out of its range, or one the conversion would round (Buzz's 0.1
under a float16 key, a float16 with 10 fraction bits toward a bbzfloat, -0.0 toward
Buzz) is not converted: it is unmappable, and the translators count it as
`drop_unmapped` (firmware_spec/dialects.md section 5, "Values").

BittyBuzz string ids: ids 0-45 are the same in every build (BittyBuzz
src/bittybuzz/util/BittyBuzzStrings.bst, prepended to every script's strings); the
rest come from the compiled script. `bzzparse`/`bzzasm` write the `.bo` (u16 string
count, little-endian, then NUL-terminated strings in id order) and the `.basm` (a
`!count` line, then one `'string` line per id); both hold the whole table.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, get_args

from ..inputs import InputFileError, parse_toml, read_regular, toml_line
from ..values import from_raw, to_raw
from ..wire import KEY_MAX
from .bittybuzz import BbzType, bbzfloat_from_float, bbzfloat_to_float
from .buzz import BUZZ_DIALECTS, BuzzDialect, BuzzObject, buzz_float_from_wire, buzz_float_to_wire

__all__ = [
    "BBZ_BASE_STRINGS",
    "DIALECT_VALUE_TYPES",
    "Deployment",
    "DeploymentError",
    "DialectValueType",
    "KeyMap",
    "load_deployment",
    "parse_deployment",
    "read_bbz_symbols",
]

DialectValueType = Literal["int16", "uint16", "float16", "bbzfloat"]
DIALECT_VALUE_TYPES: tuple[str, ...] = get_args(DialectValueType)

# The strings every BittyBuzz build numbers first (BittyBuzzStrings.bst), so id = index.
BBZ_BASE_STRINGS: tuple[str, ...] = (
    "id", "swarm", "create", "select", "init", "step", "reset", "destroy", "join", "unselect", "leave", "in",
    "exec", "intersection", "union", "difference", "others", "neighbors", "foreach", "map", "reduce", "distance",
    "azimuth", "elevation", "count", "kin", "nonkin", "data", "filter", "broadcast", "listen", "ignore",
    "stigmergy", "put", "get", "size", "onconflict", "onconflictlost", "robot", "timestamp", "pos", "x", "y",
    "orientation", "__INTERNAL_1_DO_NOT_USE__", "__INTERNAL_2_DO_NOT_USE__",
)
BBZ_DEFAULT_CAPACITY = 4  # BittyBuzzConfig.cmake BBZVSTIG_CAP


class DeploymentError(ValueError):
    """A deployment file that cannot be used; the message names the file and the entry."""


@dataclass(frozen=True)
class KeyMap:
    """One bridged name: our key, how our 16 bits read, and its BittyBuzz string id if known."""

    name: str
    key: int
    value_type: DialectValueType
    bbz_id: int | None = None


@dataclass
class Deployment:
    keys: dict[str, KeyMap] = field(default_factory=dict)
    buzz_stigmergy: int = 0
    buzz_dialect: BuzzDialect = "current"
    bbz_capacity: int = BBZ_DEFAULT_CAPACITY

    def __post_init__(self) -> None:
        self.by_key = {entry.key: entry for entry in self.keys.values()}
        self.by_bbz_id = {entry.bbz_id: entry for entry in self.keys.values() if entry.bbz_id is not None}

    # ---- values: each returns None unless the value crosses exactly ----
    # A robot stores what it hears under the writer's (timestamp, robot), and a copy with other
    # bits at that version is never replaced (same version, same writer). So a value crosses
    # only if converting it back gives the writer's bits; a rounded one is not sent at all.

    @staticmethod
    def raw_from_buzz(obj: BuzzObject, value_type: DialectValueType) -> int | None:
        """Our 16 raw bits for a Buzz object under a key of `value_type`."""
        raw = _raw_from_buzz(obj, value_type)
        return raw if raw is not None and _same_object(_buzz_from_raw(raw, value_type), obj) else None

    @staticmethod
    def buzz_from_raw(raw: int, value_type: DialectValueType) -> BuzzObject:
        """The Buzz object for our 16 raw bits; None where Buzz robots could not hold exactly it."""
        obj = _buzz_from_raw(raw, value_type)
        return obj if obj is not None and _raw_from_buzz(obj, value_type) == raw else None

    @staticmethod
    def raw_from_bbz(tag: int, value: int, value_type: DialectValueType) -> int | None:
        """Our 16 raw bits for a BittyBuzz value (type tag, 16 bits) under a key of `value_type`."""
        raw = _raw_from_bbz(tag, value, value_type)
        return raw if raw is not None and _bbz_from_raw(raw, value_type) == (tag, value) else None

    @staticmethod
    def bbz_from_raw(raw: int, value_type: DialectValueType) -> tuple[int, int] | None:
        """(type tag, 16 bits) a Kilobot reads as exactly our value, or None."""
        tagged = _bbz_from_raw(raw, value_type)
        return tagged if tagged is not None and _raw_from_bbz(*tagged, value_type) == raw else None


# The plain conversions, each rounding as its target type does; the methods above keep only
# the values that come back unchanged.

def _raw_from_buzz(obj: BuzzObject, value_type: DialectValueType) -> int | None:
    try:
        if isinstance(obj, bool):
            return None
        if isinstance(obj, int) and value_type in ("int16", "uint16"):
            return to_raw(obj, value_type)
        if isinstance(obj, float) and value_type == "float16":
            return to_raw(obj, "float16")
        if isinstance(obj, float) and value_type == "bbzfloat":
            return bbzfloat_from_float(obj)
    except ValueError:
        return None
    return None


def _buzz_from_raw(raw: int, value_type: DialectValueType) -> BuzzObject:
    """What a Buzz robot holds once it hears our value: Buzz's float has one zero and no infinity."""
    number = bbzfloat_to_float(raw) if value_type == "bbzfloat" else from_raw(raw, value_type)
    if isinstance(number, int):
        return number
    if not math.isfinite(number):
        return None
    return buzz_float_from_wire(*buzz_float_to_wire(number))


def _same_object(held: BuzzObject, wrote: BuzzObject) -> bool:
    """The same Buzz object bit for bit: an int is no float, and -0.0 is not 0.0."""
    if isinstance(held, float) and isinstance(wrote, float):
        return struct.pack(">d", held) == struct.pack(">d", wrote)
    return type(held) is type(wrote) and held == wrote


def _raw_from_bbz(tag: int, value: int, value_type: DialectValueType) -> int | None:
    if tag == BbzType.INT and value_type == "int16":
        return value
    if tag == BbzType.INT and value_type == "uint16":
        return value if value < 0x8000 else None  # a negative int16 is no uint16
    if tag == BbzType.FLOAT and value_type == "bbzfloat":
        return value
    if tag == BbzType.FLOAT and value_type == "float16":
        try:
            return to_raw(bbzfloat_to_float(value), "float16")
        except ValueError:
            return None
    return None


def _bbz_from_raw(raw: int, value_type: DialectValueType) -> tuple[int, int] | None:
    if value_type == "int16":
        return BbzType.INT, raw
    if value_type == "uint16":
        return (BbzType.INT, raw) if raw < 0x8000 else None
    if value_type == "bbzfloat":
        return BbzType.FLOAT, raw
    try:
        return BbzType.FLOAT, bbzfloat_from_float(from_raw(raw, "float16"))
    except ValueError:
        return None


# --------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------


DEPLOYMENT_MAX_BYTES = 1 << 20  # a deployment file maps a few hundred keys at most
SYMBOLS_MAX_BYTES = 16 << 20  # a compiled script's .bo or .basm; its string table has at most 65535 ids


def _read_regular(path: Path, limit: int, what: str) -> bytes:
    """`read_regular` (vstig_hw.inputs) with its error as a DeploymentError."""
    try:
        return read_regular(path, limit, what)
    except InputFileError as error:
        raise DeploymentError(str(error)) from None


def read_bbz_symbols(path: Path) -> list[str]:
    """The string table of a compiled Buzz script (.bo or .basm): index = BittyBuzz string id."""
    data = _read_regular(path, SYMBOLS_MAX_BYTES, "the BittyBuzz symbols")
    if path.suffix == ".basm":
        lines = data.decode("utf-8", "replace").splitlines()
        if not lines or not lines[0].startswith("!"):
            raise DeploymentError(f"{path}:1: a .basm starts with the '!count' line of its string table")
        count = lines[0][1:].strip()
        if not (count.isascii() and count.isdigit()) or int(count) > 0xFFFF:
            raise DeploymentError(f"{path}:1: {lines[0][:40]!r} is not '!count' with a count in 0..65535")
        strings = [line[1:].rstrip() for line in lines[1:] if line.startswith("'")]
        if len(strings) < int(count):
            raise DeploymentError(f"{path}:1: the string table announces {count} strings, found {len(strings)}")
        return strings[:int(count)]
    if len(data) < 2:
        raise DeploymentError(f"{path}: too short for a .bo string table")
    announced = int.from_bytes(data[:2], "little")
    if data[2:].count(b"\0") < announced:
        raise DeploymentError(f"{path}: the .bo announces {announced} strings but the file ends first")
    return [s.decode("utf-8", "replace") for s in data[2:].split(b"\0")[:announced]]


def _int(table: dict[str, Any], name: str, where: str, low: int, high: int, default: int) -> int:
    value = table.get(name, default)
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise DeploymentError(f"{where}.{name} must be an integer in {low}..{high}, got {value!r}")
    return value


def parse_deployment(text: str, source: str = "<deployment>", base: Path | None = None) -> Deployment:
    """A Deployment from TOML text; `source` names it in errors, `base` anchors a relative symbols path."""
    try:
        doc = parse_toml(text, source)
    except InputFileError as error:
        raise DeploymentError(str(error)) from None
    unknown = sorted(set(doc) - {"buzz", "bittybuzz", "keys"})
    if unknown:
        raise DeploymentError(f"{source}: unknown section(s) {', '.join(unknown)}; expected buzz, bittybuzz, keys")
    buzz, bbz, keys = doc.get("buzz", {}), doc.get("bittybuzz", {}), doc.get("keys", {})
    for name, section in (("buzz", buzz), ("bittybuzz", bbz), ("keys", keys)):
        if not isinstance(section, dict):
            raise DeploymentError(f"{source}: [{name}] must be a table")
    dialect = buzz.get("dialect", "current")
    if dialect not in BUZZ_DIALECTS:
        raise DeploymentError(f"{source}: buzz.dialect must be one of {', '.join(BUZZ_DIALECTS)}, got {dialect!r}")
    symbols = list(BBZ_BASE_STRINGS)
    if "symbols" in bbz:
        path = Path(str(bbz["symbols"]))
        try:
            symbols = read_bbz_symbols(path if path.is_absolute() or base is None else base / path)
        except DeploymentError as error:
            raise DeploymentError(f"{source}{toml_line(text, 'symbols')}: bittybuzz.symbols: {error}") from None
    ids = {name: index for index, name in reversed(list(enumerate(symbols)))}
    entries: dict[str, KeyMap] = {}
    for name, spec in keys.items():
        where = f"{source}: keys.{name}"
        if not isinstance(spec, dict):
            raise DeploymentError(f"{where} must be a table like {{ key = 1, type = \"int16\" }}")
        extra = sorted(set(spec) - {"key", "type", "bbz_id"})
        if extra:
            raise DeploymentError(f"{where} has unknown field(s) {', '.join(extra)}; expected key, type, bbz_id")
        if "key" not in spec or "type" not in spec:
            raise DeploymentError(f"{where} needs both key and type")
        value_type = spec["type"]
        if value_type not in DIALECT_VALUE_TYPES:
            raise DeploymentError(f"{where}.type must be one of {', '.join(DIALECT_VALUE_TYPES)}, got {value_type!r}")
        key = _int(spec, "key", where, 0, KEY_MAX, 0)
        bbz_id = _int(spec, "bbz_id", where, 0, 0xFFFF, -1) if "bbz_id" in spec else ids.get(name)
        entries[name] = KeyMap(name, key, value_type, bbz_id)
    _no_clash(entries, source)
    return Deployment(entries, _int(buzz, "stigmergy", f"{source}: buzz", 0, 0xFFFF, 0), dialect,
                      _int(bbz, "capacity", f"{source}: bittybuzz", 1, 0xFFFF, BBZ_DEFAULT_CAPACITY))


def _no_clash(entries: dict[str, KeyMap], source: str) -> None:
    """Two names on one key, or on one string id, would merge two variables silently."""
    for attribute in ("key", "bbz_id"):
        seen: dict[int, str] = {}
        for entry in entries.values():
            value = getattr(entry, attribute)
            if value is None:
                continue
            if value in seen:
                raise DeploymentError(f"{source}: keys.{seen[value]} and keys.{entry.name} share {attribute} {value}")
            seen[value] = entry.name


def load_deployment(path: str | Path) -> Deployment:
    """Read a deployment TOML file: a regular file, bounded in size; a relative symbols path is taken from the
    file's folder. Errors name the file (and the line, where TOML gives one)."""
    file = Path(path)
    data = _read_regular(file, DEPLOYMENT_MAX_BYTES, "the deployment file")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        line = data.count(b"\n", 0, error.start) + 1
        raise DeploymentError(f"{file}:{line}: not UTF-8 text") from None
    return parse_deployment(text, str(file), file.parent)
