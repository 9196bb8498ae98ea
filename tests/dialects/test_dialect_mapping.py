"""The deployment file: TOML keys and types, BittyBuzz symbols from a build, unmappable values counted."""

from __future__ import annotations

import os
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vstig_hw.dialects.bittybuzz import BbzOp, BbzType, BbzVstig
from vstig_hw.dialects.buzz import BuzzOp, BuzzTable, BuzzVstig
from vstig_hw.dialects.mapping import (
    BBZ_BASE_STRINGS,
    DeploymentError,
    load_deployment,
    parse_deployment,
    read_bbz_symbols,
)
from vstig_hw.dialects.translate import BittyBuzzTranslator, BuzzTranslator
from vstig_hw.wire import Message, Op

TEXT = """
[buzz]
stigmergy = 1

[bittybuzz]
capacity = 2

[keys]
x = { key = 1, type = "int16" }
count = { key = 2, type = "uint16", bbz_id = 60 }
light = { key = 3, type = "float16" }
heading = { key = 4, type = "bbzfloat" }
pos = { key = 6, type = "int16" }
"""


def test_keys_types_and_base_string_ids() -> None:
    deployment = parse_deployment(TEXT)
    assert deployment.buzz_stigmergy == 1 and deployment.buzz_dialect == "current"
    assert deployment.keys["x"].bbz_id == 41  # "x" is a base string: id 41 in every build
    assert deployment.keys["count"].bbz_id == 60 and deployment.keys["light"].bbz_id is None
    assert deployment.by_key[4].name == "heading" and deployment.bbz_capacity == 2
    assert BBZ_BASE_STRINGS.index("y") == 42 and len(BBZ_BASE_STRINGS) == 46


def _bo(strings: list[str]) -> bytes:
    return struct.pack("<H", len(strings)) + b"".join(s.encode() + b"\0" for s in strings) + b"\x01\x02bytecode"


def test_symbols_from_a_bo_and_a_basm(tmp_path: Path) -> None:
    table = [*BBZ_BASE_STRINGS, "led", "stig", "1"]
    (tmp_path / "behavior.bo").write_bytes(_bo(table))
    (tmp_path / "behavior.basm").write_text(f"!{len(table)}\n" + "".join(f"'{s}\n" for s in table) + "\tpushi 1\n")
    for name in ("behavior.bo", "behavior.basm"):
        assert read_bbz_symbols(tmp_path / name) == table
        deployment = f'[bittybuzz]\nsymbols = "{name}"\n[keys]\n"1" = {{ key = 9, type = "int16" }}\n'
        (tmp_path / "d.toml").write_text(deployment)
        assert load_deployment(tmp_path / "d.toml").keys["1"].bbz_id == 48


@pytest.mark.parametrize(("text", "names"), [
    ("[keys]\nx = { key = 40000, type = \"int16\" }", "keys.x.key"),
    ("[keys]\nx = { key = 1, type = \"int32\" }", "keys.x.type"),
    ("[keys]\nx = { key = 1 }", "needs both"),
    ("[keys]\nx = { key = 1, type = \"int16\", colour = 1 }", "colour"),
    ("[keys]\nx = { key = 1, type = \"int16\" }\ny = { key = 1, type = \"int16\" }", "share key 1"),
    ("[buzz]\ndialect = \"2016\"", "buzz.dialect"),
    ("[buzz]\nstigmergy = -1", "stigmergy"),
    ("[robots]\n", "unknown section"),
    ("[keys\n", "not valid TOML"),
    ("[bittybuzz]\nsymbols = \"missing.bo\"", "missing.bo"),
])
def test_bad_files_name_the_entry(text: str, names: str, tmp_path: Path) -> None:
    (tmp_path / "bad.toml").write_text(text)
    with pytest.raises(DeploymentError, match=names) as caught:
        load_deployment(tmp_path / "bad.toml")
    assert "bad.toml" in str(caught.value)


