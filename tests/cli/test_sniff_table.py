"""`vstig sniff`'s table fits 80 columns, whole, and shows a key only ever asked for as holding nothing."""

from __future__ import annotations

import io
import threading
import time

import can
from click.testing import CliRunner
from rich.console import Console

from vstig_cli.commands.sniff import _table
from vstig_cli.main import cli
from vstig_hw import Message, Op
from vstig_hw.gateway.swarmview import SwarmView
from vstig_hw.links import Heard


def _rendered(table: object, width: int = 80) -> list[str]:
    console = Console(width=width, record=True, file=io.StringIO())
    console.print(table)
    return console.export_text().splitlines()


def _busy_view() -> SwarmView:
    """A key as wide as a long sniff makes it: int16 extremes, five-digit counts, many stale senders, refusals."""
    view = SwarmView()
    then = time.time() - 123.4  # the key was last heard two minutes ago
    for n in range(12_345):
        view.add(Heard(Message(Op.PUT, 999, 0x8000, 65535, 254), "can0", then, 2 + n % 40))
    view.add(Heard(Message(Op.PUT, 999, 1, 65534, 253), "can0", then, 77))  # 77 lags behind
    view.add(Heard(Message(Op.PUT, 999, 7, 65535, 200), "can0", then, 78))  # a conflict
    for _ in range(12):
        view.refuse(Heard(Message(Op.PUT, 999, 1, 3, 9), "can0", then, 9), "drop_source_rate")
    for sender in range(100, 110):
        view.add(Heard(Message(Op.GET, 999, 1, 65000, 1), "can0", then, sender))  # stale views
    view.add(Heard(Message(Op.GET, 4, 0, 0, 9), "can0", time.time(), 9))  # key 4: only ever asked for
    return view


def test_a_busy_table_fits_80_columns_with_every_header_and_cell_whole() -> None:
    lines = _rendered(_table(_busy_view(), "int16"))
    header = next(line for line in lines if line.lstrip().startswith("key"))
    assert header.split() == ["key", "value", "ts", "robot", "age", "PUT", "GET", "conflicts", "stale", "refused"]
    assert all(len(line) <= 80 for line in lines) and not any("…" in line for line in lines), "\n".join(lines)
    busy = next(line for line in lines if line.lstrip().startswith("999 "))
    assert busy.split()[:4] == ["999", "-32768", "65535", "254"] and 123.4 <= float(busy.split()[4][:-1]) < 125, busy
    assert busy.rstrip().endswith("12 source_rate") and " +" in busy, busy  # stale senders: the first, and +N
    rows = [line for line in lines if line.strip() and line.lstrip()[0].isdigit()]
    assert len(rows) == 2, "\n".join(lines)  # one line per key: nothing wrapped


def test_a_key_only_asked_for_shows_no_value_ts_or_robot() -> None:
    lines = _rendered(_table(_busy_view(), "uint16"))
    asked = next(line for line in lines if line.lstrip().startswith("4 "))
    assert asked.split()[:4] == ["4", "-", "-", "-"] and asked.split()[5:7] == ["0", "1"], asked  # 0 PUT, 1 GET


def test_sniff_prints_its_table_whole_at_80_columns_with_an_asked_for_key_as_dashes() -> None:
    def robot() -> None:
        time.sleep(0.5)
        with can.Bus(interface="virtual", channel="vstig-table-80") as bus:
            bus.send(can.Message(arbitration_id=0x707, data=bytes.fromhex("8005000000000007"), is_extended_id=False))
            bus.send(can.Message(arbitration_id=0x607, data=bytes.fromhex("0003000a00020007"), is_extended_id=False))

    threading.Thread(target=robot, daemon=True).start()
    result = CliRunner().invoke(cli, ["sniff", "can:virtual:vstig-table-80", "--for", "1.5"], env={"COLUMNS": "80"})
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert "vstig sniff: 2 messages, 2 keys" in result.stdout, result.stdout
    assert all(len(line) <= 80 for line in lines) and "…" not in result.stdout, result.stdout
    (asked,) = [line.split() for line in lines if line.lstrip().startswith("5 ")]
    assert asked[:4] == ["5", "-", "-", "-"] and asked[5:7] == ["0", "1"], asked  # a GET for key 5, no entry
    (written,) = [line.split() for line in lines if line.lstrip().startswith("3 ")]
    assert written[:4] == ["3", "10", "2", "7"], written


def test_the_live_views_table_row_of_a_key_only_asked_for_has_no_value_or_robot() -> None:
    from vstig_hw.live.server import LiveServer

    server = LiveServer(["can0"])  # never opened: its table is built from what it was fed
    server._view.add(Heard(Message(Op.GET, 5, 0, 0, 7), "can0", time.time(), 7))
    server._view.add(Heard(Message(Op.PUT, 3, 10, 2, 7), "can0", time.time(), 7))
    rows = {row["key"]: row for row in server.table()["rows"]}
    assert (rows[5]["value"], rows[5]["timestamp"], rows[5]["robot"], rows[5]["gets"]) == (None, 0, None, 1)
    assert (rows[3]["value"], rows[3]["timestamp"], rows[3]["robot"]) == (10, 2, 7)
