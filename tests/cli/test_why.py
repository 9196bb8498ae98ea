"""`vstig why` on a capture a real `vstig bridge --record` process made, with one planted cause per key.

The bridge (robot 200) joins seven pty radios, one robot on each, played by this test:

* key 1: W writes ts 2 over deaf robot D's ts 1. D keeps asking with ts 1 and never reads (its radio is
  deaf); healthy robot H reads what the bridge sends and shows it back.
* key 2: W writes ts 2 while F's port is full (nothing reads it): the bridge's queue for F never empties.
* key 3: G writes ts 1, then jumps to ts 1000: the guard refuses it (drop_jump).
* key 4: C and W write the same timestamp as robots 3 and 9: robot 9's wins, C keeps showing its own.
* key 5: W writes it; N is heard (it asks for key 1) but never asks for key 5.

`why` must name each cause, and none for H and W; and `replay --table --at T` must hold, at T, the newest write
`why` names for every key the guard did not refuse.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest
from peers import PtyPeer, has_open, run_vstig, start_vstig, stop, wait_for

from vstig_hw import Message, Op, Stigmergy
from vstig_hw.framing import make_serial_framing
from vstig_hw.links import parse

DEAF, FULL, GUARDED, CONFLICT, NEVER = 1, 2, 3, 4, 5


class Robot:
    """One robot on a pty radio: sends messages as they are, and reads what the bridge sends (unless deaf)."""

    def __init__(self) -> None:
        self.peer = PtyPeer()
        self.spec = f"serial:{self.peer.path}?framing=cobs8"
        self.name = parse(self.spec).name
        self._framing = make_serial_framing("cobs8")
        self.heard: list[Message] = []

    def send(self, op: Op, key: int, value: int, ts: int, robot: int) -> None:
        for unit in self._framing.encode(Message(op, key, value, ts, robot)):
            self.peer.write(unit)

    def read(self) -> list[Message]:
        got = []
        while data := self.peer.read(0):
            got += self._framing.feed(data)
        self.heard += got
        return got


def _choke(robot: Robot) -> None:
    """Fill the radio's pty towards its far end to the last byte (not only in 4 KiB steps, which leave room for
    a frame), as a radio would that stopped reading long ago: the bridge's writes to it take nothing."""
    fd = os.open(robot.peer.path, os.O_WRONLY | os.O_NONBLOCK | os.O_NOCTTY)
    try:
        quiet_since = time.monotonic()
        while time.monotonic() - quiet_since < 0.3:
            for size in (4096, 256, 1):
                try:
                    while True:
                        os.write(fd, bytes(size))
                        quiet_since = time.monotonic()
                except BlockingIOError:
                    pass
            time.sleep(0.02)
    finally:
        os.close(fd)


def _why(capture: Path, *args: str) -> dict:
    result = run_vstig("why", str(capture), "--json", *args)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


def _verdict(capture: Path, key: int, robot: Robot, *at: str) -> dict:
    (only,) = _why(capture, "--key", str(key), "--robot", robot.name, *at)["senders"]
    return only


