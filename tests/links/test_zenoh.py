"""The zenoh link: its pure framing, its spec, its closed-by-default config, and real sessions on loopback."""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path
from typing import Any

import pytest
from waiting import wait_until

from vstig_hw.framing.zenoh import ZenohFraming, ZenohKeySpace, ZenohSample
from vstig_hw.links import Link, parse
from vstig_hw.links.zenoh import EXAMPLES, ZenohSpec, exposure, zenoh_config
from vstig_hw.transports.base import TransportError
from vstig_hw.wire import Message, Op, encode

MESSAGES = [Message(Op.PUT, k, 100 + k, 1, 7) for k in range(5)]


# -- framing ----------------------------------------------------------------------
def test_a_batch_is_one_sample_under_the_gateways_key_and_decodes_back() -> None:
    framing = ZenohFraming(ZenohKeySpace("lab", 2), sender=201)
    [sample] = framing.encode_batch(MESSAGES)
    assert sample.key == "vstig/lab/2/201"
    assert sample.payload == b"".join(encode(m) for m in MESSAGES)
    listener = ZenohFraming(ZenohKeySpace("lab", 2), sender=0)
    assert listener.feed(sample) == MESSAGES
    assert listener.sender_of(sample) == 201
    assert framing.encode_batch([]) == []
    assert framing.encode(MESSAGES[0]) == [ZenohSample("vstig/lab/2/201", encode(MESSAGES[0]))]


@pytest.mark.parametrize(("key", "payload", "reason"), [
    ("vstig/lab/3/201", b"\0" * 8, "foreign_key"),  # another stigmergy
    ("vstig/other/2/201", b"\0" * 8, "foreign_key"),
    ("vstig/lab/2/robot", b"\0" * 8, "foreign_key"),
    ("vstig/lab/2/070000", b"\0" * 8, "foreign_key"),
    ("vstig/lab/2/201", b"\0" * 9, "bad_length"),
    ("vstig/lab/2/201", b"", "bad_length"),
])
def test_what_is_not_a_batch_of_this_space_is_dropped_and_counted(key: str, payload: bytes, reason: str) -> None:
    framing = ZenohFraming(ZenohKeySpace("lab", 2), sender=0)
    assert framing.feed(ZenohSample(key, payload)) == []
    assert framing.drops == {reason: 1}


def test_the_key_space_refuses_names_that_are_not_one_chunk() -> None:
    for swarm in ("", "a/b", "lab*", "$x", "la b"):
        with pytest.raises(ValueError, match="swarm name"):
            ZenohKeySpace(swarm)
    with pytest.raises(ValueError, match="stigmergy"):
        ZenohKeySpace("lab", 70000)
    with pytest.raises(ValueError, match="gateway id"):
        ZenohKeySpace("lab").key(-1)


# -- spec ---------------------------------------------------------------------------
def test_spec_defaults_and_every_key() -> None:
    assert parse("zenoh:lab") == ZenohSpec("lab")
    spec = parse("zenoh:lab?mode=client&connect=tls/router.lab:7447,tcp/10.0.0.5:7447&config=lab.json5"
                 "&stigmergy=3&scout=0")
    assert spec == ZenohSpec("lab", mode="client", connect=("tls/router.lab:7447", "tcp/10.0.0.5:7447"),
                             config="lab.json5", stigmergy=3, scout=False)
    assert spec.name == "zenoh-lab" and spec.kind == "zenoh"
    for example in EXAMPLES["zenoh"]:
        assert isinstance(parse(example), ZenohSpec)


@pytest.mark.parametrize(("spec", "names"), [
    ("zenoh:", "swarm name ''"),
    ("zenoh:a/b", "swarm name 'a/b'"),
    ("zenoh:lab?mode=router", "mode='router'"),
    ("zenoh:lab?connect=10.0.0.5:7447", "connect='10.0.0.5:7447'"),
    ("zenoh:lab?listen=tcpx/0.0.0.0:7447", "unknown protocol 'tcpx'"),
    ("zenoh:lab?scout=yes", "scout='yes'"),
    ("zenoh:lab?stigmergy=70000", "stigmergy=70000"),
    ("zenoh:lab?mode=client", "a client needs connect="),
    ("zenoh:lab?mode=client&connect=tcp/h:1&listen=tcp/0.0.0.0:1", "a client does not listen"),
    ("zenoh:lab?bitrate=5", "unknown parameter 'bitrate=5'"),
])
def test_a_bad_zenoh_spec_is_one_line_naming_the_bad_part(spec: str, names: str) -> None:
    with pytest.raises(ValueError) as caught:
        parse(spec)
    text = str(caught.value)
    assert names in text and "\n" not in text and "e.g. zenoh:lab" in text


