"""`vstig sniff --robots --jsonl` on 12 real pty robots: 3 go silent mid-run and one keeps sending an old write;
quiet, gone and behind show within the documented times (docs/how-to/robots.md)."""

from __future__ import annotations

import fcntl
import io
import json
import os
import pty
import select
import signal
import struct
import subprocess
import termios
import threading
import time
from pathlib import Path
from typing import Any

from peers import VSTIG, start_vstig, stop, wait_for
from rich.console import Console
from robots import PtyRobot
from roster_steps import KEY, RosterSteps

from vstig_cli.robots import ROBOTS_KEY, robots_table
from vstig_hw.gateway.roster import Roster
from vstig_hw.wire import Message, Op

SILENT = (9, 10, 11)
LAGGING = 12
STEP = 0.1  # the robots' control step, as the gateway's period
QUIET_AFTER, GONE_AFTER = 0.3, 2.0


class Rows:
    """The JSON rows a sniff prints, as they come, with when each arrived."""

    def __init__(self, stream: Any) -> None:
        self.rows: list[tuple[float, dict[str, Any]]] = []
        self._thread = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self._thread.start()

    def _read(self, stream: Any) -> None:
        for line in stream:
            self.rows.append((time.monotonic(), json.loads(line)))

    def first(self, robot: int, since: float, test: Any) -> float | None:
        """When the first row of `robot` arriving after `since` that passes `test` arrived."""
        return next((at for at, row in list(self.rows) if at >= since and row["robot"] == robot and test(row)), None)


def test_quiet_gone_and_behind_show_within_the_documented_time() -> None:
    robots = [PtyRobot(n) for n in range(1, 13)]
    step = RosterSteps(robots, LAGGING, STEP)
    sniff = start_vstig("sniff", *(robot.spec for robot in robots), "--robots", "--jsonl",
                        "--quiet-after", str(QUIET_AFTER), "--gone-after", str(GONE_AFTER))
    rows = Rows(sniff.stdout)
    try:
        wait_for(lambda: {row["robot"] for _, row in rows.rows} >= set(range(1, 13)), 30, step)
        assert all(row["state"] == "alive" and row["named_by"] == "writer" and row["sender"] is None
                   for _, row in rows.rows[-12:]), rows.rows[-12:]
        step.silent.update(SILENT)
        since = time.monotonic()
        wait_for(lambda: all(rows.first(n, since, lambda r: r["state"] == "gone") for n in SILENT), 20, step)
        for n in SILENT:  # their last write was a step before: quiet within quiet-after and a period, printed
            # within the second after (and half a second of a busy machine)
            quiet = rows.first(n, since, lambda r: r["state"] == "quiet")
            gone = rows.first(n, since, lambda r: r["state"] == "gone")
            assert quiet is not None and quiet - since <= QUIET_AFTER + STEP + 1.0 + 0.5, quiet - since
            assert gone is not None and GONE_AFTER - STEP <= gone - since <= GONE_AFTER + STEP + 1.0 + 0.5
        latest = {row["robot"]: row for _, row in rows.rows[-12:]}
        assert {n for n, row in latest.items() if row["state"] == "alive"} == set(range(1, 13)) - set(SILENT)
        assert latest[LAGGING]["behind"] == [KEY] and latest[1]["behind"] == []
        assert all(latest[n]["links"] == [Path(robots[n - 1].radio.path).name] for n in range(1, 9)), latest
        assert latest[1]["writes"] >= 2 * latest[2]["writes"] - 2 and latest[2]["rate"] > 3, latest
    finally:
        _, stderr = stop(sniff)
        for robot in robots:
            robot.close()
    assert "Traceback" not in stderr, stderr


def _roster_of(count: int) -> Roster:
    """`count` robots as a long sniff sees them: XBee-wide ids, busy counters, lagging on many keys, some gone."""
    roster = Roster(0.1, gone_after=60.0)
    now = time.time()
    for key in range(20):
        roster.take("radio0", now - 36, 1, [Message(Op.PUT, key, 1, 2, 1)])
    for n in range(count):
        who = 0x0013A20040A10000 + n
        for key in range(20):
            roster.take("radio0", now - 35, who, [Message(Op.GET, key, 0, 1, 1)] * 600)
        roster.take("radio1", now - (30 if n % 3 else 1), who, [Message(Op.PUT, 1000 + n % 30000, 1, 2, 1)])
    roster.sweep(now)
    return roster


def _rendered(table: object, width: int = 80) -> list[str]:
    console = Console(width=width, record=True, file=io.StringIO())
    console.print(table)
    return console.export_text().splitlines()


def test_the_robots_table_fits_80_columns_one_line_a_robot_sorted_by_state_then_id() -> None:
    roster = _roster_of(40)
    lines = _rendered(robots_table(roster))
    assert all(len(line) <= 80 for line in lines), "\n".join(lines)
    header = next(line for line in lines if line.lstrip().startswith("robot"))
    assert header.split() == ["robot", "by", "state", "links", "heard", "rate", "PUT", "GET", "behind", "refused"]
    rows = [line.split() for line in lines if line.lstrip().startswith("0x")]
    assert len(rows) == 40, "\n".join(lines)  # one line a robot: nothing wrapped
    order = [(["alive", "quiet", "gone"].index(row[2]), int(row[0], 16)) for row in rows]
    assert order == sorted(order) and {row[2] for row in rows} == {"alive", "quiet"}
    # the links that fit and +N, and so the keys it is behind on; counts kept to five characters
    assert rows[0][1:5] == ["s", "alive", "radio0", "+1"] and rows[0][7:9] == ["1", "12k"], rows[0]
    assert rows[0][-4:] == ["0", "1", "2", "+17"] and "…" not in "\n".join(lines), rows[0]


def test_the_robots_table_at_1000_robots_redraws_within_one_control_period() -> None:
    roster = _roster_of(1000)
    console = Console(width=80, height=50, file=io.StringIO(), force_terminal=True)
    times = []
    for _ in range(5):  # the CPU this thread spends: what other work on a shared machine cannot inflate
        start = time.thread_time()
        console.print(robots_table(roster, height=50))
        times.append(time.thread_time() - start)
    assert min(times) < 0.1, times


def test_r_switches_the_live_table_between_keys_and_robots_on_a_real_terminal() -> None:
    robot = PtyRobot(3)
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 80, 0, 0))
    sniff = subprocess.Popen([VSTIG, "sniff", robot.spec], stdin=slave, stdout=slave, stderr=slave,
                             start_new_session=True)
    seen = b""

    def read_until(text: bytes) -> None:
        nonlocal seen
        end = time.monotonic() + 30
        while text not in seen:
            assert time.monotonic() < end and sniff.poll() is None, seen.decode(errors="replace")[-2000:]
            robot.put(7, 1)
            if select.select([master], [], [], 0.2)[0]:
                seen += os.read(master, 65536)

    try:
        read_until(b"conflicts")  # the keys table
        seen = b""
        os.write(master, ROBOTS_KEY.encode())
        read_until(b"behind")  # the robots table
        assert b"alive" in seen
        seen = b""
        os.write(master, ROBOTS_KEY.encode())
        read_until(b"conflicts")  # and back
    finally:
        sniff.send_signal(signal.SIGINT)
        sniff.wait(timeout=30)
        os.close(master)
        os.close(slave)
        robot.close()
    assert sniff.returncode == 0