def _while_the_robots_ran(capture: Path, robots: dict[str, Robot]) -> tuple[str, str]:
    """--at the last time W was heard: before the bridge's stop, whose drain may still reach a full port."""
    return "--at", str(_verdict(capture, DEAF, robots["W"])["last_heard"])


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Robot]]:
    robots = {name: Robot() for name in "WDHFGCN"}
    path = tmp_path_factory.mktemp("why") / "swarm.cap"
    bridge = start_vstig("bridge", *(r.spec for r in robots.values()), "--robot-id", "200", "--record", str(path))
    w, d, h, f, g, c, n = robots.values()
    healthy = Stigmergy(6)
    try:
        wait_for(lambda: all(has_open(bridge.pid, r.peer.path) for r in robots.values()), 30)
        time.sleep(0.3)
        d.send(Op.PUT, DEAF, 10, 1, 7)
        f.send(Op.PUT, FULL, 10, 1, 8)
        g.send(Op.PUT, GUARDED, 10, 1, 11)
        c.send(Op.PUT, CONFLICT, 30, 5, 3)
        time.sleep(0.5)
        _choke(f)  # F's radio takes nothing more: what the bridge sends it waits in its queue
        w.send(Op.PUT, DEAF, 20, 2, 5)
        w.send(Op.PUT, FULL, 20, 2, 5)
        w.send(Op.PUT, CONFLICT, 90, 5, 9)
        w.send(Op.PUT, NEVER, 50, 1, 5)
        g.send(Op.PUT, GUARDED, 99, 1000, 11)  # a jump of 999 > the guard's 255
        for _ in range(25):
            for robot in (w, d, g, c, n):
                robot.read()  # drained and ignored: deaf, or playing a robot that keeps its own entry
            for msg in h.read():
                healthy.receive(msg)
            healthy.get(DEAF)
            for msg in healthy.drain(4):
                h.send(msg.op, msg.key, msg.value, msg.timestamp, msg.robot)
            d.send(Op.GET, DEAF, 10, 1, 7)
            f.send(Op.GET, FULL, 10, 1, 8)
            g.send(Op.GET, GUARDED, 99, 1000, 11)
            c.send(Op.GET, CONFLICT, 30, 5, 3)
            n.send(Op.GET, DEAF, 0, 0, 0)
            w.send(Op.GET, DEAF, 20, 2, 5)
            time.sleep(0.1)
    finally:
        _, err = stop(bridge)
        for robot in robots.values():
            robot.peer.close()
    assert "units in" in err, err
    return path, robots


def test_the_bridge_records_what_it_heard_sent_and_decided(capture: tuple[Path, dict[str, Robot]]) -> None:
    path, robots = capture
    text = path.read_text()
    assert f") {robots['D'].name} cobs8 tx " in text  # what it sent the deaf robot
    assert f") {robots['W'].name} cobs8 rx " in text
    assert "# vstig decision (" in text and f" {robots['G'].name} drop_jump 1 sender=- key={GUARDED} ts=1000" in text
    assert f" {robots['F'].name} queued " in text
    assert " engine conflict 1" in text


def test_why_names_each_planted_cause(capture: tuple[Path, dict[str, Robot]]) -> None:
    path, robots = capture
    at = _while_the_robots_ran(path, robots)
    deaf = _verdict(path, DEAF, robots["D"], *at)
    assert deaf["cause"] == "deaf", deaf
    assert "never shown back" in deaf["verdict"]
    full = _verdict(path, FULL, robots["F"], *at)
    assert full["cause"] == "never_sent", full
    assert "queue for it was full" in full["verdict"]
    refused = _verdict(path, GUARDED, robots["G"], *at)
    assert refused["cause"] == "refused" and "drop_jump" in refused["verdict"], refused
    lost = _verdict(path, CONFLICT, robots["C"], *at)
    assert lost["cause"] == "conflict_lost" and "robot 9" in lost["verdict"], lost
    never = _verdict(path, NEVER, robots["N"], *at)
    assert never["cause"] == "never_asked", never


def test_why_names_no_cause_where_there_was_none(capture: tuple[Path, dict[str, Robot]]) -> None:
    path, robots = capture
    for robot in (robots["H"], robots["W"]):
        verdict = _verdict(path, DEAF, robot)
        assert verdict["cause"] is None and "holds the newest write" in verdict["verdict"], verdict
    answer = _why(path, "--key", str(DEAF))
    assert answer["newest"]["ts"] == 2 and answer["newest"]["robot"] == 5
    assert answer["path"][0]["sender"] == robots["W"].name
    assert any(hop["sent"] and hop["link"] == robots["H"].name for hop in answer["path"])
    assert any(hop["sender"] == robots["H"].name and not hop["sent"] for hop in answer["path"])
    causes = {s["sender"]: s["cause"] for s in answer["senders"]}
    assert causes[robots["D"].name] == "deaf" and causes[robots["H"].name] is None