# -- configuration: closed by default -------------------------------------------------
def test_by_default_it_listens_on_loopback_only_and_does_not_scout() -> None:
    config = zenoh_config(ZenohSpec("lab"))
    listen = config.get_json("listen/endpoints")
    assert listen.startswith('["tcp/127.0.0.1:') and listen.count("tcp/") == 1
    assert config.get_json("scouting/multicast/enabled") == "false"
    assert config.get_json("mode") == '"peer"'
    assert exposure(config) is None


def test_a_config_file_passes_through_and_the_spec_overrides_only_what_it_names(tmp_path: Path) -> None:
    file = tmp_path / "lab.json5"
    file.write_text('{ connect: { endpoints: ["tcp/10.0.0.9:7447"] }, listen: { endpoints: ["tcp/0.0.0.0:7447"] },'
                    ' transport: { link: { tx: { lease: 2500 } },'
                    ' auth: { usrpwd: { user: "lab", password: "pw" } } } }')
    config = zenoh_config(parse(f"zenoh:lab?config={file}&connect=tcp/10.0.0.5:7447"))
    assert config.get_json("transport/link/tx/lease") == "2500"
    assert config.get_json("connect/endpoints") == '["tcp/10.0.0.5:7447"]'
    assert config.get_json("listen/endpoints") == '["tcp/0.0.0.0:7447"]'
    assert config.get_json("scouting/multicast/enabled") == "false"  # unset in the file: our closed default
    assert exposure(config) is None  # user/password configured


def test_a_bad_config_file_is_one_line_naming_it(tmp_path: Path) -> None:
    file = tmp_path / "broken.json5"
    file.write_text("{ mode: ")
    for spec in (f"zenoh:lab?config={file}", f"zenoh:lab?config={tmp_path / 'missing.json5'}"):
        with pytest.raises(TransportError) as caught:
            parse(spec).build(robot_id=1)
        assert "Zenoh config file" in str(caught.value) and "\n" not in str(caught.value)


# -- real sessions on loopback --------------------------------------------------------
def _pair() -> tuple[Link[ZenohSample], Link[ZenohSample]]:
    first = parse("zenoh:lab").build(robot_id=201)
    first.open()
    [endpoint] = first.transport.listening  # type: ignore[attr-defined]  # read once open: the port bound
    second = parse(f"zenoh:lab?connect={endpoint}").build(robot_id=202)
    second.open()
    return first, second


def _until(condition: object, deadline: float = 20.0) -> None:
    end = time.monotonic() + deadline
    while not condition():  # type: ignore[operator]
        assert time.monotonic() < end, "timed out"
        time.sleep(0.05)


def _one_message_crosses(sender: Link[ZenohSample], receiver: Link[ZenohSample]) -> bool:
    """Send one message until the receiver hears it (a sample before the sessions meet reaches nobody)."""
    end = time.monotonic() + 20
    while time.monotonic() < end:
        sender.send(MESSAGES[0])
        heard = receiver.receive(0.3)
        if heard:
            return [h.message for h in heard] == [MESSAGES[0]]
    return False


def test_two_links_exchange_a_batch_as_one_sample_named_by_its_sender() -> None:
    first, second = _pair()
    try:
        heard = []
        end = time.monotonic() + 20
        while len(heard) < len(MESSAGES) and time.monotonic() < end:
            first.send_many(MESSAGES)  # again until the peers have met (a sample before that meets nobody)
            heard = second.receive(0.5)
        assert [h.message for h in heard] == MESSAGES
        assert {h.sender for h in heard} == {201}
        assert first.stats()["out"] >= 5 and first.transport.counters["tx"] == first.stats()["out"] // 5
        assert first.receive(0.2) == []  # a session never hears itself
        alone = parse("zenoh:lab").build(robot_id=203)
        alone.open()
        alone.send(MESSAGES[0])
        alone.close()
        assert alone.transport.counters["tx_unheard"] == 1  # published while no other session subscribed
    finally:
        first.close()
        second.close()