def test_truncated_symbol_files(tmp_path: Path) -> None:
    (tmp_path / "short.bo").write_bytes(struct.pack("<H", 5) + b"id\0")
    (tmp_path / "short.basm").write_text("!5\n'id\n")
    for name in ("short.bo", "short.basm"):
        with pytest.raises(DeploymentError, match="5"):
            read_bbz_symbols(tmp_path / name)


def _fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


@pytest.mark.parametrize(("symbols", "says"), [
    ("/dev/zero", "/dev/zero: the BittyBuzz symbols must be a regular file"),
    ("pipe.bo", "pipe.bo: the BittyBuzz symbols must be a regular file"),  # a FIFO: no wait for a writer
    (".", ": the BittyBuzz symbols must be a regular file"),
    ("huge.basm", "huge.basm: the BittyBuzz symbols is larger than the 16 MiB read at most"),
    ("bad.basm", "bad.basm:1: '!\u00b2' is not '!count'"),  # int('²') once escaped as a bare ValueError
    (r"nul\u0000.bo", "cannot read the BittyBuzz symbols: embedded null byte"),  # a TOML escape
])
def test_symbols_that_are_not_a_small_regular_file_are_named(tmp_path: Path, symbols: str, says: str) -> None:
    _fifo(tmp_path / "pipe.bo")
    with open(tmp_path / "huge.basm", "wb") as huge:  # sparse: no disk used
        huge.truncate((16 << 20) + 1)
    (tmp_path / "bad.basm").write_text("!\u00b2\n'id\n")
    deployment = tmp_path / "lab.toml"
    deployment.write_text(f'# a lab\n[bittybuzz]\nsymbols = "{symbols}"\n')
    with pytest.raises(DeploymentError) as caught:
        load_deployment(deployment)
    message = str(caught.value)
    assert message.startswith(f"{deployment}:3: bittybuzz.symbols: "), message
    assert says in message, message


@pytest.mark.parametrize("name", ["/dev/zero", "pipe.toml", "."])
def test_a_deployment_that_is_not_a_regular_file_is_named(tmp_path: Path, name: str) -> None:
    _fifo(tmp_path / "pipe.toml")
    path = tmp_path / name if not name.startswith("/") else Path(name)
    with pytest.raises(DeploymentError, match="the deployment file must be a regular file") as caught:
        load_deployment(path)
    assert str(caught.value).startswith(f"{path}: ")


def test_a_deployment_that_is_not_utf8_names_its_line(tmp_path: Path) -> None:
    (tmp_path / "lab.toml").write_bytes(b"[keys]\nx = { key = 1, type = \"int16\" } # \xff\n")
    with pytest.raises(DeploymentError, match=r"lab\.toml:2: not UTF-8 text"):
        load_deployment(tmp_path / "lab.toml")


def test_symbols_are_found_beside_the_deployment_file_whatever_the_working_folder(tmp_path: Path) -> None:
    (tmp_path / "lab").mkdir()
    (tmp_path / "lab" / "behavior.basm").write_text("!1\n'x\n")
    (tmp_path / "lab" / "lab.toml").write_text('[bittybuzz]\nsymbols = "behavior.basm"\n'
                                               '[keys]\nx = { key = 1, type = "int16" }\n')
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    code = ("from vstig_hw.dialects.mapping import load_deployment; "
            "print(load_deployment('../lab/lab.toml').keys['x'].bbz_id)")
    done = subprocess.run([sys.executable, "-c", code], cwd=elsewhere, capture_output=True, text=True, timeout=60)
    assert done.stdout.strip() == "0", done.stderr


