"""The link-spec grammar: examples parse to the right fields, bad specs say what is wrong."""

from __future__ import annotations

import contextlib
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vstig_hw.links import examples, parse
from vstig_hw.links.can import CanSpec
from vstig_hw.links.registry import SCHEMES
from vstig_hw.links.serial import SerialSpec


def test_can_specs() -> None:
    assert parse("can:socketcan:vcan0") == CanSpec("socketcan", "vcan0")
    spec = parse("can:slcan:/dev/ttyACM0?bitrate=500000")
    assert spec == CanSpec("slcan", "/dev/ttyACM0", bitrate=500000)
    assert spec.name == "dev_ttyACM0"
    spec = parse("can:socketcan:can0?fd=1&id_base=0x18000000&extended=1")
    assert spec == CanSpec("socketcan", "can0", fd=True, id_base=0x18000000, extended=True)
    spec = parse("can:socketcan:can0?extended=1&stigmergy=0x2a")
    assert spec == CanSpec("socketcan", "can0", extended=True, stigmergy=42)
    assert parse("can:virtual:lab?filter=0") == CanSpec("virtual", "lab", kernel_filter=False)
    assert parse("can:virtual:lab?echo=1") == CanSpec("virtual", "lab", echo=True)


def test_serial_specs() -> None:
    assert parse("serial:/dev/ttyUSB0") == SerialSpec("/dev/ttyUSB0", 115200, "cobs8")
    assert parse("serial:/dev/ttyUSB0?baud=9600&framing=kilobot") == SerialSpec("/dev/ttyUSB0", 9600, "kilobot")
    spec = parse("serial:socket://localhost:7000?framing=epuck4")
    assert spec == SerialSpec("socket://localhost:7000", 115200, "epuck4")
    assert spec.name == "localhost:7000"
    spec = parse("serial:/dev/ttyUSB1?framing=epuck4&expiry_ticks=5")
    assert spec == SerialSpec("/dev/ttyUSB1", 115200, "epuck4", expiry_ticks=5)


def test_url_keeps_its_own_options() -> None:
    spec = parse("serial:socket://h:7000?logging=debug&framing=epuck4")
    assert spec == SerialSpec("socket://h:7000?logging=debug", 115200, "epuck4")


def test_kilobot_ohc() -> None:
    spec = parse("kilobot-ohc:/dev/ttyUSB1")
    assert spec == SerialSpec("/dev/ttyUSB1", 38400, "kilobot-ohc") and spec.kind == "kilobot-ohc"


def test_every_documented_example_parses() -> None:
    for specs in examples().values():
        for example in specs:
            parse(example)


@pytest.mark.parametrize(
    ("spec", "names"),
    [
        ("usb:/dev/ttyUSB0", "unknown kind 'usb'"),
        ("serial:/dev/ttyUSB0?buad=9600", "unknown parameter 'buad=9600'"),
        ("serial:/dev/ttyUSB0?baud=fast", "baud='fast' is not an integer"),
        ("serial:/dev/ttyUSB0?framing=hdlc", "framing='hdlc'"),
        ("serial:?baud=9600", "the port is missing"),
        ("can:virtual", "expected can:<interface>:<channel>"),
        ("can:virtual:lab?fd=yes", "fd='yes' must be 0 or 1"),
        ("can:virtual:lab?id_base=0x800", "id_base=0x800 is outside"),
        ("can:vir tual:lab", "interface 'vir tual'"),
        ("can:virtual:lab?bitrate", "parameter 'bitrate' needs a value"),
        ("serial:/dev/ttyUSB0?expiry_ticks=5", "expiry_ticks is an epuck4 option"),
        ("serial:/dev/ttyUSB0?framing=epuck4&expiry_ticks=0", "expiry_ticks=0 is outside 1..254"),
        ("can:virtual:lab?filter=no", "filter='no' must be 0 or 1"),
        ("can:virtual:lab?stigmergy=2", "stigmergy=2 needs 29-bit IDs (extended=1)"),
        ("can:virtual:lab?extended=1&stigmergy=256", "stigmergy=256 is outside 0..255"),
    ],
)
def test_bad_specs_name_the_bad_part_and_show_an_example(spec: str, names: str) -> None:
    with pytest.raises(ValueError) as caught:
        parse(spec)
    text = str(caught.value)
    assert names in text and "(e.g. " in text and "\n" not in text


@given(st.text(max_size=60))
def test_fuzz_only_value_error(spec: str) -> None:
    try:
        parsed = parse(spec)
    except ValueError as error:
        assert "\n" not in str(error).replace(repr(spec), "")
    else:  # only text that names a registered kind parses (a ros2 or zenoh swarm may be any name)
        assert spec.partition(":")[0] in SCHEMES, (spec, parsed)


@given(st.sampled_from(["can:virtual:", "serial:", "serial:socket://x:1", "kilobot-ohc:"]), st.text(max_size=40))
def test_fuzz_after_a_valid_prefix(prefix: str, tail: str) -> None:
    with contextlib.suppress(ValueError):
        parse(prefix + tail)


def test_spec_options_reach_the_link() -> None:
    """expiry_ticks goes to the epuck4 reassembler; filter=0 leaves the CAN bus without acceptance filters."""
    serial = parse("serial:/dev/ttyUSB1?framing=epuck4&expiry_ticks=5").build()
    assert serial.framing.reassembler.expiry_ticks == 5  # type: ignore[attr-defined]
    assert "can_filters" not in parse("can:virtual:x?filter=0").build().transport._bus_kwargs  # type: ignore[attr-defined]
    assert "can_filters" in parse("can:virtual:x").build().transport._bus_kwargs  # type: ignore[attr-defined]


def test_which_links_are_one_broadcast_domain(tmp_path: Path) -> None:
    """A bus and a blabbermouth relay are (no echo of a PUT back onto them); radios, and a bus with echo=1, are not."""
    deployment = tmp_path / "kheperas.toml"
    deployment.write_text('[keys]\nleader = { key = 1, type = "int16" }\n', encoding="utf-8")
    assert parse(f"blabbermouth:127.0.0.1?size=64&deployment={deployment}").build().one_domain
    assert parse("can:virtual:x").build().one_domain
    assert not parse("can:virtual:x?echo=1").build().one_domain
    assert not parse("serial:/dev/ttyUSB1?framing=epuck4").build().one_domain
    assert not parse("serial:/dev/ttyUSB1").build().one_domain


def test_bus_options_reach_python_can() -> None:
    spec = parse("can:socketcand:can0?bus.host=192.168.1.5&bus.port=29536&bus.receive_own_messages=true")
    assert isinstance(spec, CanSpec)
    assert spec.bus_options == (("host", "192.168.1.5"), ("port", 29536), ("receive_own_messages", True))
    with pytest.raises(ValueError, match=r"bus\.bitrate is not a bus option of its own: give bitrate= itself"):
        parse("can:virtual:x?bus.bitrate=500000")
    with pytest.raises(ValueError, match=r"unknown parameter 'bus\.=1'"):
        parse("can:virtual:x?bus.=1")
    # On a real python-can bus: receive_own_messages makes the link hear what it sends.
    import can

    link = parse("can:virtual:vstig-edges-own?bus.receive_own_messages=true").build("own", robot_id=3)
    link.open()
    try:
        link.transport.write(can.Message(arbitration_id=0x603, data=bytes(8), is_extended_id=False))
        assert any(f.arbitration_id == 0x603 for f in link.transport.read(2.0))
    finally:
        link.close()