def _noticing_its_peer(link: Link[ZenohSample]) -> None:
    _until(lambda: link.transport.session.info.peers_zid())  # type: ignore[attr-defined]
    link.receive(1.1)  # the link notices its peer once a second


def test_a_link_that_connects_losing_every_peer_is_logged_once_and_counted(
        caplog: pytest.LogCaptureFixture) -> None:
    listener, dialer = _pair()
    try:
        _noticing_its_peer(dialer)
        with caplog.at_level(logging.WARNING):
            listener.close()
            end = time.monotonic() + 20
            while not dialer.transport.counters["lost"] and time.monotonic() < end:
                dialer.receive(0.2)
            for _ in range(10):
                dialer.receive(0.2)
    finally:
        dialer.close()
    assert dialer.transport.counters["lost"] == 1
    assert [r.getMessage() for r in caplog.records] == ["zenoh-lab: lost every Zenoh peer; Zenoh reconnects "
                                                       "with backoff"]


def test_a_listener_whose_last_peer_left_says_so_at_info_and_counts_no_loss(
        caplog: pytest.LogCaptureFixture) -> None:
    """Peers come to a listener and leave when done (a `vstig put`): that is no outage."""
    listener, dialer = _pair()
    try:
        _noticing_its_peer(listener)
        with caplog.at_level(logging.INFO, logger="vstig_hw.transports.zenoh"):
            dialer.close()
            _until(lambda: listener.receive(0.2) == [] and any("left" in r.getMessage() for r in caplog.records))
    finally:
        listener.close()
    [endpoint] = listener.transport.listening  # type: ignore[attr-defined]
    assert [(r.levelno, r.getMessage()) for r in caplog.records if r.name.endswith("zenoh")] == [
        (logging.INFO, f"zenoh-lab: the last Zenoh peer left; listening on {endpoint}")]
    assert listener.transport.counters["lost"] == 0 and listener.transport.counters["unreachable"] == 0


def test_a_client_with_no_router_retries_with_backoff_instead_of_failing(caplog: pytest.LogCaptureFixture) -> None:
    link = parse("zenoh:lab?mode=client&connect=tcp/127.0.0.1:1").build(robot_id=3)
    with caplog.at_level(logging.WARNING):
        link.open()  # no exception: the router may come later
        for _ in range(5):
            assert link.receive(0.1) == []
        link.send(MESSAGES[0])
    link.close()
    assert not link.transport.connected
    assert link.transport.counters["unreachable"] == 1 and link.transport.counters["tx_dropped"] == 1
    assert len(caplog.records) == 1 and "no Zenoh router reachable" in caplog.records[0].getMessage()


# -- the zenoh capture -----------------------------------------------------------------
def test_a_zenoh_capture_round_trips_and_a_bad_line_is_named(tmp_path: Path) -> None:
    from vstig_hw.capture.files import RotatingCapture
    from vstig_hw.capture.records import CaptureError, Record, read_capture

    path = str(tmp_path / "lab.zcap")
    sample = ZenohFraming(ZenohKeySpace("lab"), sender=201).encode_batch(MESSAGES)[0]
    capture = RotatingCapture(path, "zenoh")
    capture.write(Record(1700000000.25, "zenoh-lab", "zenoh", sample))
    capture.close()
    assert Path(path).read_text().splitlines() == [
        "# vstig zenoh capture v1", f"(1700000000.250000) zenoh-lab zenoh rx vstig/lab/0/201 {sample.payload.hex()}"]
    assert list(read_capture(path)) == [Record(1700000000.25, "zenoh-lab", "zenoh", sample)]
    with open(path, "a") as file:
        file.write("(1.0) zenoh-lab zenoh rx vstig/lab/0/201\n")
    with pytest.raises(CaptureError, match=r"lab.zcap:3: not a zenoh capture line"):
        list(read_capture(path))