def test_buzz_values_by_key_type() -> None:
    buzz = BuzzTranslator(parse_deployment(TEXT))
    assert buzz.to_ours(BuzzVstig(BuzzOp.PUT, 1, "x", -2, 3, 9)) == Message(Op.PUT, 1, 0xFFFE, 3, 9)
    assert buzz.to_ours(BuzzVstig(BuzzOp.PUT, 1, "light", 1.5, 3, 9)) == Message(Op.PUT, 3, 0x3E00, 3, 9)
    assert buzz.to_ours(BuzzVstig(BuzzOp.PUT, 1, "heading", 1.0, 3, 9)) == Message(Op.PUT, 4, 0x3E00, 3, 9)
    assert buzz.to_ours(BuzzVstig(BuzzOp.QUERY, 1, "x", None, 0, 7)) == Message(Op.GET, 1, 0, 0, 7)
    unmappable = [
        BuzzVstig(BuzzOp.PUT, 2, "x", 1, 1, 1),  # another stigmergy
        BuzzVstig(BuzzOp.PUT, 1, "y", 1, 1, 1),  # a name the deployment does not bridge
        BuzzVstig(BuzzOp.PUT, 1, 7, 1, 1, 1),  # an integer key
        BuzzVstig(BuzzOp.PUT, 1, "x", 40000, 1, 1),  # outside int16
        BuzzVstig(BuzzOp.PUT, 1, "count", -1, 1, 1),  # outside uint16
        BuzzVstig(BuzzOp.PUT, 1, "x", 1.0, 1, 1),  # a float under an int key: not guessed
        BuzzVstig(BuzzOp.PUT, 1, "light", 1, 1, 1),  # an int under a float key
        BuzzVstig(BuzzOp.PUT, 1, "light", 1e6, 1, 1),  # beyond float16
        BuzzVstig(BuzzOp.PUT, 1, "x", None, 4, 3),  # a tombstone: we have no nil
        BuzzVstig(BuzzOp.PUT, 1, "x", BuzzTable(), 4, 3),
    ]
    assert [buzz.to_ours(m) for m in unmappable] == [None] * len(unmappable)
    assert buzz.drops["unmapped"] == len(unmappable)


def test_ours_to_buzz() -> None:
    buzz = BuzzTranslator(parse_deployment(TEXT))
    assert buzz.from_ours(Message(Op.PUT, 1, 0xFFFE, 3, 9)) == BuzzVstig(BuzzOp.PUT, 1, "x", -2, 3, 9)
    assert buzz.from_ours(Message(Op.GET, 3, 0x3E00, 3, 9)) == BuzzVstig(BuzzOp.QUERY, 1, "light", 1.5, 3, 9)
    assert buzz.from_ours(Message(Op.GET, 2, 0, 0, 9)) == BuzzVstig(BuzzOp.QUERY, 1, "count", None, 0, 9)
    assert buzz.from_ours(Message(Op.PUT, 3, 0x7C00, 3, 9)) is None  # a float16 infinity: Buzz cannot send it
    assert buzz.from_ours(Message(Op.PUT, 99, 1, 1, 1)) is None
    assert buzz.drops["unmapped"] == 2


@given(st.integers(0, 0xFFFF), st.sampled_from(["int16", "uint16", "float16", "bbzfloat"]))
def test_every_mappable_value_crosses_to_buzz_and_back_unchanged(raw: int, value_type: str) -> None:
    deployment = parse_deployment(f'[keys]\nk = {{ key = 5, type = "{value_type}" }}')
    buzz = BuzzTranslator(deployment)
    out = buzz.from_ours(Message(Op.PUT, 5, raw, 1, 1))
    if out is not None:  # -0.0 never is: Buzz's float has one zero
        assert buzz.to_ours(out) == Message(Op.PUT, 5, raw, 1, 1)


