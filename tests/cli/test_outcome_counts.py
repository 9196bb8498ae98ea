"""`bridge` and `sniff` report the engine's receive outcomes (SPEC section 4), on a pty radio."""

from __future__ import annotations

import json
import threading
from pathlib import Path

from peers import PtyPeer, start_vstig, stop, wait_for

from vstig_hw import Message, Op
from vstig_hw.framing import make_serial_framing

# One message per outcome, in this order, for key 1 (and 2, 3) of a robot that starts empty.
ONE_OF_EACH = [
    Message(Op.PUT, 1, 10, 2, 5),  # stored
    Message(Op.PUT, 1, 10, 1, 5),  # stale: older than ts 2
    Message(Op.PUT, 1, 99, 2, 5),  # same: same ts, same robot
    Message(Op.PUT, 1, 30, 2, 7),  # conflict: same ts, other robot
    Message(Op.GET, 1, 0, 1, 8),  # answered: a GET older than ours
    Message(Op.GET, 2, 0, 0, 8),  # unknown: an empty GET for a key nobody holds
    Message(Op.PUT, 3, 1, 0, 8),  # invalid: a PUT with the reserved timestamp 0
]
SENTINEL = Message(Op.PUT, 50, 1, 1, 9)  # stored; heard last, so everything before it was heard


def _engine_line(stderr: str) -> dict[str, int]:
    (line,) = [line for line in stderr.splitlines() if line.startswith("engine: ")]
    return {name: int(n) for name, n in (item.split("=") for item in line.removeprefix("engine: ").split())}


def _expected(stored: int) -> dict[str, int]:
    return {"stored": stored, "answered": 1, "stale": 1, "same": 1, "conflict": 1, "unknown": 1, "invalid": 1}


def test_bridge_reports_each_engine_outcome_in_its_final_counters() -> None:
    radio = PtyPeer()
    framing = make_serial_framing("cobs8")
    bridge = start_vstig("bridge", f"serial:{radio.path}", "--robot-id", "200")
    try:
        assert bridge.stderr is not None
        assert "bridging" in bridge.stderr.readline()  # printed once the port is open
        radio.write(b"".join(unit for msg in [*ONE_OF_EACH, SENTINEL] for unit in framing.encode(msg)))
        heard: list[Message] = []
        wait_for(lambda: SENTINEL in heard, 30, step=lambda: heard.extend(framing.feed(radio.read(0.05))))
    finally:
        _out, err = stop(bridge)
        radio.close()
    assert bridge.returncode == 0, err
    assert _engine_line(err) == _expected(stored=2)


def test_sniff_reports_what_each_message_would_do_to_a_robot() -> None:
    radio = PtyPeer()
    framing = make_serial_framing("cobs8")
    sniffer = start_vstig("sniff", f"serial:{radio.path}", "--jsonl")
    rows: list[dict[str, object]] = []

    def pump() -> None:
        assert sniffer.stdout is not None
        rows.extend(json.loads(line) for line in sniffer.stdout)

    threading.Thread(target=pump, daemon=True).start()
    probes = iter(range(100, 1000))
    try:
        def probe() -> None:  # a new key each time (each one stored) until the sniffer has the port open
            for unit in framing.encode(Message(Op.PUT, next(probes), 1, 1, 9)):
                radio.write(unit)
            assert radio.read(0.2) == b"", "the sniffer transmitted"

        wait_for(lambda: bool(rows), 30, step=probe)
        radio.write(b"".join(unit for msg in [*ONE_OF_EACH, SENTINEL] for unit in framing.encode(msg)))
        wait_for(lambda: any(r["key"] == SENTINEL.key for r in rows), 30)
    finally:
        _out, err = stop(sniffer)
        radio.close()
    assert sniffer.returncode == 0, err
    probes_heard = sum(1 for r in rows if isinstance(r["key"], int) and r["key"] >= 100)
    assert _engine_line(err) == _expected(stored=probes_heard + 2)


def test_a_device_named_engine_does_not_hide_the_engine_counters(tmp_path: Path) -> None:
    from vstig_cli.running import build_links
    from vstig_hw.links import parse

    (link,) = build_links([parse(f"serial:{tmp_path / 'engine'}")])
    assert link.name == "engine-2"
