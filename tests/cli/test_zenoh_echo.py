"""Zenoh is one broadcast domain: a `vstig bridge` publishes on zenoh what its radio heard, once, and never
publishes back onto zenoh a PUT it heard there (every other gateway heard that sample already)."""

from __future__ import annotations

import threading
import time
from typing import Any

from peers import wait_for
from test_isolation import ZenohBridge, _counters

from vstig_hw import Message, Op, encode
from vstig_hw.framing import make_serial_framing
from vstig_hw.wire import decode_many


def test_a_put_heard_on_zenoh_is_not_published_back_and_a_radios_put_is_published_once() -> None:
    bridge = ZenohBridge()
    radio, out, peer = bridge.radio, bridge.out, bridge.peer
    published: list[list[Message]] = []  # the bridge's samples, as heard by another gateway
    lock = threading.Lock()

    def heard(sample: Any) -> None:
        with lock:
            published.append(decode_many(sample.payload.to_bytes()))

    subscriber = peer.declare_subscriber("vstig/lab/0/200", heard)
    cobs8 = make_serial_framing("cobs8")
    try:
        bridge.await_peer()
        for key in range(100, 150):  # from another gateway on zenoh
            peer.put("vstig/lab/0/301", encode(Message(Op.PUT, key, key, 1, 301)))
            time.sleep(0.01)
        for key in range(200, 250):  # from a robot on the radio
            radio.write(cobs8.encode(Message(Op.PUT, key, key, 1, 7))[0])
            time.sleep(0.01)
        wait_for(lambda: all(k in out.arrived for k in range(100, 150)), 10)
        wait_for(lambda: sum(len(s) for s in published) >= 50, 10)
        time.sleep(1.0)  # anything echoed would have come by now
    finally:
        subscriber.undeclare()
        err = bridge.stop()
    with lock:
        keys = sorted(msg.key for sample in published for msg in sample)
        samples = len(published)
    assert keys == list(range(200, 250))  # the radio's PUTs, each once; none of what zenoh carried came back
    assert samples <= len(keys)  # one sample per relayed message (two, now and then, when they meet in a flush)
    assert _counters(err, "zenoh-lab")["not_echoed"] >= 51, err


def test_echo_and_max_sample_in_a_zenoh_spec() -> None:
    from vstig_hw.links import parse
    from vstig_hw.links.zenoh import ZenohSpec

    default = parse("zenoh:lab")
    assert isinstance(default, ZenohSpec) and default.max_sample == 65536 and not default.echo
    assert default.build(robot_id=5).one_domain
    spec = parse("zenoh:lab?max_sample=1024&echo=1")
    assert isinstance(spec, ZenohSpec) and spec.max_sample == 1024 and spec.echo
    link = spec.build(robot_id=5)
    assert not link.one_domain and link.transport.max_sample == 1024  # type: ignore[attr-defined]
    for bad, words in (("max_sample=4", "max_sample=4 is outside 8.."), ("echo=2", "echo")):
        try:
            parse(f"zenoh:lab?{bad}")
        except ValueError as error:
            assert words in str(error)
        else:
            raise AssertionError(f"{bad} was accepted")
