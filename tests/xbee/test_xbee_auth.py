"""An XBee link that requires tags (SPEC.md 10.5, 10.6), through emulated modules on ptys: the gateway takes the
compiled data path, refuses a forged record and an untagged write, relays the honest records onto a cobs8 radio,
and sends entries to the XBee robots as tagged batches, as many records a frame as the module's NP holds, from the
outlet itself (the link's writer never handed a unit). Under VSTIG_PURE=1 the Python path is held to the same."""

from __future__ import annotations

import time
from typing import Any

import pytest
from peers import PtyPeer, wait_for
from xbee_network import Host, XBeeNetwork

from vstig_hw.auth import BATCH_MARKER, RECORD_SIZE, SwarmKeys, Tagged, decode_batch, encode_batch
from vstig_hw.framing import make_serial_framing
from vstig_hw.gateway import Node
from vstig_hw.links.assemble import assemble_links
from vstig_hw.native import native
from vstig_hw.wire import Message, Op, encode

MASTER = bytes(range(0x60, 0x80))
GATEWAY, ROBOT = 0x0013A20040000001, 0x0013A20040000100
NP = 61  # the gateway module's: 3 records a tagged batch (0xA1 and 60 bytes)


@pytest.mark.parametrize("api", [1, 2])
def test_an_xbee_link_that_requires_tags_checks_and_sends_them_in_c(api: int) -> None:
    keys = SwarmKeys(MASTER)
    honest = [keys.tag(Message(Op.PUT, key, key * 10, 1, 10), 0) for key in range(1, 6)]
    forged = Tagged(Message(Op.PUT, 6, 60, 1, 10), 0, bytes(8))
    from_radio = keys.tag(Message(Op.PUT, 20, 200, 1, 30), 0)
    cobs8 = make_serial_framing("cobs8")
    radio = PtyPeer()
    handed: list[int] = []
    with XBeeNetwork() as network:
        module = network.module(GATEWAY, api=api, np=NP)
        robot = Host(network.module(ROBOT, api=api))
        links = assemble_links([f"serial:{module.path}?framing=xbee&baud=230400&auth=require&api={api}",
                                f"serial:{radio.path}?framing=cobs8&auth=require"], 200)
        try:
            with Node(links, 200, budget=None, swarm_keys=keys) as node:
                assert node.compiled == (native is not None)  # VSTIG_PURE=1: the Python path, held to the same
                for outlet in node.outlets:
                    submit = outlet.writer.submit
                    outlet.writer.submit = lambda units, count, submit=submit: (handed.append(count),
                                                                                submit(units, count))
                robot.transmit(encode_batch(honest))
                robot.transmit(encode_batch([forged]))
                robot.transmit(encode(Message(Op.PUT, 7, 70, 1, 10)))
                radio.write(cobs8.encode_tagged([from_radio])[0])
                on_radio: list[Tagged | None] = []
                at_robot: list[Tagged] = []
                wait_for(lambda: len(on_radio) >= 5 and any(r.message.key == 20 for r in at_robot), 20,
                         step=lambda: _heard(cobs8, radio, robot, on_radio, at_robot))
                stats = node.stats()[links[0].name]
        finally:
            robot.close()
            radio.close()
    assert handed == [] or native is None  # the Python path hands its writer every unit
    assert (stats["drop_bad_tag"], stats["drop_untagged"]) == (1, 1)
    relayed = {r.message.key for r in on_radio if r is not None and keys.verify(r)}
    assert relayed - {20} == {1, 2, 3, 4, 5}  # (20, the radio's own, is re-broadcast there too)
    assert None not in on_radio and all(keys.verify(r) for r in at_robot)
    batches = [frame[14:] for frame in _transmits(module.from_host, api)]  # after the 14-byte header
    assert batches and all(rf[0] == BATCH_MARKER for rf in batches)  # every Transmit Request a tagged batch
    assert max((len(rf) - 1) // RECORD_SIZE for rf in batches) == 3  # five records: 3 and 2, as NP 61 holds


def _heard(cobs8: Any, radio: PtyPeer, robot: Host, on_radio: list[Tagged | None], at_robot: list[Tagged]) -> None:
    on_radio += [record for _msg, record in cobs8.feed_tagged(radio.read(0.05))]
    at_robot += [record for _source, rf in robot.received() if rf[:1] == bytes((BATCH_MARKER,))
                 for record in decode_batch(rf)]
    time.sleep(0.02)


def _transmits(raw_frames: list[bytes], api: int) -> list[bytes]:
    """The frame data of each Transmit Request (0x10) among frames as they crossed the UART."""
    data = []
    for raw in raw_frames:
        body = bytearray()
        escaped = False
        for byte in raw[1:]:
            if api == 2 and byte == 0x7D:
                escaped = True
                continue
            body.append(byte ^ 0x20 if escaped else byte)
            escaped = False
        frame = bytes(body[2:-1])
        if frame[:1] == b"\x10":
            data.append(frame)
    return data