def _sockets(table: str) -> list[tuple[str, int, str]]:
    """(local address hex, port, state hex) of every socket in /proc/net/<table> (this network namespace)."""
    rows = Path(f"/proc/net/{table}").read_text().splitlines()[1:]
    out = []
    for row in rows:
        fields = row.split()
        address, port = fields[1].split(":")
        out.append((address, int(port, 16), fields[3]))
    return out


def test_an_open_link_really_listens_on_loopback_only_and_joins_no_multicast_group() -> None:
    link = parse("zenoh:lab").build(robot_id=1)
    link.open()
    [endpoint] = link.transport.listening  # type: ignore[attr-defined]
    port = int(endpoint.rsplit(":", 1)[1])
    try:
        listening = [(a, s) for a, p, s in _sockets("tcp") + _sockets("tcp6") if p == port and s == "0A"]
        assert listening == [("0100007F", "0A")]  # 127.0.0.1, LISTEN: nothing on 0.0.0.0 or ::
        assert all(p != 7446 for _, p, _ in _sockets("udp") + _sockets("udp6"))  # Zenoh's scouting port unused
    finally:
        link.close()


def test_a_default_port_taken_before_the_session_binds_it_is_replaced_by_a_fresh_one(
        caplog: pytest.LogCaptureFixture) -> None:
    import socket

    first = parse("zenoh:lab").build(robot_id=201)
    [picked] = first.transport.listening  # type: ignore[attr-defined]
    assert picked.startswith("tcp/127.0.0.1:")
    thief = socket.socket(socket.AF_INET, socket.SOCK_STREAM)  # another program takes the port meanwhile
    thief.bind(("127.0.0.1", int(picked.rsplit(":", 1)[1])))
    thief.listen()
    second = None
    try:
        with caplog.at_level(logging.WARNING):
            first.open()  # today's code stopped here: "Address already in use"
        [bound] = first.transport.listening  # type: ignore[attr-defined]
        assert bound != picked and bound.startswith("tcp/127.0.0.1:")
        assert f"listening on {bound}" in first.transport.about
        port = int(bound.rsplit(":", 1)[1])
        assert [(a, s) for a, p, s in _sockets("tcp") if p == port and s == "0A"] == [("0100007F", "0A")]
        assert [r.getMessage() for r in caplog.records] == [
            f"zenoh-lab: another program took {picked} before Zenoh bound it; listening on a fresh port"]
        second = parse(f"zenoh:lab?connect={bound}").build(robot_id=202)
        second.open()
        assert _one_message_crosses(first, second)
    finally:
        thief.close()
        first.close()
        if second is not None:
            second.close()


def test_when_every_fresh_port_is_taken_too_opening_fails_in_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    import socket

    import vstig_hw.links.zenoh as zenoh_links

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        monkeypatch.setattr(zenoh_links, "_free_loopback_port", lambda: port)  # every pick lands on a taken port
        link = parse("zenoh:lab").build(robot_id=1)
        with pytest.raises(TransportError) as caught:
            link.open()
    message = str(caught.value)
    assert message.startswith("zenoh-lab: cannot open a Zenoh session: ") and "Address already in use" in message
    assert "\n" not in message


def test_a_listen_port_the_user_named_is_never_swapped_for_another() -> None:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        endpoint = f"tcp/127.0.0.1:{taken.getsockname()[1]}"
        link = parse(f"zenoh:lab?listen={endpoint}").build(robot_id=1)
        with pytest.raises(TransportError) as caught:
            link.open()
    message = str(caught.value)
    assert message.startswith(f"zenoh-lab: cannot open a Zenoh session: Can not create a new TCP listener "
                              f"bound to {endpoint}") and "Address already in use" in message
    assert "\n" not in message and link.transport.listening == (endpoint,)  # type: ignore[attr-defined]


def _router(port: int) -> object:
    import json

    import zenoh

    config = zenoh.Config()
    config.insert_json5("mode", '"router"')
    config.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