@pytest.mark.parametrize("at", [1.0, 2.0, 100.0])
def test_replay_table_and_why_agree_on_the_newest_write_at_t(capture: tuple[Path, dict[str, Robot]],
                                                             at: float) -> None:
    path, _ = capture
    table = run_vstig("replay", str(path), "--table", "--at", str(at))
    assert table.returncode == 0, table.stderr
    rows = {int(k): (int(ts), int(robot)) for k, _v, ts, robot in
            (line.split() for line in table.stdout.splitlines()[2:])}
    for key in (DEAF, FULL, CONFLICT, NEVER):
        newest = _why(path, "--key", str(key), "--at", str(at))["newest"]
        assert rows.get(key) == (None if newest is None else (newest["ts"], newest["robot"])), (key, at)


DOCS_PLOT = Path(__file__).parents[2] / "docs" / "how-to" / "img" / "why-key1.png"


def test_the_plot_is_written_and_a_second_one_is_not_replaced(capture: tuple[Path, dict[str, Robot]],
                                                             tmp_path: Path) -> None:
    """The PNG of docs/how-to/why.md comes from here: VSTIG_WRITE_DOCS_PLOT=1 writes it there too."""
    path, _robots = capture
    png = tmp_path / "key1.png"
    result = run_vstig("why", str(path), "--key", str(DEAF), "--plot", str(png))
    assert result.returncode == 0, result.stderr
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    again = run_vstig("why", str(path), "--key", str(DEAF), "--plot", str(png))
    assert again.returncode == 2 and "--overwrite" in again.stderr
    if os.environ.get("VSTIG_WRITE_DOCS_PLOT") == "1":
        DOCS_PLOT.parent.mkdir(exist_ok=True)
        DOCS_PLOT.write_bytes(png.read_bytes())


def test_bad_input_is_one_line(capture: tuple[Path, dict[str, Robot]], tmp_path: Path) -> None:
    path, _ = capture
    missing_key = run_vstig("why", str(path))
    assert missing_key.returncode == 2 and "--key" in missing_key.stderr
    junk = tmp_path / "junk.cap"
    junk.write_text("# vstig serial capture v1\nnot a line\n")
    broken = run_vstig("why", str(junk), "--key", "1")
    assert broken.returncode == 1 and "junk.cap:2" in broken.stderr and "Traceback" not in broken.stderr
    unknown = run_vstig("why", str(path), "--key", "1", "--robot", "nobody")
    assert unknown.returncode == 0 and "no such sender" in unknown.stderr
    assert json.loads(run_vstig("why", str(path), "--key", "1", "--robot", "nobody", "--json").stdout)[
        "senders"][0]["cause"] == "unheard"
    recorded_twice = run_vstig("bridge", "serial:/dev/null", "--robot-id", "1", "--record", str(path))
    assert recorded_twice.returncode == 2 and "--overwrite" in recorded_twice.stderr
    assert path.stat().st_size > 0


def test_a_recording_to_a_symlink_is_refused_and_mcap_keeps_the_sends_apart(tmp_path: Path) -> None:
    """A bridge of a pty radio and a python-can virtual bus (two media: .mcap) records what it sent apart from what
    it heard; a symbolic link is never written through, even with --overwrite."""
    link = tmp_path / "link.mcap"
    link.symlink_to(tmp_path / "elsewhere.mcap")
    refused = run_vstig("bridge", "serial:/dev/null", "--robot-id", "1", "--record", str(link), "--overwrite")
    assert refused.returncode == 2 and "symbolic link" in refused.stderr
    assert not (tmp_path / "elsewhere.mcap").exists()
    robot = Robot()
    path = tmp_path / "mixed.mcap"
    bridge = start_vstig("bridge", robot.spec, "can:virtual:why", "--robot-id", "200", "--record", str(path))
    try:
        wait_for(lambda: has_open(bridge.pid, robot.peer.path), 30)
        time.sleep(0.3)
        robot.send(Op.PUT, 9, 5, 3, 4)
        wait_for(lambda: any(m.key == 9 for m in robot.read()), 10, step=lambda: time.sleep(0.05))
    finally:
        _, err = stop(bridge)
        robot.peer.close()
    assert "units in" in err, err
    answer = _why(path, "--key", "9")
    assert answer["newest"]["ts"] == 3 and answer["newest"]["link"] == robot.name
    assert {(hop["link"], hop["sent"]) for hop in answer["path"]} >= {(robot.name, False), ("why", True)}, answer
