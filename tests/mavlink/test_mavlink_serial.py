"""A mavlink:serial: link on a real pty, a telemetry radio's UART: pymavlink on the radio's side decodes what it
sends, paced to the radio's air rate, and what pymavlink sends it arrives a few bytes at a time."""

from __future__ import annotations

import time

from peers import PtyPeer
from pymavlink.dialects.v20 import common as mav2

from vstig_hw.links import parse
from vstig_hw.transports.mavlink import AIR_SHARE
from vstig_hw.wire import Message, Op


class _Sink:
    def write(self, data: bytes) -> None:
        pass


def test_a_radio_link_paces_to_its_air_rate_and_reads_a_byte_stream() -> None:
    radio = PtyPeer()
    air_rate = 64000
    link = parse(f"mavlink:serial:{radio.path}?air_rate={air_rate}&sysid=5").build()
    link.open()
    parser = mav2.MAVLink(_Sink())
    heard: list[object] = []
    try:
        batches = [[Message(Op.PUT, b * 16 + i, i, 1, 5) for i in range(16)] for b in range(40)]
        started = time.monotonic()
        for batch in batches:
            link.send_many(batch)  # a blocking write: waits for room in the air budget
        elapsed = time.monotonic() - started
        deadline = time.monotonic() + 2
        while len([m for m in heard if m.get_type() == "TUNNEL"]) < 40 and time.monotonic() < deadline:  # type: ignore[attr-defined]
            heard += parser.parse_buffer(radio.read(0.1)) or []
        # what pymavlink sends, cut into 5-byte runs as a UART may deliver them
        them = mav2.MAVLink(_Sink(), srcSystem=9, srcComponent=1)
        data = bytes(Message(Op.PUT, 9, 99, 1, 9)[0].to_bytes(2, "big") + b"\x00\x63\x00\x01\x00\x09")
        wire = bytes(mav2.MAVLink_tunnel_message(0, 0, 0xB571, 8, list(data) + [0] * 120).pack(them))
        for i in range(0, len(wire), 5):
            radio.write(wire[i:i + 5])
        got = []
        deadline = time.monotonic() + 3
        while not got and time.monotonic() < deadline:
            got = link.receive(0.1)
    finally:
        link.close()
        radio.close()
    tunnels = [m for m in heard if m.get_type() == "TUNNEL"]  # type: ignore[attr-defined]
    assert len(tunnels) == 40 and {m.get_srcSystem() for m in tunnels} == {5}  # type: ignore[attr-defined]
    sent = sum(len(m.get_msgbuf()) for m in tunnels)  # type: ignore[attr-defined]
    budget = air_rate * AIR_SHARE / 8
    # The bucket starts full (a quarter second of air); the rest goes at the budget's rate, not the UART's.
    assert elapsed >= (sent - budget / 4) / budget * 0.9, (elapsed, sent)
    assert elapsed < sent / budget * 1.5, (elapsed, sent)
    assert [h.message for h in got] == [Message(Op.PUT, 9, 99, 1, 9)] and got[0].sender == 9 << 8 | 1
