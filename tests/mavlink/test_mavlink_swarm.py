"""`vstig bridge` processes on mavlink: links, with real MAVLink peers on loopback.

MAVProxy routes between two gateways and a pymavlink ground station that keeps its own traffic flowing
(HEARTBEATs, a parameter request) while the gateways' robots converge, signed and unsigned; and a gateway whose
udpin link is signed takes an honest drone's TUNNELs while forged, replayed, unsigned, truncated, MAVLink 1,
other payload_type and noise datagrams, and a flood, are each dropped and counted, and its other link (a robot
on a pty radio) keeps its pace.
"""

from __future__ import annotations

import hashlib
import os
import socket
import struct
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from peers import start_vstig, stop, wait_for

os.environ["MAVLINK20"] = "1"  # mavutil's connections speak MAVLink 2 (1 unless told): signing needs it
from pymavlink import mavutil
from pymavlink.dialects.v10 import common as mav1
from pymavlink.dialects.v20 import common as mav2
from robots import PtyRobot
from test_isolation import _counters

from vstig_hw.framing.mavlink import PAYLOAD_TYPE
from vstig_hw.wire import Message, Op

MAVPROXY = Path(sys.executable).with_name("mavproxy.py")
PASSPHRASE = "lab swarm"
KEY = hashlib.sha256(PASSPHRASE.encode()).digest()


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def key_file(tmp_path: Path) -> str:
    path = tmp_path / "swarm.key"
    path.write_text(PASSPHRASE + "\n")
    os.chmod(path, 0o600)
    return str(path)


@pytest.fixture
def mavproxy(tmp_path: Path) -> Iterator[tuple[int, int, int]]:
    """MAVProxy as a lab runs it: the vehicle side on its master (udpin), two outputs (udpout); no terminal."""
    master, out_gateway, out_station = free_udp_port(), free_udp_port(), free_udp_port()
    process = subprocess.Popen(
        [str(MAVPROXY), f"--master=udpin:127.0.0.1:{master}", f"--out=udpout:127.0.0.1:{out_gateway}",
         f"--out=udpout:127.0.0.1:{out_station}", "--daemon", "--non-interactive", "--nowait",
         "--default-modules=", f"--state-basedir={tmp_path}"],
        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        yield master, out_gateway, out_station
    finally:
        stop(process)


class GroundStation:
    """A pymavlink ground station: HEARTBEATs twice a second and a PARAM_REQUEST_LIST, and what it hears."""

    def __init__(self, port: int, key: bytes | None) -> None:
        self.conn: Any = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255,
                                                    source_component=190, dialect="common")
        if key is not None:  # it checks what it hears; it sends unsigned, as a station the lab did not set up
            self.conn.setup_signing(key, sign_outgoing=False)
        self.heard: list[Any] = []
        self._beat_at = 0.0
        self._asked = False

    def step(self) -> None:
        now = time.monotonic()
        if now >= self._beat_at:
            self._beat_at = now + 0.5
            self.conn.mav.heartbeat_send(mav2.MAV_TYPE_GCS, mav2.MAV_AUTOPILOT_INVALID, 0, 0, mav2.MAV_STATE_ACTIVE)
            if self._asked or self.heard:
                self.conn.mav.param_request_list_send(1, 191)
                self._asked = True
        while (msg := self.conn.recv_match(blocking=False)) is not None:
            self.heard.append(msg)

    def messages(self) -> list[Message]:
        return [Message(Op(w[0] >> 15), w[0] & 0x7FFF, *w[1:]) for m in self.heard if m.get_type() == "TUNNEL"
                for w in struct.iter_unpack(">HHHH", bytes(m.payload[:m.payload_length]))]


@pytest.mark.parametrize("signed", [False, True], ids=["unsigned", "signed"])
def test_two_gateways_converge_through_mavproxy_beside_a_ground_station(
        mavproxy: tuple[int, int, int], tmp_path: Path, signed: bool) -> None:
    master, out_gateway, out_station = mavproxy
    key = f"?key={key_file(tmp_path)}" if signed else ""
    robots = [PtyRobot(10), PtyRobot(20)]
    for robot in robots:
        robot.put(1, robot.id)
    bridges = [start_vstig("bridge", f"mavlink:udpout:127.0.0.1:{master}{key}", robots[0].spec, "--robot-id", "1",
                           "--larger-value-wins", "--tick", "0.05"),
               start_vstig("bridge", f"mavlink:udpin:127.0.0.1:{out_gateway}{key}", robots[1].spec, "--robot-id",
                           "2", "--larger-value-wins", "--tick", "0.05")]
    station = GroundStation(out_station, KEY if signed else None)
    try:
        # converged, and the station heard the gateway announce itself (a HEARTBEAT a second) and relay the write
        wait_for(lambda: all(r.value(1) == 20 for r in robots) and len(station.heard) > 20
                 and any(m.get_type() == "HEARTBEAT" and m.get_srcComponent() == 191 for m in station.heard)
                 and Message(Op.PUT, 1, 20, 1, 20) in station.messages(), 40,
                 step=lambda: ([r.step() for r in robots], station.step(), time.sleep(0.05)))
    finally:
        errs = [stop(bridge)[1] for bridge in bridges]
        for robot in robots:
            robot.close()
    assert all(bridge.returncode == 0 for bridge in bridges), errs
    beats = [m for m in station.heard if m.get_type() == "HEARTBEAT" and m.get_srcComponent() == 191]
    assert beats and {m.get_srcSystem() for m in beats} == {1}  # MAVProxy passes the master's side to outputs
    assert {(m.type, m.autopilot) for m in beats} == {(mav2.MAV_TYPE_ONBOARD_CONTROLLER, mav2.MAV_AUTOPILOT_INVALID)}
    tunnels = [m for m in station.heard if m.get_type() == "TUNNEL"]
    assert tunnels and {m.payload_type for m in tunnels} == {PAYLOAD_TYPE}
    assert all(m.get_signed() == signed for m in tunnels + beats)  # pymavlink checked every signature
    assert Message(Op.PUT, 1, 20, 1, 20) in station.messages()  # robot 20's value, as gateway 1 relays it
    first = _counters(errs[0], f"mavlink-127.0.0.1:{master}")
    # The station's HEARTBEATs and parameter requests reach the master side: taken by nobody, counted.
    assert first.get("drop_unsigned" if signed else "drop_other_message", 0) >= 2, first
    assert first["heartbeats"] >= 1 and first["in"] > 0, first


