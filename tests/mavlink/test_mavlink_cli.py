"""`vstig record`, `decode`, `replay` and `sniff` on mavlink: links as processes, and the one-line errors a
mavlink: link's user meets (a key file others can read, no sysid, an address not this PC's)."""

from __future__ import annotations

import os
import select
import socket
import time
from pathlib import Path

from peers import run_vstig, start_vstig, stop, wait_for
from test_mavlink_swarm import free_udp_port

from vstig_hw.framing.mavlink import MavlinkFraming
from vstig_hw.wire import Message, Op

DRONE = MavlinkFraming(9, 1)
SENT = [Message(Op.PUT, k, k * 10, 1, 9) for k in range(3)]


def _send_until_heard(port: int, heard: object) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as drone:
        def step() -> None:
            for msg in SENT:
                drone.sendto(DRONE.encode(msg)[0], ("127.0.0.1", port))
            time.sleep(0.2)
        wait_for(heard, 30, step=step)  # type: ignore[arg-type]


def test_record_decode_and_replay_keep_the_sender(tmp_path: Path) -> None:
    port = free_udp_port()
    capture = tmp_path / "drones.cap"
    recorder = start_vstig("record", f"mavlink:udpin:127.0.0.1:{port}", "-o", str(capture))
    try:
        _send_until_heard(port, lambda: capture.exists() and capture.read_text().count(" mavlink rx ") >= 3)
    finally:
        _out, err = stop(recorder)
    assert recorder.returncode == 0, err
    decoded = run_vstig("decode", str(capture), "--sender", str(9 << 8 | 1))
    assert decoded.returncode == 0, decoded.stderr
    for msg in SENT:
        assert f"PUT key={msg.key} value={msg.value} ts=1 robot=9 sender=2305" in decoded.stdout
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as far:
        far.bind(("127.0.0.1", 0))
        replayed = run_vstig("replay", str(capture), "--onto",
                             f"mavlink:udpout:127.0.0.1:{far.getsockname()[1]}?sysid=5")
        assert replayed.returncode == 0, replayed.stderr
        got = []
        while select.select([far], [], [], 0.5)[0]:
            got += MavlinkFraming(255).feed(far.recv(65536))
    # what was heard goes out again under the replaying gateway's own sysid (a heard frame is another's)
    assert set(SENT) <= set(got)


def test_sniff_shows_what_drones_put_and_sends_nothing() -> None:
    port = free_udp_port()
    sniff = start_vstig("sniff", f"mavlink:udpin:127.0.0.1:{port}", "--jsonl", "--for", "6")
    _send_until_heard(port, lambda: sniff.poll() is not None)  # the drone sends until sniff's time is up
    out, err = stop(sniff)
    assert sniff.returncode == 0, err
    assert all(f'"key": {msg.key}' in out for msg in SENT) and '"sender": 2305' in out, out
    assert "heartbeats=" not in err and " tx=" not in err, err  # a sniffer announces nothing


def test_errors_name_what_to_fix(tmp_path: Path) -> None:
    key = tmp_path / "swarm.key"
    key.write_text("lab swarm\n")
    os.chmod(key, 0o644)
    port = free_udp_port()
    shared = run_vstig("bridge", f"mavlink:udpin:127.0.0.1:{port}?key={key}", "--robot-id", "3", "--for", "1")
    assert shared.returncode == 2 and f"chmod 600 {key}" in shared.stderr, shared.stderr
    nobody = run_vstig("bridge", f"mavlink:udpin:127.0.0.1:{port}", "--robot-id", "0", "--for", "1")
    assert nobody.returncode == 2 and "--robot-id 1..255 or sysid=" in nobody.stderr, nobody.stderr
    elsewhere = run_vstig("bridge", "mavlink:udpin:192.0.2.1:14550", "--robot-id", "3", "--for", "1")
    assert elsewhere.returncode == 1 and "udpin:192.0.2.1:14550" in elsewhere.stderr, elsewhere.stderr
    assert "Traceback" not in shared.stderr + nobody.stderr + elsewhere.stderr
    assert "not signed (no key=)" in elsewhere.stderr  # the exposure warning


def test_the_roster_names_each_drone_by_its_sysid_and_compid() -> None:
    port = free_udp_port()
    sniff = start_vstig("sniff", f"mavlink:udpin:127.0.0.1:{port}", "--robots", "--jsonl", "--for", "6")
    drones = [MavlinkFraming(9, 1), MavlinkFraming(12, 191)]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as radio:
        def step() -> None:
            for number, drone in enumerate(drones):
                radio.sendto(drone.encode(Message(Op.PUT, number, 1, 1, 20 + number))[0], ("127.0.0.1", port))
            time.sleep(0.2)
        wait_for(lambda: sniff.poll() is not None, 30, step=step)
    out, err = stop(sniff)
    assert sniff.returncode == 0, err
    for sender in (9 << 8 | 1, 12 << 8 | 191):
        assert f'"robot": {sender}, "sender": {sender}, "named_by": "sender"' in out, out
