"""`vstig sniff --foxglove`, watched by a viewer that is not ours: Foxglove's official WebSocket client.

tests/live/foxglove_client.cjs runs `@foxglove/ws-protocol` under Node (installed from npm by `make test`
into tests/live/node_modules), offers the subprotocol today's Foxglove app offers (`foxglove.sdk.v1`),
subscribes to every channel advertised and decodes each message with the schema advertised for it
(Foxglove's own ROS 2 CDR decoder, or JSON). The sniffer hears two CAN robots on an slcan adapter
(python-can's real slcan driver, on a pty) and a cobs8 robot on a pty radio.
"""

from __future__ import annotations

import json
import os
import queue
import re
import shutil
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from peers import PtyPeer, SlcanAdapter, has_open, run_vstig, start_vstig, stop, wait_for
from robots import PtyRobot, Robot

from vstig_hw.capture.rosbag import MSGDEF, TYPE_NAME, topic_for
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.wire import Message, Op

LIVE = Path(__file__).resolve().parents[1] / "live"
CLIENT = LIVE / "foxglove_client.cjs"
_URL = re.compile(r"live view: (ws://\S+)")


def _node() -> str:
    """Node, with the npm packages installed; skip (fail under VSTIG_REQUIRE_PEERS=1) without them."""
    node = shutil.which("node")
    reason = ("node is missing (tests/sysdeps.sh installs it)" if node is None else
              "tests/live/node_modules is missing (`make test` runs npm install there)"
              if not (LIVE / "node_modules" / "@foxglove" / "ws-protocol").is_dir() else None)
    if reason:
        if os.environ.get("VSTIG_REQUIRE_PEERS") == "1":
            pytest.fail(f"VSTIG_REQUIRE_PEERS=1 but {reason}")
        pytest.skip(reason)
    assert node is not None
    return node


class Lines:
    """A process's output stream read line by line in a thread."""

    def __init__(self, stream: Any) -> None:
        self.lines: list[str] = []
        self._thread = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self._thread.start()

    def _read(self, stream: Any) -> None:
        for line in stream:
            self.lines.append(line)

    def join(self) -> None:
        self._thread.join(timeout=20)

    def first(self, pattern: re.Pattern[str], deadline: float = 30) -> re.Match[str]:
        def match() -> re.Match[str] | None:
            return next((m for line in list(self.lines) if (m := pattern.search(line))), None)

        try:
            wait_for(lambda: match() is not None, deadline)
        except AssertionError:
            raise AssertionError(f"no {pattern.pattern!r} in {self.lines}") from None
        found = match()
        assert found is not None
        return found


class Viewer:
    """The Node client: its JSON lines as events."""

    def __init__(self, url: str, *protocols: str, stall: bool = False) -> None:
        self.process = subprocess.Popen([_node(), str(CLIENT), url, *protocols], stdin=subprocess.PIPE,
                                        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                        env={**os.environ, "STALL": "1" if stall else "0"})
        self.events: queue.Queue[dict[str, Any]] = queue.Queue()
        self.seen: list[dict[str, Any]] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.events.put(json.loads(line))

    def take(self) -> list[dict[str, Any]]:
        while True:
            try:
                self.seen.append(self.events.get_nowait())
            except queue.Empty:
                return self.seen

    def messages(self, topic: str) -> list[dict[str, Any]]:
        return [e for e in self.take() if e["event"] == "message" and e["topic"] == topic]

    def until(self, done: Callable[[], bool], deadline: float = 30, step: Callable[[], None] | None = None) -> None:
        try:
            wait_for(lambda: bool(self.take()) and done(), deadline, step)
        except AssertionError:
            raise AssertionError(f"the viewer saw {self.take()[-5:]}; stderr {self.stderr_now()}") from None

    def stderr_now(self) -> str:
        return "" if self.process.poll() is None else (self.process.stderr.read() if self.process.stderr else "")

    def leave(self) -> int:
        assert self.process.stdin is not None
        self.process.stdin.close()
        return self.process.wait(timeout=10)


