"""`vstig` as a subprocess on pty radios: sniff --jsonl, bridge to CAN (slcan), serial captures, demo."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import can
import pytest
from peers import PtyPeer, SlcanAdapter, run_vstig, start_vstig, stop, wait_for

from vstig_hw import Message, Op, Stigmergy, encode
from vstig_hw.framing import make_serial_framing


def _lines(process: object) -> list[str]:
    """Collect a subprocess's stdout lines on a thread, so the test can poll them."""
    lines: list[str] = []

    def pump() -> None:
        for line in process.stdout:  # type: ignore[attr-defined]
            lines.append(line)

    threading.Thread(target=pump, daemon=True).start()
    return lines


def test_sniff_jsonl_on_a_pty_prints_messages_and_never_transmits() -> None:
    radio = PtyPeer()
    framing = make_serial_framing("cobs8")
    sniffer = start_vstig("sniff", f"serial:{radio.path}?framing=cobs8", "--jsonl")
    lines = _lines(sniffer)
    sent = [Message(Op.PUT, 2, 500, 3, 11), Message(Op.GET, 2, 0, 0, 12)]  # a GET a robot would answer
    try:
        def send_and_check() -> None:
            for msg in sent:
                for unit in framing.encode(msg):
                    radio.write(unit)
            assert radio.read(0.3) == b"", "the sniffer transmitted"

        wait_for(lambda: len(lines) >= 2, 30, step=send_and_check)  # resend until the sniffer has the port open
    finally:
        stop(sniffer)
        radio.close()
    rows = [json.loads(line) for line in lines]
    assert {(r["op"], r["key"], r["value"], r["timestamp"], r["robot"]) for r in rows} == {
        ("PUT", 2, 500, 3, 11), ("GET", 2, 0, 0, 12)}
    assert sniffer.returncode == 0


@pytest.mark.slow
def test_bridge_carries_data_between_can_and_a_pty_radio() -> None:
    adapter, radio = SlcanAdapter(), PtyPeer()
    framing = make_serial_framing("cobs8")
    far_robot = Stigmergy(40)
    bridge = start_vstig("bridge", f"can:slcan:{adapter.path}", f"serial:{radio.path}?framing=cobs8",
                         "--robot-id", "200")
    try:
        wait_for(lambda: "O" in adapter.commands, 30)
        put = Message(Op.PUT, 5, 4242, 1, 7)
        adapter.inject(can.Message(arbitration_id=0x607, data=encode(put), is_extended_id=False))

        def radio_robot_listens() -> None:
            for msg in framing.feed(radio.read(0.05)):
                far_robot.receive(msg)

        wait_for(lambda: far_robot.entry(5) is not None, 20, step=radio_robot_listens)
        assert far_robot.entry(5) == (4242, 1, 7)
        far_robot.put(6, 99)  # and the radio robot's own write reaches the CAN bus
        for msg in far_robot.drain():
            for unit in framing.encode(msg):
                radio.write(unit)
        wait_for(lambda: any(f.data[1] == 6 and f.data[3] == 99 for f in adapter.sent), 20)
        frame = next(f for f in adapter.sent if f.data[1] == 6)
        assert frame.arbitration_id == 0x600 | 200 and bytes(frame.data) == encode(Message(Op.PUT, 6, 99, 1, 40))
    finally:
        _out, err = stop(bridge)
        adapter.close()
        radio.close()
    assert bridge.returncode == 0, err
    assert "in=" in err and "out=" in err  # counters printed on shutdown


def test_serial_record_decode_replay_round_trip(tmp_path: Path) -> None:
    capture = tmp_path / "radio.cap"
    radio = PtyPeer()
    framing = make_serial_framing("epuck4")
    messages = [Message(Op.PUT, 9, 100 + i, i + 1, 3) for i in range(4)]
    stream = b"".join(unit for msg in messages for unit in framing.encode(msg))
    recorder = start_vstig("record", f"serial:{radio.path}?framing=epuck4", "-o", str(capture))
    try:
        def open_yet() -> bool:
            radio.write(b"\0")  # idle-line bytes (recorded raw, ignored by framings) until the port is open
            return capture.exists() and " rx " in capture.read_text()

        wait_for(open_yet, 30)
        radio.write(stream)
        wait_for(lambda: bytes.fromhex("".join(line.split()[-1] for line in capture.read_text().splitlines()
                                               if " rx " in line)).endswith(stream), 20)
    finally:
        stop(recorder)
        radio.close()
    assert recorder.returncode == 0

    decoded = run_vstig("decode", str(capture), "--format", "jsonl")
    assert decoded.returncode == 0, decoded.stderr
    rows = [json.loads(line) for line in decoded.stdout.splitlines()]
    assert [(r["key"], r["value"], r["timestamp"]) for r in rows] == [(9, 100 + i, i + 1) for i in range(4)]
    assert all("can_id" not in r and r["op"] == "PUT" for r in rows)

    same, other = PtyPeer(), PtyPeer()
    try:
        done = run_vstig("replay", str(capture), "--onto", f"serial:{same.path}?framing=epuck4", "--speed", "20")
        assert done.returncode == 0, done.stderr
        got = b""
        while stream not in got:
            chunk = same.read(1.0)
            assert chunk, "the replay did not reach the port"
            got += chunk
        done = run_vstig("replay", str(capture), "--onto", f"serial:{other.path}?framing=cobs8", "--speed", "20")
        assert done.returncode == 0, done.stderr
        cobs = make_serial_framing("cobs8")
        heard: list[Message] = []
        while len(heard) < len(messages):
            chunk = other.read(1.0)
            assert chunk, "the translated replay did not reach the port"
            heard += cobs.feed(chunk)
    finally:
        same.close()
        other.close()
    assert heard == messages  # epuck4 fragments re-encoded as cobs8 frames


@pytest.mark.slow
def test_demo_converges() -> None:
    done = run_vstig("demo", "--robots", "12", "--drop", "0.5", "--max-steps", "200", timeout=90)
    assert done.returncode == 0, done.stderr
    assert "converged: all 12 robots hold 12" in done.stdout
    assert "interrupted" not in done.stderr  # nobody stopped it
    for medium in ("can", "cobs8", "epuck4"):
        assert any(line.startswith(medium) for line in done.stdout.splitlines())


def test_demo_that_gives_up_fails_without_saying_interrupted() -> None:
    done = run_vstig("demo", "--robots", "6", "--drop", "0.95", "--step", "0.01", "--max-steps", "1", timeout=60)
    assert done.returncode == 1, done.stderr
    assert "did not converge in 1 step\n" in done.stderr and "interrupted" not in done.stderr, done.stderr


@pytest.mark.slow
def test_demo_stopped_by_ctrl_c_says_interrupted() -> None:
    import signal
    import time

    demo = start_vstig("demo", "--robots", "12", "--drop", "0.95", "--step", "1.0", "--max-steps", "10000")
    time.sleep(4)
    demo.send_signal(signal.SIGINT)
    _out, err = demo.communicate(timeout=60)
    assert demo.returncode == 0 and "interrupted" in err and "Traceback" not in err, err