def test_clients_survive_their_router_going_away_and_coming_back(caplog: pytest.LogCaptureFixture) -> None:
    from vstig_hw.links.zenoh import _free_loopback_port

    port = _free_loopback_port()
    router = _router(port)
    spec = f"zenoh:lab?mode=client&connect=tcp/127.0.0.1:{port}"
    sender, receiver = parse(spec).build(robot_id=1), parse(spec).build(robot_id=2)
    sender.open()
    receiver.open()
    try:
        with caplog.at_level(logging.WARNING):
            router.close()  # type: ignore[attr-defined]
            _until(lambda: sender.receive(0.2) == [] and sender.transport.counters["lost"] == 1)
            router = _router(port)
            _until(lambda: sender.receive(0.2) == [] and sender.transport.counters["reconnects"] == 1)
        assert _one_message_crosses(sender, receiver)
        mine = [r.getMessage() for r in caplog.records if r.name.endswith("zenoh")]
        assert mine.count("zenoh-lab: lost every Zenoh peer; Zenoh reconnects with backoff") >= 1
        assert sender.transport.counters["lost"] == 1 and sender.transport.counters["unreachable"] == 0
    finally:
        sender.close()
        receiver.close()
        router.close()  # type: ignore[attr-defined]


def test_capture_filters_cut_a_zenoh_sample_by_key_and_sender() -> None:
    from vstig_hw.capture.decoded import filter_records
    from vstig_hw.capture.filters import Filter
    from vstig_hw.capture.records import Record

    space = ZenohKeySpace("lab")
    samples = [ZenohFraming(space, sender=gateway).encode_batch(MESSAGES)[0] for gateway in (201, 202)]
    records = [Record(1.0 + i, "zenoh-lab", "zenoh", sample) for i, sample in enumerate(samples)]
    kept = list(filter_records(records, Filter(keys=frozenset({1, 3}), senders=frozenset({202}))))
    assert kept == [Record(2.0, "zenoh-lab", "zenoh", ZenohSample("vstig/lab/0/202", encode(MESSAGES[1])
                                                                   + encode(MESSAGES[3])))]


def test_a_client_opened_before_its_router_joins_when_the_router_comes_up() -> None:
    from vstig_hw.links.zenoh import _free_loopback_port

    port = _free_loopback_port()
    link = parse(f"zenoh:lab?mode=client&connect=tcp/127.0.0.1:{port}").build(robot_id=4)
    link.open()
    router = _router(port)
    try:
        _until(lambda: link.receive(0.2) == [] and link.transport.connected, 30)  # reopened under backoff
        assert link.transport.counters["unreachable"] == 1 and link.transport.counters["reconnects"] == 1
    finally:
        link.close()
        router.close()  # type: ignore[attr-defined]


def _honest_gateway_and_stock_session(gateway: Link[Any]) -> tuple[Link[Any], Any]:
    """Beside an open zenoh link: another gateway's link (gateway 202) and a stock Zenoh session, both connected to
    it, once the stock session hears its subscription."""
    import json

    import zenoh

    [endpoint] = gateway.transport.listening  # type: ignore[attr-defined]
    honest = parse(f"zenoh:lab?connect={endpoint}").build(robot_id=202)
    honest.open()
    config = zenoh.Config()
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    stock = zenoh.open(config)
    _until(lambda: stock.info.peers_zid())
    time.sleep(0.5)  # the gateway's subscription reaches the stock session just after the session opens
    return honest, stock


