"""Signed frames leave a mavlink link in timestamp order (issue 49's replays): a receiver that keeps MAVLink's
replay rule (pymavlink's own, and ours) drops none of them, however the TUNNELs waited for the air budget while
HEARTBEATs went out from the reader thread, on the compiled path and the pure one."""

from __future__ import annotations

import hashlib
import os
import threading
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from peers import PtyPeer, start_vstig, stop, wait_for
from pymavlink.dialects.v20 import common as mav2
from robots import PtyRobot
from test_isolation import _counters
from test_mavlink_swarm import PASSPHRASE, free_udp_port, key_file

from vstig_hw.counters import Counters
from vstig_hw.framing.mavlink import MavlinkFraming, MavlinkStreamReader, Signing
from vstig_hw.gateway.writer import LinkWriter
from vstig_hw.links import parse
from vstig_hw.native import PURE_ENV, native
from vstig_hw.wire import Message, Op

KEY = hashlib.sha256(PASSPHRASE.encode()).digest()
PATHS = ["pure", pytest.param("compiled", marks=pytest.mark.skipif(native is None, reason="no compiled extension"))]


class _Sink:
    def write(self, data: bytes) -> None:
        pass


def _units(link: Any, path: str) -> Any:
    """How the gateway makes a batch's units on `path`: the framing's, or the compiled Encoder's it shares."""
    if path == "pure":
        return link.units_of
    from vstig_hw.gateway.compiled import encoder_for

    encoder = encoder_for(link)
    return lambda batch: [b"".join(encoder.encode_batch(batch))]


@pytest.mark.parametrize("path", PATHS)
def test_held_tunnels_and_heartbeats_reach_signed_receivers_in_timestamp_order(tmp_path: Path, path: str) -> None:
    radio = PtyPeer()
    # 8 kbit/s of air: 500 bytes a second are ours, so a 24-TUNNEL burst waits ~7 s while HEARTBEATs go out
    link = parse(f"mavlink:serial:{radio.path}?air_rate=8000&sysid=5&key={key_file(tmp_path)}").build()
    link.open()
    units_of = _units(link, path)
    writer = LinkWriter(link)
    stop = threading.Event()

    def read() -> None:
        while not stop.is_set():
            link.receive(0.05)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()  # the gateway's reader thread: it sends the HEARTBEATs
    station = mav2.MAVLink(_Sink())
    station.robust_parsing = True  # a refused frame is BAD_DATA, not raised
    station.signing.secret_key, station.signing.sign_outgoing = KEY, False  # checks signatures and replays
    ours = MavlinkFraming(9, signing=Signing(KEY))
    cutter = MavlinkStreamReader(Counters())
    sent = [Message(Op.PUT, key, key + 1, 1, 5) for key in range(24 * 16)]
    tunnels = bad = 0
    got: list[Message] = []
    try:
        for i in range(0, len(sent), 16):
            writer.submit(units_of(sent[i:i + 16]), 16)
            time.sleep(0.15)  # a source's pace: submits meet held units and due HEARTBEATs
        deadline = time.monotonic() + 15
        while len(got) < len(sent) and time.monotonic() < deadline:
            data = radio.read(0.1)
            for msg in station.parse_buffer(data) or []:
                tunnels += msg.get_type() == "TUNNEL"
                bad += msg.get_type() == "BAD_DATA"
            for wire in cutter.feed(data):  # whole frames, each fed as a unit
                got += ours.feed(wire)
    finally:
        stop.set()
        reader.join(2)
        writer.close()
        link.close()
        radio.close()
    assert link.transport.counters["heartbeats"] >= 3  # they did fire during the burst
    assert station.signing.reject_count == 0
    assert (bad, dict(ours.drops)) == (0, {"other_message": ours.drops["other_message"]})
    assert tunnels == 24 and got == sent


@pytest.mark.parametrize("pure", ["0", pytest.param("1", marks=pytest.mark.skipif(native is None, reason="no "
                                                                                   "compiled extension to turn off"))])
def test_signed_udp_bridges_and_clients_drop_no_honest_frame_as_a_replay(tmp_path: Path, pure: str) -> None:
    """The lead's loopback pair: a udpin bridge, a udpout bridge and get/put clients beside it, all signed."""
    env = {**os.environ, PURE_ENV: pure}
    key, port = key_file(tmp_path), free_udp_port()
    robots = [PtyRobot(1, watch=range(1, 9)), PtyRobot(2, watch=range(1, 9))]
    bridges = [start_vstig("bridge", f"mavlink:udpin:127.0.0.1:{port}?key={key}", robots[0].spec, "--robot-id",
                           "200", "--tick", "0.02", env=env),
               start_vstig("bridge", f"mavlink:udpout:127.0.0.1:{port}?sysid=9&key={key}", robots[1].spec,
                           "--robot-id", "9", "--tick", "0.02", env=env)]
    try:
        wait_for(lambda: robots[1].value(1) == 1, 30,
                 step=lambda: (robots[0].put(1, 1) if robots[1].value(1) is None else None,
                               [robot.step() for robot in robots], time.sleep(0.05)))
        for round_ in range(2, 8):  # clients come and go while both robots keep writing
            for robot in robots:
                robot.put(round_, round_ * 10 + robot.id)
            client = f"mavlink:udpout:127.0.0.1:{port}?sysid={10 + round_}&key={key}"
            clients = [start_vstig("put", str(100 + round_), str(round_), "--on", client, "--wait", "2", env=env),
                       start_vstig("get", "1", "--on", client.replace(f"sysid={10 + round_}",
                                                                      f"sysid={20 + round_}"), "--wait", "1",
                                   env=env)]
            deadline = time.monotonic() + 20
            while any(c.poll() is None for c in clients) and time.monotonic() < deadline:
                for robot in robots:
                    robot.step()
                    robot.put(8, int(time.monotonic() * 100) & 0x7FFF)  # a steady stream of TUNNELs both ways
                time.sleep(0.02)
            assert "value=1 " in [stop(c)[0] for c in clients][1] and clients[0].returncode == 0
    finally:
        errs = [stop(bridge)[1] for bridge in bridges]
        for robot in robots:
            robot.close()
    for bridge, err, side in zip(bridges, errs, (port, port), strict=True):
        assert bridge.returncode == 0, err
        counts = _counters(err, f"mavlink-127.0.0.1:{side}")
        assert counts.get("drop_replay", 0) == 0 and counts.get("drop_signature", 0) == 0, counts
        assert counts["in"] > 100 and counts["heartbeats"] >= 5, counts


@pytest.mark.parametrize("path", PATHS)
def test_a_frame_written_after_a_newer_one_is_signed_again_and_the_clock_goes_on_from_it(path: str) -> None:
    clock = [1.8e9]
    framing = MavlinkFraming(5, signing=Signing(KEY, link_id=3, clock=lambda: clock[0]))
    units_of = _units(SimpleNamespace(framing=framing, units_of=framing.encode_batch), path)
    held = units_of([Message(Op.PUT, 1, 1, 1, 5)])[0]
    beat = framing.heartbeat()
    assert framing.in_order(beat) is beat  # in order: as it is, nothing hashed
    again = framing.in_order(held)
    assert again != held and again[:-13] == held[:-13] and again[-13] == 3  # the same frame, the same link id
    later = units_of([Message(Op.PUT, 2, 2, 1, 5)])[0]  # the clock has not moved: the next stamp goes on
    assert framing.in_order(later) is later
    receiver = Signing(KEY)
    assert [receiver.check(wire) for wire in (beat, again, later)] == [None, None, None]
    assert receiver.check(held) == "replay"  # what a receiver would have done with it unsigned again