class SharedBusRobot(Robot):
    """A robot on the CAN bus behind the slcan adapter: what it sends, the sniffer and the other robots hear."""

    def __init__(self, robot_id: int, adapter: SlcanAdapter, bus: list[tuple[int, Message]]) -> None:
        super().__init__(robot_id)
        self.adapter, self.bus = adapter, bus
        self.framing = CanFraming(CanIdScheme(), sender=robot_id)
        self._read = 0

    def _heard(self) -> list[Message]:
        new, self._read = self.bus[self._read:], len(self.bus)
        return [msg for sender, msg in new if sender != self.id]

    def _send(self, messages: list[Message]) -> None:
        for msg in messages:
            self.bus.append((self.id, msg))
            for frame in self.framing.encode(msg):
                self.adapter.inject(frame)

    def close(self) -> None:
        """The adapter is closed by its owner."""


@pytest.fixture
def swarm() -> Iterator[tuple[SlcanAdapter, list[SharedBusRobot], PtyRobot]]:
    adapter = SlcanAdapter()
    bus: list[tuple[int, Message]] = []
    can_robots = [SharedBusRobot(3, adapter, bus), SharedBusRobot(4, adapter, bus)]
    radio_robot = PtyRobot(9)
    yield adapter, can_robots, radio_robot
    radio_robot.close()
    adapter.close()


def test_foxglove_client_decodes_every_channel_of_a_sniffer(
        swarm: tuple[SlcanAdapter, list[SharedBusRobot], PtyRobot]) -> None:
    adapter, (a, b), radio_robot = swarm
    _node()
    sniffer = start_vstig("sniff", f"can:slcan:{adapter.path}", radio_robot.spec,
                          "--foxglove", "0", "--jsonl")
    assert sniffer.stderr is not None and sniffer.stdout is not None
    err, out = Lines(sniffer.stderr), Lines(sniffer.stdout)
    viewer = None
    try:
        url = err.first(_URL).group(1)
        assert url.startswith("ws://127.0.0.1:")  # loopback unless asked
        viewer = Viewer(url)
        viewer.until(lambda: any(e["event"] == "advertise" for e in viewer.seen)
                     and bool(viewer.messages("/vstig/table")))
        (opened,) = [e for e in viewer.seen if e["event"] == "open"]
        assert opened["protocol"] == "foxglove.sdk.v1"
        (advertised,) = [e["channels"] for e in viewer.seen if e["event"] == "advertise"]
        by_topic = {c["topic"]: c for c in advertised}
        ours = ("/vstig/table", "/vstig/writes", "/vstig/stats", "/vstig/robots")
        links = sorted(t for t in by_topic if t not in ours)
        assert len(links) == 2
        for topic in links:
            assert (by_topic[topic]["schemaName"], by_topic[topic]["encoding"], by_topic[topic]["schemaEncoding"],
                    by_topic[topic]["schema"]) == (TYPE_NAME, "cdr", "ros2msg", MSGDEF)
        for topic in ours:
            assert (by_topic[topic]["encoding"], by_topic[topic]["schemaEncoding"]) == ("json", "jsonschema")

        def step() -> None:
            for robot in (a, b, radio_robot):
                robot.step()
            time.sleep(0.05)

        def rows() -> list[dict[str, Any]]:
            return [json.loads(line) for line in list(out.lines)]

        # Until the sniffer hears both links (their empty GETs), it may not have opened them yet.
        wait_for(lambda: {r["sender"] is None for r in rows()} == {True, False}, 30, step)
        started = time.time()
        a.put(1, 111)
        radio_robot.put(2, 222)

        def spread_done() -> bool:
            return any(m["data"]["key"] == 1 and m["data"]["converged_after"] is not None
                       for m in viewer.messages("/vstig/writes"))

        viewer.until(lambda: spread_done() and _table_row(viewer, 2) is not None and any(  # counters come 10 times
            m["data"]["links"] and m["data"]["engine"].get("stored", 0) >= 2  # a second: wait for those after
            for m in viewer.messages("/vstig/stats")), step=step)       # the writes (the adapter opens at once)
        assert b.value(1) == 111  # robot 4 learnt the write from robot 3 over the bus

        # The sniffer's own rows name the links: the CAN one names senders, the radio does not.
        can_link = next(r["link"] for r in rows() if r["sender"] is not None)
        radio_link = next(r["link"] for r in rows() if r["sender"] is None)
        assert sorted([topic_for(can_link), topic_for(radio_link)]) == links

        can_heard = viewer.messages(topic_for(can_link))
        first_put = next(m for m in can_heard if m["data"]["key"] == 1 and m["data"]["op"] == 0)
        # sender is an int64 (64-bit XBee addresses): Foxglove's decoder gives a BigInt, which the client prints as text
        assert first_put["data"] == {"op": 0, "key": 1, "value": 111, "timestamp": 1, "robot": 3, "sender": "3"}
        assert any(m["data"]["key"] == 1 and m["data"]["sender"] == "4" and m["data"]["timestamp"] == 1
                   for m in can_heard)  # robot 4's relay or GET shows the entry it caught up to
        radio_put = next(m for m in viewer.messages(topic_for(radio_link)) if m["data"]["op"] == 0)
        assert radio_put["data"] == {"op": 0, "key": 2, "value": 222, "timestamp": 1, "robot": 9, "sender": "-1"}
        for message in (first_put, radio_put):  # stamped with the time it was heard
            assert started - 1 < int(message["logTime"]) / 1e9 < time.time()

        assert {k: _table_row(viewer, 1)[k] for k in ("value", "timestamp", "robot")} == \
            {"value": 111, "timestamp": 1, "robot": 3}
        assert {k: _table_row(viewer, 2)[k] for k in ("value", "timestamp", "robot")} == \
            {"value": 222, "timestamp": 1, "robot": 9}

        write = next(m["data"] for m in viewer.messages("/vstig/writes")
                     if m["data"]["key"] == 1 and m["data"]["converged_after"] is not None)
        assert (write["value"], write["timestamp"], write["robot"], write["link"]) == (111, 1, 3, can_link)
        assert (write["senders_total"], write["senders_caught_up"], write["behind"]) == (2, 2, [])
        assert 0 <= write["converged_after"] < 10  # 0: both copies arrived in one read

        stats = viewer.messages("/vstig/stats")[-1]["data"]
        assert stats["links"][can_link]["in"] > 0 and stats["links"][radio_link]["in"] > 0
        assert stats["engine"]["stored"] >= 2  # the listening engine's outcomes

        # The roster: the CAN robots named by their sender field, the radio's by the writer id of its PUTs.
        viewer.until(lambda: {(r["robot"], r["named_by"]) for r in _robots(viewer)} >= {
            (3, "sender"), (4, "sender"), (9, "writer")}, step=step)
        robots = {r["robot"]: r for r in _robots(viewer)}
        assert robots[3]["links"] == [can_link] and robots[9]["links"] == [radio_link]
        assert robots[3]["state"] == "alive" and robots[3]["writes"] >= 1 and robots[4]["gets"] >= 1

        # A viewer leaving touches no link: what the robots send next is still heard.
        assert viewer.leave() == 0
        radio_robot.put(3, 333)
        wait_for(lambda: any('"key": 3' in line and '"value": 333' in line for line in out.lines), 20)
    finally:
        if viewer is not None and viewer.process.poll() is None:
            viewer.process.kill()
        sniffer.terminate()  # as Ctrl-C would
        sniffer.wait(timeout=20)
        err.join()
    assert sniffer.returncode == 0, "".join(err.lines)
    (live,) = [line for line in err.lines if line.startswith("live: ")]
    assert "subscribed=6" in live and "drop_behind" not in live, live