def test_a_peer_naming_a_new_gateway_per_sample_is_held_to_its_source_rate_and_others_keep_theirs() -> None:
    import zenoh

    from vstig_hw.gateway import Mode, Node
    from vstig_hw.gateway.guard import Guard
    from vstig_hw.links import Heard

    gateway = parse("zenoh:lab").build(robot_id=201)
    node = Node([gateway], mode=Mode.LISTEN, guard=Guard(source_rate=50))
    heard: list[Heard] = []
    node.listen(heard=heard.append)
    with node:
        honest, attacker = _honest_gateway_and_stock_session(gateway)  # the stock session claims a new gateway id
        try:                                                             # per sample, and stamps nothing
            for i in range(1000):
                attacker.put(f"vstig/lab/0/{1000 + i}", encode(Message(Op.PUT, 1, i, i + 1, 1000 + i)),
                             congestion_control=zenoh.CongestionControl.BLOCK)
            honest.send_many([Message(Op.PUT, 2, v, v + 1, 202) for v in range(20)])

            def refused() -> int:  # mostly the source rate; a sample let through after a long refusal may jump
                return sum(n for name, n in gateway.counters.items() if name.startswith("drop_"))

            def all_accounted() -> bool:  # every attacker sample heard or refused, every honest one heard
                attacker_heard = sum(h.message.key == 1 for h in heard)
                return (attacker_heard + refused() >= 1000
                        and sum(h.message.key == 2 for h in heard) >= 20)

            wait_until(all_accounted, 10.0)
        finally:
            attacker.close()  # type: ignore[no-untyped-call]
            honest.close()
    from_attacker = [h for h in heard if h.message.key == 1]
    assert 50 <= len(from_attacker) <= 200, len(from_attacker)  # a burst of 50, then 50 a second
    assert refused() == 1000 - len(from_attacker), dict(gateway.counters)
    assert gateway.counters["drop_source_rate"] >= 1000 - len(from_attacker) - 10
    assert [h.message.value for h in heard if h.message.key == 2] == list(range(20))  # another session: its own