def _tunnel(mav: Any, messages: list[Message], payload_type: int = PAYLOAD_TYPE) -> bytes:
    data = b"".join(struct.pack(">HHHH", *m) for m in messages)
    return bytes(mav2.MAVLink_tunnel_message(0, 0, payload_type, len(data),
                                             list(data) + [0] * (128 - len(data))).pack(mav))


class _Sink:
    def write(self, data: bytes) -> None:
        pass


def _signer(sysid: int, key: bytes | None, stamp: int | None = None) -> Any:
    mav = mav2.MAVLink(_Sink(), srcSystem=sysid, srcComponent=1)
    if key is not None:
        mav.signing.secret_key, mav.signing.sign_outgoing = key, True
        if stamp is not None:
            mav.signing.timestamp = stamp
    return mav


def test_hostile_input_is_dropped_and_counted_and_the_other_link_keeps_its_pace(tmp_path: Path) -> None:
    port = free_udp_port()
    robot = PtyRobot(30, watch=(5, 6, 7))
    bridge = start_vstig("bridge", f"mavlink:udpin:127.0.0.1:{port}?key={key_file(tmp_path)}", robot.spec,
                         "--robot-id", "3", "--tick", "0.05")
    drone: Any = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=9, source_component=1,
                                            dialect="common")
    drone.setup_signing(KEY, sign_outgoing=True)
    attacker = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    to = ("127.0.0.1", port)
    honest = _signer(9, KEY)
    good = _tunnel(honest, [Message(Op.PUT, 5, 99, 1, 9)])
    try:
        wait_for(lambda: robot.value(5) == 99, 30,
                 step=lambda: (attacker.sendto(good, to) if robot.value(5) is None else None, robot.step(),
                               time.sleep(0.1)))
        v1 = mav1.MAVLink(_Sink(), srcSystem=9, srcComponent=1)
        for datagram in (
            good,  # a replay: the same timestamp again
            _tunnel(_signer(9, hashlib.sha256(b"guess").digest()), [Message(Op.PUT, 6, 1, 1, 66)]),  # forged
            _tunnel(_signer(9, None), [Message(Op.PUT, 6, 2, 1, 66)]),  # unsigned
            _tunnel(honest, [Message(Op.PUT, 6, 3, 1, 66)])[:30],  # truncated
            bytes(mav1.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3).pack(v1)),  # MAVLink 1
            _tunnel(honest, [Message(Op.PUT, 6, 4, 1, 66)], payload_type=PAYLOAD_TYPE - 1),  # not ours
            b"\x00noise\x00",
        ):
            attacker.sendto(datagram, to)
        # A flood of forged TUNNELs while the robot on the pty puts a new value: the drone hears it in time.
        forger = _signer(9, hashlib.sha256(b"flood").digest())
        flood = [_tunnel(forger, [Message(Op.PUT, 6, i, 1, 66)] * 16) for i in range(2000)]
        robot.put(7, 77)
        started = time.monotonic()
        heard_at: list[float] = []

        def step() -> None:
            for datagram in flood[:200]:
                attacker.sendto(datagram, to)
            del flood[:200]
            robot.step()
            while (msg := drone.recv_match(type="TUNNEL", blocking=False)) is not None:
                carried = bytes(msg.payload[:msg.payload_length])
                if any(w[0] & 0x7FFF == 7 and w[1] == 77 for w in struct.iter_unpack(">HHHH", carried)):  # key 7 = 77
                    heard_at.append(time.monotonic())
            drone.mav.heartbeat_send(mav2.MAV_TYPE_QUADROTOR, mav2.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 4)
            time.sleep(0.02)

        wait_for(lambda: bool(heard_at) and not flood, 30, step=step)
    finally:
        _out, err = stop(bridge)
        robot.close()
        attacker.close()
    assert bridge.returncode == 0, err
    assert heard_at[0] - started < 3.0, heard_at[0] - started
    assert robot.value(6) is None  # nothing the attacker sent was taken
    counts = _counters(err, f"mavlink-127.0.0.1:{port}")
    assert counts["drop_replay"] >= 1 and counts["drop_unsigned"] >= 1 and counts["drop_truncated"] == 1, counts
    assert counts["drop_mavlink1"] == 1 and counts["drop_other_payload_type"] == 1 and counts["drop_noise"] == 1, counts
    assert counts["drop_signature"] >= 2001, counts  # the forged frame and the flood, each counted
    assert "drop_write_error" not in counts, counts