def _robots(viewer: Viewer) -> list[dict[str, Any]]:
    """The rows of the latest /vstig/robots message."""
    sent = viewer.messages("/vstig/robots")
    return sent[-1]["data"]["rows"] if sent else []


def _table_row(viewer: Viewer, key: int) -> dict[str, Any] | None:
    tables = viewer.messages("/vstig/table")
    return next((row for row in tables[-1]["data"]["rows"] if row["key"] == key), None) if tables else None


def test_an_old_only_client_is_refused_at_the_handshake() -> None:
    """foxglove-sdk speaks `foxglove.sdk.v1` only: a client offering just the old name gets HTTP 400."""
    _node()
    radio = PtyPeer()
    sniffer = start_vstig("sniff", f"serial:{radio.path}", "--foxglove", "0", "--jsonl")
    try:
        assert sniffer.stderr is not None
        url = Lines(sniffer.stderr).first(_URL).group(1)
        viewer = Viewer(url, "foxglove.websocket.v1")
        assert viewer.process.wait(timeout=20) == 3
        assert {"event": "error", "status": 400} in viewer.take()
    finally:
        stop(sniffer)
        radio.close()


def test_a_port_in_use_or_a_bad_host_is_one_line_and_exit_1() -> None:
    """Both fail before any link opens (the radio here does not even exist)."""
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        port = holder.getsockname()[1]
        done = run_vstig("sniff", "serial:/dev/vstig-no-such-port", "--foxglove", str(port), "--jsonl")
        assert (done.returncode, done.stdout) == (1, "")
        assert done.stderr == (f"Error: --foxglove 127.0.0.1:{port}: cannot listen: Address already in use "
                               "(os error 98)\n")
    done = run_vstig("sniff", "serial:/dev/vstig-no-such-port", "--foxglove", "no-such-host.invalid:8765",
                     "--jsonl")
    assert (done.returncode, done.stdout, done.stderr.count("\n")) == (1, "", 1), done.stderr
    assert done.stderr.startswith("Error: --foxglove no-such-host.invalid:8765: cannot listen: ")
    done = run_vstig("bridge", "serial:/dev/vstig-no-such-port", "--robot-id", "1", "--foxglove", "host:port")
    assert done.returncode == 2 and "the port must be a number in 0..65535" in done.stderr