def test_a_peer_stamping_a_fresh_session_id_on_every_sample_is_held_to_one_source_rate() -> None:
    """The stock API stamps any id per sample (`put(timestamp=...)`): a made-up id names no session connected to
    ours, so every such sample shares the link's one bucket, while a connected session keeps its own."""
    import datetime

    import zenoh

    from vstig_hw.gateway import Mode, Node
    from vstig_hw.gateway.guard import Guard

    gateway = parse("zenoh:lab").build(robot_id=201)
    node = Node([gateway], mode=Mode.LISTEN, guard=Guard(source_rate=100))
    passed: dict[int, int] = {1: 0, 2: 0}
    node.listen(messages=lambda _link, _t, _sender, msgs: passed.update(
        {key: passed[key] + sum(m.key == key for m in msgs) for key in passed}))
    with node:
        honest, forger = _honest_gateway_and_stock_session(gateway)
        try:
            start = time.monotonic()
            sent = 0
            while time.monotonic() - start < 2.0:  # ~2 s of forged samples, each with a new session id
                stamp = zenoh.Timestamp(datetime.datetime.now(datetime.UTC),
                                        zenoh.TimestampId(os.urandom(16)))
                forger.put(f"vstig/lab/0/{1000 + sent % 1000}", encode(Message(Op.PUT, 1, sent, 1 + sent % 255, 7)),
                           timestamp=stamp, congestion_control=zenoh.CongestionControl.BLOCK)
                sent += 1
                if sent % 50 == 0:  # the honest session: 25 messages a second, well within its own 100
                    honest.send_many([Message(Op.PUT, 2, sent // 50, sent // 50, 202)])
                    time.sleep(0.04)
            took = time.monotonic() - start
            time.sleep(0.5)
        finally:
            forger.close()  # type: ignore[no-untyped-call]
            honest.close()
    assert sent > 1000, sent  # the forger sent far beyond the rate
    assert passed[1] <= 1.5 * 100 * (1 + took), (passed, took)  # a burst of 100, then 100 a second: at most 1.5x
    assert gateway.counters["drop_source_rate"] >= sent - passed[1] - 10
    assert passed[2] == sent // 50, passed  # the connected session's own bucket: every honest message


def test_a_gateway_closes_at_once_while_a_peer_floods_it_through_zenohs_callback() -> None:
    """Samples reach the gateway on Zenoh's callback thread; closing mid-flood neither waits on it nor breaks it."""
    import os
    import threading

    from vstig_hw.gateway import Node

    gateway = parse("zenoh:lab").build(robot_id=201)
    bus = parse(f"can:virtual:zenoh-flood-{os.getpid()}").build(robot_id=201)
    node = Node([gateway, bus], 201, budget=None)
    threads: set[str] = set()  # the threads zenoh's messages were handled on
    node.listen(messages=lambda link, _t, _sender, _messages: threads.add(threading.current_thread().name)
                            if link == gateway.name else None)
    node.open()
    [endpoint] = gateway.transport.listening  # type: ignore[attr-defined]
    peer = parse(f"zenoh:lab?connect={endpoint}").build(robot_id=202)
    peer.open()
    flooding = threading.Event()

    def flood() -> None:
        stamp = 0
        while not flooding.is_set():
            stamp += 1
            peer.send_many([Message(Op.PUT, key, stamp, stamp, 202) for key in range(64)])

    flooder = threading.Thread(target=flood, daemon=True)
    flooder.start()
    try:
        _until(lambda: gateway.counters["in"] > 2000)
        assert node.on_node_thread() is False  # the test's thread is not a gateway thread
        flowing = set(threads)  # while it ran (at the stop the read thread may hand over what zenoh queued then)
        began = time.monotonic()
        node.close()
        took = time.monotonic() - began
    finally:
        flooding.set()
        flooder.join(timeout=5)
        peer.close()
    assert took < 3.0, f"close took {took:.1f} s under a zenoh flood"
    assert node.wait_closed(0)
    heard = gateway.counters["in"]
    assert bus.counters["out"] > 0  # what zenoh carried went on to the bus
    assert flowing and not any(name.startswith("read-") for name in flowing)  # from zenoh's thread, not our reader
    time.sleep(0.3)
    assert gateway.counters["in"] == heard  # nothing handled after close


# -- what a peer can make the gateway hold: bounded in the config we build ------------------------------------
def test_the_config_we_build_bounds_a_peers_sample_and_shares_no_memory() -> None:
    from vstig_hw.links.zenoh import HEADROOM

    config = zenoh_config(ZenohSpec("lab"))
    assert config.get_json("transport/link/rx/max_message_size") == str(64 * 1024 + HEADROOM)
    assert config.get_json("transport/shared_memory/enabled") == "false"
    bigger = zenoh_config(parse("zenoh:lab?max_sample=1048576"))  # derived from max_sample
    assert bigger.get_json("transport/link/rx/max_message_size") == str(1048576 + HEADROOM)


def test_a_config_file_that_loosens_our_bounds_keeps_its_values_and_is_warned_about(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    file = tmp_path / "lab.json5"
    file.write_text("{\n  transport: {\n    link: { rx: { max_message_size: 1073741824 } },\n"
                    "    shared_memory: { enabled: true },\n  },\n}\n")
    with caplog.at_level(logging.WARNING):
        link = parse(f"zenoh:lab?config={file}").build(robot_id=1)
    config = zenoh_config(parse(f"zenoh:lab?config={file}"))
    assert config.get_json("transport/link/rx/max_message_size") == "1073741824"  # the user's, as written
    assert config.get_json("transport/shared_memory/enabled") == "true"
    assert [r.getMessage() for r in caplog.records] == [
        f"zenoh-lab: {file}:3 sets transport/link/rx/max_message_size to 1073741824 (vstig's default: 131072): "
        "one peer's sample can take that much of this PC's memory",
        f"zenoh-lab: {file}:4 sets transport/shared_memory/enabled to true (vstig's default: false): each local "
        "peer's shared memory may stay mapped here after it leaves"]
    assert link.name == "zenoh-lab"
    caplog.clear()
    file.write_text("{ transport: { link: { rx: { max_message_size: 100000 } } } }")  # tighter: kept, silently
    with caplog.at_level(logging.WARNING):
        parse(f"zenoh:lab?config={file}").build(robot_id=1)
    assert caplog.records == []
    assert zenoh_config(parse(f"zenoh:lab?config={file}")).get_json("transport/link/rx/max_message_size") == "100000"
    file.write_text("{ transport: { link: { tx: { lease: 2500 } } } }")  # the file sets neither: ours, silently
    with caplog.at_level(logging.WARNING):
        parse(f"zenoh:lab?config={file}").build(robot_id=1)
    assert caplog.records == []
    assert zenoh_config(parse(f"zenoh:lab?config={file}")).get_json("transport/shared_memory/enabled") == "false"
