"""A `vstig bridge --swarm-key` process with two mavlink: links that require tags (SPEC.md 10.5, 10.6), and
pymavlink as the peer on both: tagged TUNNELs (payload_type 46450) in, tagged TUNNELs out.

Link A (udpin, signed with the MAVLink link key, auth=require) hears drone 9/1 carrying honest robot 5, who holds
only its own key, and the attackers, each on frames the link key signs (an insider's radio: MAVLink signing proves
the hop, not the writer): an outsider's untagged write, robot 6 writing under robot 5's id with its own key, and
robot 5's entry with its value changed on the way. Link B (udpout, auth=require) is a pymavlink ground station.
Each attack is refused and counted on A; every honest write reaches B in a tagged TUNNEL with robot 5's own tag.
"""

from __future__ import annotations

import hashlib
import os
import socket
import time
from pathlib import Path
from typing import Any

from peers import start_vstig, stop, wait_for

os.environ["MAVLINK20"] = "1"  # mavutil's connections speak MAVLink 2 (1 unless told): signing needs it
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mav2
from test_isolation import _counters
from test_mavlink_swarm import _Sink, free_udp_port, key_file

from vstig_hw.auth import SwarmKeys, Tagged, decode_record, encode_record, entry_tag, robot_key
from vstig_hw.framing.mavlink import PAYLOAD_TYPE, PAYLOAD_TYPE_TAGGED
from vstig_hw.wire import Message, Op, encode

MASTER = bytes(range(0x40, 0x60))
LINK_KEY = hashlib.sha256(b"lab swarm").digest()  # key_file's passphrase
HONEST_KEYS = range(10, 40)


def own(robot: int, msg: Message) -> Tagged:
    """`msg` tagged by robot `robot`, holding only its own key."""
    return Tagged(msg, 0, entry_tag(robot_key(MASTER, robot), 0, msg, 0))


def tunnel(drone: Any, data: bytes, payload_type: int = PAYLOAD_TYPE_TAGGED) -> bytes:
    """A TUNNEL as pymavlink packs it (signed with the drone's link key)."""
    return bytes(mav2.MAVLink_tunnel_message(0, 0, payload_type, len(data), list(data) + [0] * (128 - len(data)))
                 .pack(drone))


def test_forged_writes_refused_on_a_mavlink_link_and_honest_ones_relayed_with_their_tags(tmp_path: Path) -> None:
    swarm_key = tmp_path / "swarm.master"
    swarm_key.write_text(MASTER.hex() + "\n", encoding="ascii")
    swarm_key.chmod(0o600)
    port_a, port_b = free_udp_port(), free_udp_port()
    station: Any = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port_b}", source_system=255, source_component=190,
                                              dialect="common")
    bridge = start_vstig("bridge", f"mavlink:udpin:127.0.0.1:{port_a}?key={key_file(tmp_path)}&auth=require",
                         f"mavlink:udpout:127.0.0.1:{port_b}?auth=require", "--robot-id", "3",
                         "--swarm-key", str(swarm_key), "--tick", "0.02", "--no-refresh")
    drone = mav2.MAVLink(_Sink(), srcSystem=9, srcComponent=1)
    drone.signing.secret_key, drone.signing.sign_outgoing = LINK_KEY, True
    radio = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    heard: list[Any] = []

    def send(records: list[Tagged]) -> None:
        for i in range(0, len(records), 6):
            radio.sendto(tunnel(drone, b"".join(map(encode_record, records[i:i + 6]))), ("127.0.0.1", port_a))

    def listen() -> None:
        while (msg := station.recv_match(type="TUNNEL", blocking=False)) is not None:
            heard.append(msg)

    def records() -> list[Tagged]:
        return [decode_record(data[i:i + 20]) for m in heard if m.payload_type == PAYLOAD_TYPE_TAGGED
                for data in [bytes(m.payload[:m.payload_length])] for i in range(0, len(data), 20)]

    first = own(5, Message(Op.PUT, 1, 1000, 3, 5))
    try:
        wait_for(lambda: any(r.message.key == 1 for r in records()), 30,
                 step=lambda: (send([first]), listen(), time.sleep(0.1)))
        outsider = encode(Message(Op.PUT, 2, 666, 9, 99))
        radio.sendto(tunnel(drone, outsider, PAYLOAD_TYPE), ("127.0.0.1", port_a))  # untagged: no key
        send([own(6, Message(Op.PUT, 3, 666, 9, 5))])  # robot 6 claims robot 5's id, tags with its own key
        send([Tagged(Message(Op.PUT, 1, 1001, 4, 5), 0, first.tag)])  # robot 5's entry, its value changed
        honest = [own(5, Message(Op.PUT, key, key, 1, 5)) for key in HONEST_KEYS]
        send(honest)
        wait_for(lambda: {r.message.key for r in records()} >= set(HONEST_KEYS), 30,
                 step=lambda: (listen(), time.sleep(0.05)))
        time.sleep(0.3)
        listen()
    finally:
        _out, err = stop(bridge)
        radio.close()
        station.close()
    assert bridge.returncode == 0, err
    relayed = records()
    keys = SwarmKeys(MASTER)
    assert all(keys.verify(record) for record in relayed), err  # every entry on B proven by its writer
    assert set(honest) <= set(relayed), err  # robot 5's writes, each with its own tag, as it sent them
    assert {m.payload_type for m in heard} == {PAYLOAD_TYPE_TAGGED}, err  # B requires tags: nothing untagged
    assert not {r.message.key for r in relayed} & {2, 3} and (1, 1001) not in {r.message[:2] for r in relayed}, err
    counted = _counters(err, f"mavlink-127.0.0.1:{port_a}")
    assert (counted["drop_untagged"], counted["drop_bad_tag"]) == (1, 2), counted
    assert "drop_signature" not in counted and "drop_unsigned" not in counted, counted  # the hop checked out
    assert "refusing untagged writes claiming robot 99" in err, err
    assert "refusing writes whose tag does not check out claiming robot 5" in err, err
