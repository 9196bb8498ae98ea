"""A misspelled option on every kind of link and every port form is a usage error naming it and its closest known
key: exit 2 from `vstig`, ValueError from `vstig_hw.join`, never pyserial's KeyError (issue 44)."""

from __future__ import annotations

import pytest
from peers import run_vstig

import vstig_hw
from vstig_hw.links import examples
from vstig_hw.links.registry import SCHEMES
from vstig_hw.links.serial import PYSERIAL_URL_OPTIONS

# (what it covers, spec with one misspelled key, that key, the key it is closest to)
TYPOS = [
    ("can", "can:virtual:lab?bitrat=500000", "bitrat", "bitrate"),
    ("serial", "serial:/dev/ttyUSB0?frming=cobs8", "frming", "framing"),
    ("loop", "serial:loop://?frming=cobs8", "frming", "framing"),
    ("loop before our ?", "serial:loop://?frming=cobs8?baud=9600", "frming", "framing"),
    ("socket", "serial:socket://localhost:7000?framing=epuck4&bud=9600", "bud", "baud"),
    ("rfc2217", "serial:rfc2217://localhost:7000?timout=3", "timout", "timeout"),
    ("spy", "serial:spy://loop://?colour", "colour", "color"),
    ("alt", "serial:alt:///dev/ttyUSB0?clas=PosixPollSerial", "clas", "class"),
    ("hwgrep", "serial:hwgrep://USB?frameing=cobs8", "frameing", "framing"),
    ("cp2110", "serial:cp2110://0001:004a:00?bauds=9600", "bauds", "baud"),
    ("xbee", "serial:/dev/ttyUSB0?framing=xbee&dst=0013A20040A1B2C3", "dst", "dest"),
    ("bittybuzz", "serial:/dev/ttyUSB0?framing=kilobot&dialect=bittybuzz&deploymnt=lab.toml", "deploymnt",
     "deployment"),
    ("rosbuzz", "serial:/dev/ttyUSB0?framing=xbee&dialect=buzz&deployment=drones.toml&ap=2", "ap", "api"),
    ("kilobot-ohc", "kilobot-ohc:/dev/ttyUSB0?dialekt=bittybuzz", "dialekt", "dialect"),
    ("kilobot-ohc socket", "kilobot-ohc:socket://localhost:7000?dialekt=bittybuzz", "dialekt", "dialect"),
    ("blabbermouth", "blabbermouth:127.0.0.1?size=64&deployment=lab.toml&sise=64", "sise", "size"),
    ("zenoh", "zenoh:lab?conect=tcp/127.0.0.1:7447", "conect", "connect"),
    ("ros2", "ros2:lab?domian=7", "domian", "domain"),
    ("mavlink", "mavlink:serial:/dev/ttyUSB0?bauds=57600", "bauds", "baud"),
    ("mavlink udp", "mavlink:udpin:127.0.0.1:14560?sysd=12", "sysd", "sysid"),
    ("auth, every kind's", "zenoh:lab?auht=require", "auht", "auth"),
]


def test_every_kind_and_url_scheme_has_a_typo_case() -> None:
    """A new kind of link, or a pyserial URL scheme, must join the table above."""
    covered = {case for case, *_ in TYPOS}
    assert set(SCHEMES) | set(examples()) | set(PYSERIAL_URL_OPTIONS) <= covered


@pytest.mark.parametrize(("spec", "typo", "closest"), [case[1:] for case in TYPOS], ids=[c[0] for c in TYPOS])
def test_the_cli_names_the_misspelled_option(spec: str, typo: str, closest: str) -> None:
    done = run_vstig("bridge", spec, "--robot-id", "1", timeout=30)
    assert done.returncode == 2, done.stderr
    assert f"unknown parameter '{typo}" in done.stderr and f"did you mean {closest}?" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr and "KeyError" not in done.stderr


@pytest.mark.parametrize(("spec", "typo", "closest"), [case[1:] for case in TYPOS], ids=[c[0] for c in TYPOS])
def test_join_raises_a_value_error_naming_it(spec: str, typo: str, closest: str) -> None:
    with pytest.raises(ValueError) as caught:
        vstig_hw.join(spec, robot_id=1)
    assert type(caught.value) is ValueError
    message = str(caught.value)
    assert message.startswith("links: bad link spec") and f"unknown parameter '{typo}" in message
    assert f"did you mean {closest}?" in message


@pytest.mark.parametrize(("spec", "names"), [
    ("serial:loop://?logging=verbose", "logging='verbose' is not one of debug|info|warning|error"),
    ("serial:socket://localhost:99999", "socket:// needs <host>:<port 0..65535>"),
    ("serial:socket://localhost", "socket:// needs <host>:<port 0..65535>"),
    ("serial:rfc2217://:7000", "rfc2217:// needs <host>:<port 0..65535>"),
])
def test_values_pyserial_would_turn_into_an_internal_error(spec: str, names: str) -> None:
    """pyserial formats its own message for these with a `{...}` in it: a KeyError or TypeError escaped it."""
    done = run_vstig("bridge", spec, "--robot-id", "1", timeout=30)
    assert done.returncode == 2 and names in done.stderr, done.stderr
    with pytest.raises(ValueError, match=names.replace("|", r"\|").replace("(", r"\(")):
        vstig_hw.join(spec, robot_id=1)


def test_a_known_pyserial_option_still_reaches_pyserial() -> None:
    from vstig_hw.links import parse

    assert parse("serial:loop://?logging=debug&framing=epuck4").port == "loop://?logging=debug"  # type: ignore[attr-defined]
    assert parse("serial:spy://loop://?color&framing=epuck4").port == "spy://loop://?color"  # type: ignore[attr-defined]


def test_a_url_pyserial_cannot_read_is_a_transport_error_from_serial_link() -> None:
    """serial_link takes a URL unchecked: pyserial's own KeyError on it becomes the transport's one line."""
    from vstig_hw.links.serial import serial_link
    from vstig_hw.transports.base import TransportError

    with pytest.raises(TransportError, match=r"serial port loop://\?frming=1: pyserial cannot read this URL"):
        serial_link("loop://?frming=1")
