"""A stop delivers or counts (issue 38, item 1): every message a transport handed the gateway is, at a stop,
handled (`in`) or counted (`dropped_at_stop`), never lost in between.

A bridge on two real ptys (pyserial) is flooded from both far ends with cobs8 frames (12 bytes each) and
closed at a random moment (hypothesis picks it, and the mode); then on every link, the complete frames the
device read (`rx_bytes // 12`: a read may end inside a frame) are exactly `in + dropped_at_stop`.
"""

from __future__ import annotations

import time

from flooded_pty import FRAME, FloodedPty
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vstig_hw.gateway import Mode, Node
from vstig_hw.links import parse


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(after=st.floats(0.0, 0.25), mode=st.sampled_from([Mode.RAW, Mode.ENGINE]), budget=st.sampled_from([None, 8]))
def test_a_loaded_bridge_stopped_at_any_moment_handles_or_counts_every_frame_it_read(after: float, mode: Mode,
                                                                                  budget: int | None) -> None:
    radios = [FloodedPty(7), FloodedPty(8)]
    node = Node([parse(f"serial:{radio.path}?framing=cobs8").build(f"radio{i}") for i, radio in enumerate(radios)],
                200, mode=mode, budget=budget)
    try:
        node.open()
        time.sleep(after)
        node.close(drain=0.1)  # from another thread, while the loop runs: it stops it, then closes
        assert node.wait_closed(0)
    finally:
        for radio in radios:
            radio.stop()
            radio.close()
    for link in node.links:
        counters = link.stats()
        read = counters["rx_bytes"] // FRAME
        assert read == counters["in"] + counters["dropped_at_stop"], (link.name, dict(counters))
    assert sum(link.stats()["in"] for link in node.links) > 0 or after < 0.05
