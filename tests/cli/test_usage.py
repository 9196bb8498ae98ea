"""Parsing and errors through CliRunner: usage errors exit 2, runtime failures 1, one line, no traceback."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from vstig_cli.main import cli


def invoke(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(cli, list(args))
    return result.exit_code, result.output


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["bridge", "usb:/dev/x", "--robot-id", "1"], "unknown kind 'usb'"),
        (["bridge", "can:virtual:x"], "--robot-id is required"),
        (["bridge", "can:virtual:x", "--raw"], "--raw needs at least two links"),
        (["sniff", "serial:/dev/null?framing=hdlc"], "framing='hdlc'"),
        (["sniff", "serial:/dev/null", "--value-type", "int8"], "'int8' is not one of"),
        (["put", "3", "70000", "--on", "can:virtual:x"], "outside uint16"),
        (["put", "40000", "1", "--on", "can:virtual:x"], "40000 is outside 0..32767"),
        (["get", "1"], "Missing option '--on'"),
        (["record", "can:virtual:x", "-o", "out.txt"], "chosen by extension"),
        (["record", "serial:/dev/null", "-o", "o.cap", "--max-bytes", "lots"], "not a size"),
        (["replay", "README.md"], "exactly one of --onto LINK or --table"),
        (["decode", "README.md", "--id-base", "zz"], "'zz' is not an integer"),
        (["sniff", "kilobot-ohc:/dev/null"], "kilobot-ohc:null is transmit-only"),
        (["sim", "--topology", "line", "--density", "2"], "a line layout is built by distance"),
        (["sniff", "can:virtual:x?id_base=0x601"], "must be one of 0x000, 0x200, 0x400, 0x600, got 0x601"),
        (["bridge", "can:virtual:x", "--robot-id", "300"], "300 does not fit can:virtual:x"),
        (["record", "kilobot-ohc:/dev/null", "-o", "x.cap"], "record needs a link that receives"),
    ],
)
def test_usage_errors_exit_2_with_one_clear_line(args: list[str], says: str) -> None:
    code, output = invoke(*args)
    assert code == 2, output
    assert says in output and "Traceback" not in output


def test_runtime_failures_exit_1_in_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.log"
    bad.write_text("(1.000000) can0 600#0001000200030004\nnot a frame\n")
    result = CliRunner().invoke(cli, ["decode", str(bad)])
    assert result.exit_code == 1 and "bad.log:2: not a candump line" in result.stderr
    assert result.stderr.strip().count("\n") == 0 and "Traceback" not in result.output
    code, output = invoke("sniff", "serial:/dev/vstig-no-such-port", "--jsonl", "--for", "1")
    assert code == 1 and "vstig-no-such-port" in output and "Traceback" not in output
    code, output = invoke("sniff", "can:vstignosuch:x", "--for", "0.1")
    assert code == 1 and "python-can knows: " in output and "socketcan" in output
    code, output = invoke("decode", str(tmp_path / "missing.log"))
    assert code == 2 and "does not exist" in output


def test_skip_bad_counts_and_continues(tmp_path: Path) -> None:
    bad = tmp_path / "bad.log"
    bad.write_text("(1.000000) can0 600#0001000200030004\nnot a frame\n(2.000000) can0 600#0001000200030005\n")
    result = CliRunner().invoke(cli, ["decode", str(bad), "--skip-bad", "--format", "csv"])
    assert result.exit_code == 0
    assert result.stdout.splitlines()[0] == "t,link,can_id,op,key,value,timestamp,robot,sender"
    assert len(result.stdout.splitlines()) == 3 and "1 bad line skipped" in result.stderr


def test_debug_shows_the_traceback(tmp_path: Path) -> None:
    bad = tmp_path / "bad.log"
    bad.write_text("nonsense\n")
    result = CliRunner().invoke(cli, ["--debug", "decode", str(bad)])
    assert result.exit_code == 1 and "Traceback" in result.output


def test_links_lists_the_grammar_with_examples() -> None:
    code, output = invoke("links")
    assert code == 0
    for text in ("can:<python-can interface>:<channel>", "serial:<port or pyserial URL>", "kilobot-ohc:",
                 "can:socketcan:vcan0", "serial:socket://localhost:7000?framing=epuck4",
                 "Every kind also takes auth=require|prefer|off"):
        assert text in output


def test_every_command_is_listed() -> None:
    code, output = invoke("--help")
    assert code == 0
    for name in ("bridge", "sniff", "record", "replay", "decode", "put", "get", "links", "demo"):
        assert name in output


def test_csv_of_several_files_has_one_header_and_a_file_column(tmp_path: Path) -> None:
    a, b = tmp_path / "a.log", tmp_path / "b.log"
    a.write_text("(1.000000) can0 600#0001000200030004\n")
    b.write_text("(2.000000) can0 600#0001000200030005\nnot a frame\n")
    result = CliRunner().invoke(cli, ["decode", str(a), str(b), "--format", "csv", "--skip-bad"])
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0] == "file,t,link,can_id,op,key,value,timestamp,robot,sender" and len(lines) == 3
    assert lines[1].startswith(f'"{a}",1.000000,') and lines[2].startswith(f'"{b}",2.000000,')


def test_damaged_python_can_files_name_the_record_and_honour_skip_bad(tmp_path: Path) -> None:
    damaged = tmp_path / "x.csv"
    damaged.write_text("timestamp,arbitration_id,extended,remote,error,dlc,data\n"
                       "1.0,0x600,0,0,0,8,AAEAAgADAAQ=\nnot,a,row\n3.0,0x600,0,0,0,8,AAEAAgADAAQ=\n")
    result = CliRunner().invoke(cli, ["decode", str(damaged)])
    assert result.exit_code == 1 and f"{damaged}: record 2: cannot read as .csv" in result.stderr
    result = CliRunner().invoke(cli, ["decode", str(damaged), "--skip-bad"])
    assert result.exit_code == 0 and len(result.stdout.splitlines()) == 1
    assert "1 bad line skipped" in result.stderr and "record 2" in result.stderr
    empty = tmp_path / "empty.blf"
    empty.write_bytes(b"")
    result = CliRunner().invoke(cli, ["decode", str(empty)])
    assert result.exit_code == 1 and f"{empty}: empty file: not a .blf capture" in result.stderr


def test_sniff_into_a_pipe_says_when_its_table_comes(tmp_path: Path) -> None:
    result = CliRunner().invoke(cli, ["sniff", "can:virtual:vstig-edges-pipe", "--for", "0.1"])
    assert result.exit_code == 0, result.output
    assert "the table is printed once, when sniff ends" in result.stderr and "vstig sniff" in result.stdout
    assert "can:virtual:vstig-edges-pipe is a bus inside this process only" in result.stderr


def test_serial_capture_damage_names_file_and_line(tmp_path: Path) -> None:
    cap = tmp_path / "radio.cap"
    cap.write_text("# vstig serial capture v1\n(1.000000) radio bogus rx 0102\n(2.000000) radio cobs8 rx 00\n")
    result = CliRunner().invoke(cli, ["decode", str(cap)])
    assert result.exit_code == 1 and f"{cap}:2: unknown serial framing 'bogus'" in result.stderr
    result = CliRunner().invoke(cli, ["decode", str(cap), "--skip-bad"])
    assert result.exit_code == 0 and "1 bad line skipped" in result.stderr
    cap.write_text("# vstig serial capture v2\n(1.000000) radio cobs8 rx 00\n")
    result = CliRunner().invoke(cli, ["decode", str(cap)])
    assert result.exit_code == 1 and f"{cap}:1: serial capture 'v2' is not a version this vstig-hw reads" \
        in result.stderr


def test_a_blf_cut_short_is_an_error_not_a_quiet_success(tmp_path: Path) -> None:
    import can

    whole = tmp_path / "whole.blf"
    writer = can.Logger(str(whole))
    for i in range(2000):
        writer.on_message_received(can.Message(timestamp=1700000000 + i / 100, arbitration_id=0x600 | i % 100,
                                               data=i.to_bytes(8, "big"), is_extended_id=False))
    writer.stop()
    cut = tmp_path / "cut.blf"
    cut.write_bytes(whole.read_bytes()[: whole.stat().st_size * 2 // 3])
    assert CliRunner().invoke(cli, ["decode", str(whole)]).exit_code == 0
    result = CliRunner().invoke(cli, ["decode", str(cut)])
    assert result.exit_code == 1 and f"{cut}: record " in result.stderr and "cut short" in result.stderr


def test_sniff_and_decode_print_one_json_schema(tmp_path: Path) -> None:
    import json
    import threading
    import time

    import can

    frame = can.Message(arbitration_id=0x607, data=bytes.fromhex("0003000a00020007"), is_extended_id=False)
    log = tmp_path / "one.log"
    log.write_text("(1700000000.000000) vcan0 607#0003000A00020007\n")
    decoded = json.loads(CliRunner().invoke(cli, ["decode", str(log), "--format", "jsonl"]).stdout)

    def robot() -> None:
        time.sleep(0.5)
        with can.Bus(interface="virtual", channel="vstig-edges-schema") as bus:
            bus.send(frame)

    threading.Thread(target=robot, daemon=True).start()
    result = CliRunner().invoke(cli, ["sniff", "can:virtual:vstig-edges-schema", "--jsonl", "--for", "1.5"])
    sniffed = json.loads(result.stdout.splitlines()[0])
    assert list(decoded) == ["t", "link", "can_id", "op", "key", "value", "timestamp", "robot", "sender"]
    assert list(sniffed) == [*decoded, "refused"] and sniffed["refused"] is None  # sniff adds the guard's verdict
    assert {k: sniffed[k] for k in list(decoded)[2:]} == {k: decoded[k] for k in list(decoded)[2:]}
    assert decoded["sender"] == 7 and decoded["can_id"] == 0x607


def test_sniff_filters_what_it_shows_and_its_table_says_what_fits() -> None:
    import json
    import threading
    import time

    import can

    from vstig_cli.commands.sniff import _table
    from vstig_hw import Message, Op
    from vstig_hw.gateway.swarmview import SwarmView
    from vstig_hw.links import Heard

    def robot() -> None:
        time.sleep(0.5)
        with can.Bus(interface="virtual", channel="vstig-edges-filter") as bus:
            for key in (3, 4, 3):
                bus.send(can.Message(arbitration_id=0x607, data=bytes([0, key, 0, 1, 0, 1, 0, 7]),
                                     is_extended_id=False))

    threading.Thread(target=robot, daemon=True).start()
    result = CliRunner().invoke(cli, ["sniff", "can:virtual:vstig-edges-filter", "--jsonl", "--key", "3",
                                      "--for", "1.5"])
    rows = [json.loads(line) for line in result.stdout.splitlines()]
    assert result.exit_code == 0 and [row["key"] for row in rows] == [3, 3], result.output

    view = SwarmView()
    for key in range(20):
        view.add(Heard(Message(Op.PUT, key, 1, 1, 2), "can0", 1.0, 2))
    table = _table(view, "uint16", height=12)
    assert table.row_count == 4 and "keys 0..3 shown; --key K for others" in str(table.title)  # no side borders
    assert _table(view, "uint16").row_count == 20


def test_a_raw_bridge_says_which_node_it_sends_as() -> None:
    result = CliRunner().invoke(cli, ["bridge", "can:virtual:vstig-edges-a", "can:virtual:vstig-edges-b", "--raw",
                                      "--for", "0.2"])
    assert result.exit_code == 0 and "messages re-encoded onto CAN go out as node 0" in result.stderr


def test_a_garbage_line_in_an_asc_file_is_file_line_not_silence(tmp_path: Path) -> None:
    import can

    asc = tmp_path / "x.asc"
    writer = can.Logger(str(asc))
    for i in range(3):
        writer.on_message_received(can.Message(timestamp=1700000000.0 + i, arbitration_id=0x600, channel=1,
                                               data=bytes.fromhex("0001000200030004"), is_extended_id=False))
    writer.stop()
    assert CliRunner().invoke(cli, ["decode", str(asc)]).exit_code == 0
    lines = asc.read_text().splitlines()
    lines.insert(6, "garbage here")
    asc.write_text("\n".join(lines) + "\n")
    result = CliRunner().invoke(cli, ["decode", str(asc)])
    assert result.exit_code == 1 and f"{asc}:7: not an ASC line: 'garbage here'" in result.stderr
    result = CliRunner().invoke(cli, ["decode", str(asc), "--skip-bad"])
    assert result.exit_code == 0 and len(result.stdout.splitlines()) == 3 and "1 bad line skipped" in result.stderr