def test_bittybuzz_values_and_guards() -> None:
    bbz = BittyBuzzTranslator(parse_deployment(TEXT))
    ours = bbz.to_ours(BbzVstig(BbzOp.PUT, 7, 41, 0x39, 0xFFFE, 1))  # flags above the tag are ignored
    assert ours == Message(Op.PUT, 1, 0xFFFE, 1, 7)
    assert bbz.to_ours(BbzVstig(BbzOp.PUT, 7, 60, BbzType.INT, 0xFFFF, 1)) is None  # -1 is no uint16
    assert bbz.to_ours(BbzVstig(BbzOp.PUT, 7, 99, BbzType.INT, 1, 1)) is None  # unknown string id
    assert bbz.to_ours(BbzVstig(BbzOp.PUT, 7, 41, BbzType.NIL, 0, 2)) is None  # put(nil): no nil here
    assert bbz.drops["unmapped"] == 3
    # Repeats are not news; a Kilobot asking for a key it lacks becomes our empty GET, and the
    # engine's answer (the version the anchor says they hold) then goes back as it is.
    assert bbz.to_ours(BbzVstig(BbzOp.QUERY, 9, 41, BbzType.INT, 0xFFFE, 1)) is None and bbz.drops["bbz_repeat"] == 1
    assert bbz.from_ours(Message(Op.PUT, 1, 0xFFFE, 1, 7)) is None  # they hold it
    assert bbz.to_ours(BbzVstig(BbzOp.QUERY, 3, 41, BbzType.NIL, 0, 0)) == Message(Op.GET, 1, 0, 0, 3)
    assert bbz.from_ours(Message(Op.PUT, 1, 0xFFFE, 1, 7)) == BbzVstig(BbzOp.PUT, 7, 41, BbzType.INT, 0xFFFE, 1)
    assert bbz.from_ours(Message(Op.PUT, 1, 0xFFFE, 1, 7)) is None  # once
    # Only PUTs toward the Kilobots, never an empty query, never more keys than they hold.
    assert bbz.from_ours(Message(Op.GET, 1, 5, 2, 500)) == BbzVstig(BbzOp.PUT, 500, 41, BbzType.INT, 5, 2)
    assert bbz.from_ours(Message(Op.GET, 2, 0, 0, 500)) is None and bbz.drops["guard_query"] == 1
    assert bbz.from_ours(Message(Op.PUT, 2, 9, 1, 500)) is not None  # a second key: capacity 2
    assert bbz.from_ours(Message(Op.PUT, 6, 1, 1, 500)) is None and bbz.drops["guard_capacity"] == 1
    assert bbz.from_ours(Message(Op.PUT, 4, 0x3E00, 1, 500)) is None  # no string id known for "heading"
    assert bbz.drops["unmapped"] == 4


def test_a_wrapped_timestamp_is_not_handed_to_buzz() -> None:
    buzz = BuzzTranslator(parse_deployment(TEXT))
    buzz.to_ours(BuzzVstig(BuzzOp.PUT, 1, "x", 5, 65530, 9))  # Buzz robots hold ts 65530
    assert buzz.from_ours(Message(Op.PUT, 1, 6, 3, 200)) is None  # newer to us (wrapped), older to Buzz's `<`
    assert buzz.drops["buzz_wrap"] == 1
    assert buzz.from_ours(Message(Op.PUT, 1, 6, 65531, 200)) is not None
    assert buzz.from_ours(Message(Op.GET, 1, 5, 40000, 200)) is not None  # old, not wrapped: Buzz answers it


@pytest.mark.parametrize("nested", ["[" * 100_000 + "]" * 100_000, "{ a = " * 100_000 + "1" + " }" * 100_000])
def test_a_deployment_nested_too_deeply_is_named_not_a_recursion_error(tmp_path: Path, nested: str) -> None:
    import subprocess
    import sys

    deployment = tmp_path / "lab.toml"
    deployment.write_text(f"[keys]\nx = {nested}\n")
    with pytest.raises(DeploymentError, match=f"^{deployment}: arrays or tables nested too deeply to read$"):
        load_deployment(deployment)
    vstig = str(Path(sys.executable).with_name("vstig"))  # and from the command line: one line, a usage error
    done = subprocess.run([vstig, "sniff", f"serial:/dev/ptmx?framing=kilobot&dialect=bittybuzz&deployment="
                           f"{deployment}", "--for", "1"], capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 2 and done.stderr.strip().splitlines()[-1] == (
        f"Error: serial:ptmx: {deployment}: arrays or tables nested too deeply to read"), done.stderr