def test_a_bind_beyond_loopback_warns() -> None:
    radio = PtyPeer()
    try:
        done = run_vstig("sniff", f"serial:{radio.path}", "--foxglove", "0.0.0.0:0", "--for", "0.5")
        assert done.returncode == 0, done.stderr
        assert "--foxglove: WARNING: the live view listens on ws://0.0.0.0:" in done.stderr
        assert "with no authentication" in done.stderr
        quiet = run_vstig("sniff", f"serial:{radio.path}", "--foxglove", "0", "--for", "0.5")
        assert quiet.returncode == 0 and "WARNING" not in quiet.stderr, quiet.stderr
    finally:
        radio.close()


class RadioBridge:
    """`vstig bridge --foxglove 0` between two pty radios (cobs8): `radio` floods it, `robot` hears the relay."""

    def __init__(self) -> None:
        self.radio, self.robot = PtyPeer(), PtyPeer()
        self.process = start_vstig("bridge", f"serial:{self.radio.path}?framing=cobs8",
                                   f"serial:{self.robot.path}?framing=cobs8", "--robot-id", "200", "--no-refresh",
                                   "--foxglove", "0")
        assert self.process.stderr is not None
        self.err = Lines(self.process.stderr)

    def ready(self) -> None:
        """Until the bridge reads the radio (pyserial flushes the input right after opening)."""
        wait_for(lambda: has_open(self.process.pid, self.radio.path), 30)
        time.sleep(0.3)

    def stop(self) -> str:
        """SIGTERM it, as Ctrl-C would; its `live:` line."""
        self.process.terminate()
        self.process.wait(timeout=20)
        self.err.join()
        self.radio.close()
        self.robot.close()
        assert self.process.returncode == 0, "".join(self.err.lines)
        (live,) = [line for line in self.err.lines if line.startswith("live: ")]
        return live


