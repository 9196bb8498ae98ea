"""`vstig decode` names each message's sender in text and CSV wherever the capture knows one:
an XBee frame's 64-bit source (in hex, as --sender takes it), a CAN ID's sender field, the gateway
a zenoh key names; a frame the gateway sent itself (an XBee Transmit Request) names none."""

from __future__ import annotations

from pathlib import Path

from click.testing import CliRunner

from vstig_cli.main import cli

XBEE = ("# vstig serial capture v1\n"  # a Receive Packet from module 0013A20040A1B2C3 (a PUT and a GET), then our send
        "(1700000000.100000) ttyUSB0 xbee rx 7e001c900013a20040a1b2c3fffe020001012c000400078002000000000007a3\n"
        "(1700000000.150000) ttyUSB0 xbee tx 7e00161001000000000000fffffffe00000001012c00040007ba\n")
CAN = "(1700000000.250000) can0 601#0003006400010001\n"  # a PUT whose CAN ID names sender 1
ZENOH = "# vstig zenoh capture v1\n(1700000000.250000) zenoh-lab zenoh rx vstig/lab/0/201 000100640001001f\n"


def _decode(tmp_path: Path, name: str, text: str, *args: str) -> list[str]:
    path = tmp_path / name
    path.write_text(text)
    result = CliRunner().invoke(cli, ["decode", str(path), *args])
    assert result.exit_code == 0, result.output
    return result.stdout.splitlines()


def test_text_names_an_xbee_module_in_hex_and_our_own_sends_without_one(tmp_path: Path) -> None:
    lines = _decode(tmp_path, "radio.cap", XBEE)
    assert lines[0].endswith("PUT key=1 value=300 ts=4 robot=7 sender=0x0013A20040A1B2C3")
    assert lines[1].endswith("GET key=2 value=0 ts=0 robot=7 sender=0x0013A20040A1B2C3")
    assert lines[2].endswith("PUT key=1 value=300 ts=4 robot=7")  # the gateway's broadcast: no source field


def test_text_names_the_can_id_sender_and_the_zenoh_gateway(tmp_path: Path) -> None:
    assert _decode(tmp_path, "bus.log", CAN) == ["(1700000000.250000) can0 id=601 PUT key=3 value=100 ts=1 robot=1 "
                                                 "sender=1"]
    (line,) = _decode(tmp_path, "lab.zcap", ZENOH)
    assert line.endswith("sender=201"), line


def test_csv_has_a_sender_column_empty_where_the_medium_names_nobody(tmp_path: Path) -> None:
    lines = _decode(tmp_path, "radio.cap", XBEE, "--format", "csv")
    assert lines[0] == "t,link,can_id,op,key,value,timestamp,robot,sender"
    assert lines[1].endswith(f",PUT,1,300,4,7,{0x0013A20040A1B2C3}") and lines[3].endswith(",PUT,1,300,4,7,")