def test_a_stuck_viewer_never_holds_up_the_gateway() -> None:
    """A viewer that stops reading and one that reads, while a radio floods a bridge: every message is
    relayed, the reading viewer's table counts them all, and the link channel's excess is counted."""
    _node()
    framing = make_serial_framing("cobs8")
    flood = [Message(Op.PUT, 1 + i % 500, i & 0xFFFF, 1 + i // 500, 7) for i in range(N_FLOOD)]
    bridge = RadioBridge()
    viewers: list[Viewer] = []
    try:
        url = bridge.err.first(_URL).group(1)
        stuck, reading = Viewer(url, stall=True), Viewer(url)
        viewers += [stuck, reading]
        stuck.until(lambda: any(e["event"] == "stalled" for e in stuck.seen))
        reading.until(lambda: bool(reading.messages("/vstig/table")))
        bridge.ready()
        decoder = make_serial_framing("cobs8")  # what the bridge relays to the second radio
        keys_relayed: set[int] = set()
        data = b"".join(unit for msg in flood for unit in framing.encode(msg))
        for at in range(0, len(data), 4096):  # ~6,800 messages a second: within the engine's intake, past the
            bridge.radio.write(data[at:at + 4096])  # link channel's 2,000 a second
            keys_relayed.update(m.key for m in decoder.feed(bridge.robot.read(0)))
            time.sleep(0.05)

        def every_key_relayed() -> bool:
            keys_relayed.update(m.key for m in decoder.feed(bridge.robot.read(0.05)))
            return len(keys_relayed) >= 500

        wait_for(every_key_relayed, 60)
        reading.until(lambda: (_table_messages(reading) or 0) >= N_FLOOD, 60)
    finally:
        for viewer in viewers:
            if viewer.process.poll() is None:
                viewer.process.kill()
        live = bridge.stop()
    counts = dict(item.split("=") for item in live.removeprefix("live: ").split())
    assert int(counts.get("throttled", 0)) > 0, live  # the link channel's excess, counted
    assert "drop_behind" not in counts, live


N_FLOOD = 20_000


def _table_messages(viewer: Viewer) -> int | None:
    tables = viewer.messages("/vstig/table")
    return tables[-1]["data"]["messages"] if tables else None


def test_the_gateway_outlives_its_live_view_server() -> None:
    """The live view's server process killed mid-run: the bridge relays on, says so once, counts the rest."""
    framing, decoder = make_serial_framing("cobs8"), make_serial_framing("cobs8")
    bridge = RadioBridge()
    try:
        bridge.err.first(_URL)
        (server,) = Path(f"/proc/{bridge.process.pid}/task/{bridge.process.pid}/children").read_text().split()
        os.kill(int(server), 9)
        bridge.ready()
        heard: list[Message] = []
        for key in range(1, 51):
            bridge.radio.write(b"".join(framing.encode(Message(Op.PUT, key, key, 1, 7))))
            heard += decoder.feed(bridge.robot.read(0.02))

        def relayed() -> bool:
            heard.extend(decoder.feed(bridge.robot.read(0.05)))
            return {m.key for m in heard} >= set(range(1, 51))

        wait_for(relayed, 30)
    finally:
        live = bridge.stop()
    assert sum("its server process ended" in line for line in bridge.err.lines) == 1, bridge.err.lines
    assert "drop_behind=" in live, live


# -- hostile viewers (issue 33, item 4) ------------------------------------------------------------------------
ATTACKER = str(Path(__file__).with_name("ws_attacker.py"))


class Sniffer:
    """`vstig sniff --foxglove 0` on a pty radio robot, its stderr collected; `server` is the live view's process."""

    def __init__(self, *options: str) -> None:
        self.robot = PtyRobot(9)
        self.process = start_vstig("sniff", self.robot.spec, "--foxglove", "0", "--jsonl", *options)
        assert self.process.stderr is not None and self.process.stdout is not None
        self.err, self.out = Lines(self.process.stderr), Lines(self.process.stdout)
        self.url = self.err.first(_URL).group(1)
        self.host, port = self.url.removeprefix("ws://").rsplit(":", 1)
        self.port = int(port)
        (child,) = Path(f"/proc/{self.process.pid}/task/{self.process.pid}/children").read_text().split()
        self.server = int(child)

    def attack(self, mode: str, count: int) -> subprocess.Popen[str]:
        return subprocess.Popen([sys.executable, ATTACKER, mode, self.host, str(self.port), str(count)],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)

    def stop(self) -> tuple[str, str]:
        """SIGTERM, as Ctrl-C would; (all it wrote on stderr, its `live:` counters line)."""
        self.process.terminate()
        self.process.wait(timeout=20)
        self.err.join()
        self.robot.close()
        text = "".join(self.err.lines)
        (live,) = [line for line in self.err.lines if line.startswith("live: ")]
        return text, live


def test_a_viewer_sending_garbage_cannot_write_on_the_gateways_terminal() -> None:
    """Invalid messages quoting newlines, ANSI and OSC sequences: the SDK's lines about them reach stderr escaped,
    a few a second, and the rest are counted (before: every one raw, 347,400 lines in 10 s)."""
    sniffer = Sniffer()
    began = time.monotonic()
    try:
        attacker = sniffer.attack("garbage", 20_000)
        out, _ = attacker.communicate(timeout=120)
        assert out.startswith("sent 40000"), out
    finally:
        text, live = sniffer.stop()
    took = time.monotonic() - began
    assert not re.search(r"[\x00-\x08\x0b-\x1f\x7f]", text), repr(text[:2000])  # no escape, bell or CR at all
    server_lines = [line for line in sniffer.err.lines if line.startswith("live view: ") and "ws://" not in line]
    assert 1 <= len(server_lines) <= 10 + 2 * took + took / 10 + 2, server_lines  # burst, rate, summaries
    assert any("\\x1b[31mRED\\x1b]0;pwned\\x07" in line for line in server_lines), server_lines  # shown, escaped
    assert all(len(line) <= len("live view: ") + 300 + 1 for line in server_lines)
    counts = dict(item.split("=") for item in live.removeprefix("live: ").split())
    assert int(counts["log_dropped"]) >= 1000, live  # what the SDK logged before the viewer left, held back


def test_viewers_beyond_the_cap_are_told_why_and_closed_while_the_others_keep_watching() -> None:
    import websocket

    sniffer = Sniffer("--foxglove-viewers", "2")
    viewers: list[Viewer] = []
    try:
        viewers = [Viewer(sniffer.url), Viewer(sniffer.url)]
        for viewer in viewers:
            viewer.until(lambda v=viewer: bool(v.messages("/vstig/table")))
        extra = websocket.create_connection(sniffer.url, subprotocols=["foxglove.sdk.v1"], timeout=20)
        frames = []
        while not frames or frames[-1][0] != websocket.ABNF.OPCODE_CLOSE:
            frames.append(extra.recv_data(control_frame=True))
        code, reason = int.from_bytes(frames[-1][1][:2], "big"), frames[-1][1][2:].decode()
        assert (code, reason) == (1013, "2 viewers already (--foxglove-viewers 2)")
        extra.close()
        sniffer.robot.put(4, 44)  # the two it took in still watch
        for viewer in viewers:
            viewer.until(lambda v=viewer: _table_row(v, 4) is not None, step=sniffer.robot.step)
        assert viewers[0].leave() == 0  # one leaves: a newcomer is taken in
        newcomer = Viewer(sniffer.url)
        viewers.append(newcomer)
        newcomer.until(lambda: _table_row(newcomer, 4) is not None)
    finally:
        for viewer in viewers:
            if viewer.process.poll() is None:
                viewer.process.kill()
        text, live = sniffer.stop()
    assert "refused a viewer from 127.0.0.1:" in text and "viewers_refused=1" in live, (text, live)


@pytest.mark.slow
def test_five_thousand_viewers_keep_the_server_small() -> None:
    """5,000 connections that subscribe and never read (before: the server process took 1.84 GB)."""
    sniffer = Sniffer()
    peak = 0.0
    try:
        attacker = sniffer.attack("many", 5000)
        assert attacker.stdout is not None
        held = attacker.stdout.readline()
        assert held.startswith("opened 5000"), held
        for _ in range(10):  # the server's queues would fill while the attacker holds its sockets
            sniffer.robot.put(1, int(time.monotonic() * 10) & 0xFFFF)
            time.sleep(0.1)
        fields = dict(line.split(":", 1) for line in Path(f"/proc/{sniffer.server}/status").read_text().splitlines())
        peak = int(fields["VmHWM"].split()[0]) / 1024
        attacker.communicate(timeout=60)
    finally:
        text, live = sniffer.stop()
    assert peak <= 400, f"the live view's server peaked at {peak:.0f} MB"
    counts = dict(item.split("=") for item in live.removeprefix("live: ").split())
    assert int(counts["viewers_refused"]) >= 5000 - 16, live
    assert len(text.splitlines()) < 60, text[-3000:]


def test_a_float_key_holding_nan_reaches_a_strict_json_parser_as_null() -> None:
    """A float16 value 0x7E00 is NaN: /vstig/table carries it as null, which Node's JSON.parse reads (it
    refuses the bare NaN Python's json writes by default)."""
    _node()
    sniffer = Sniffer("--value-type", "float16")
    viewer = None
    try:
        viewer = Viewer(sniffer.url)
        sniffer.robot.put(5, 0x7E00)
        sniffer.robot.put(6, 0x3C00)  # 1.0
        viewer.until(lambda: _table_row(viewer, 5) is not None and _table_row(viewer, 6) is not None,
                     step=sniffer.robot.step)
        assert _table_row(viewer, 5)["value"] is None  # type: ignore[index]
        assert _table_row(viewer, 6)["value"] == 1.0  # type: ignore[index]
        assert not [e for e in viewer.take() if e["event"] == "error"]
    finally:
        if viewer is not None and viewer.process.poll() is None:
            viewer.process.kill()
        sniffer.stop()
