"""Attacks on a `vstig bridge --swarm-key` process, on real pty radios (cobs8; SPEC.md section 10).

Radio A (auth=require) carries honest robot 5, who holds only its own key, and the attackers: an outsider's
radio writing with no key, robot 6 writing under robot 5's id with its own key, a relayed entry whose value was
changed on the way, and a replay of robot 5's old write after a timestamp wrap-around (RFC 1982 calls it newer
again; the jump guard is off, so the epoch alone refuses it). Radio B (auth=require) is honest robot 7, who reads what
the bridge relays. Radio C (auth=off) is robot 8, who has no key (a robot on a framing without room). Each
attack is refused and counted, by claimed writer; robot 5's honest writes all reach B with robot 5's own tag;
robot 8's write is kept but never carried onto B.
"""

from __future__ import annotations

import json
import re
import time
from collections.abc import Sequence
from pathlib import Path

from attacks import FLOOD_FIRST_KEY, Bridge, Radio, honest_delays, quantile, wait_until_relaying, zenoh_flood
from peers import PtyPeer, has_open, start_vstig, stop, wait_for

from vstig_hw.auth import SwarmKeys, Tagged, entry_tag, next_epoch, robot_key
from vstig_hw.framing import make_serial_framing
from vstig_hw.links.zenoh import _free_loopback_port
from vstig_hw.timestamps import TS_MAX, is_newer
from vstig_hw.wire import Message, Op

MASTER = bytes(range(0xA0, 0xC0))
HONEST_KEYS = range(10, 60)
WRAP_KEY, STEP = 4, 20_000


class Robot:
    """A cobs8 radio of the bridge, sending as it is told and keeping what it hears with its records."""

    def __init__(self) -> None:
        self.radio = PtyPeer()
        self.framing = make_serial_framing("cobs8")
        self.heard: list[tuple[Message, Tagged | None]] = []

    def send(self, records: Sequence[Tagged] = (), messages: Sequence[Message] = ()) -> None:
        data = b"".join(self.framing.encode_tagged(records)) + b"".join(self.framing.encode_batch(list(messages)))
        self.radio.write(data)

    def listen(self) -> None:
        data = self.radio.read(0.02)
        if data:
            self.heard.extend(self.framing.feed_tagged(data))


def own(robot: int, msg: Message, epoch: int = 0) -> Tagged:
    """`msg` tagged by robot `robot`, holding only its own key."""
    return Tagged(msg, epoch, entry_tag(robot_key(MASTER, robot), 0, msg, epoch))


def wrap_writes() -> list[Tagged]:
    """Robot 5's writes of WRAP_KEY, STEP apart, from timestamp 1 round the wrap (epoch 1) to one that its second
    write is newer than by RFC 1982: that write, replayed then, would win without the epoch."""
    writes = [own(5, Message(Op.PUT, WRAP_KEY, 1, 1, 5))]
    while not (writes[-1].epoch == 1 and is_newer(writes[1].message.timestamp, writes[-1].message.timestamp)):
        last = writes[-1]
        ts = (last.message.timestamp - 1 + STEP) % TS_MAX + 1
        epoch = next_epoch(last.epoch, last.message.timestamp, ts)
        writes.append(own(5, Message(Op.PUT, WRAP_KEY, len(writes), ts, 5), epoch))
    return writes


def _counters(stderr: str, link: str) -> dict[str, int]:
    line = [line for line in stderr.splitlines() if line.startswith(f"{link}: ") and "=" in line][-1]  # at exit
    return {name: int(count) for name, count in re.findall(r"(\w+)=(\d+)", line)}


def test_attacks_refused_counted_and_honest_writes_intact(tmp_path: Path) -> None:
    key_file = tmp_path / "swarm.key"
    key_file.write_text(MASTER.hex() + "\n", encoding="ascii")
    key_file.chmod(0o600)
    a, b, c = Robot(), Robot(), Robot()
    bridge = start_vstig("bridge", f"serial:{a.radio.path}?framing=cobs8&auth=require",
                         f"serial:{b.radio.path}?framing=cobs8&auth=require",
                         f"serial:{c.radio.path}?framing=cobs8&auth=off",
                         "--robot-id", "200", "--swarm-key", str(key_file), "--tick", "0.02", "--no-refresh",
                         "--max-jump", "0")
    try:
        first = own(5, Message(Op.PUT, 1, 1000, 3, 5))

        def again() -> None:  # until the bridge is up: robot 5's first write, repeated
            a.send([first])
            b.listen()
            time.sleep(0.1)

        wait_for(lambda: any(msg.key == 1 for msg, _ in b.heard), 30, again)
        a.send(messages=[Message(Op.PUT, 2, 666, 9, 99)])  # an outsider's radio: no key, no tag
        a.send([own(6, Message(Op.PUT, 3, 666, 9, 5))])  # robot 6 claims robot 5's id, tags with its own key
        a.send([Tagged(Message(Op.PUT, 1, 1001, 4, 5), 0, first.tag)])  # robot 5's entry, its value changed
        c.send(messages=[Message(Op.PUT, 5, 80, 1, 8)])  # robot 8 on the auth=off radio
        # Robot 5 writes the wrap key round the wrap (RFC 1982: its old write is "newer" again), the attacker having
        # recorded its second write; then the replay. The jump guard is off (--max-jump 0): the epoch alone stops it.
        writes = wrap_writes()
        recorded = writes[1]
        for write in writes:  # one at a time, as a robot writes
            a.send([write])
            wait_for(lambda: any(msg == write.message for msg, _ in b.heard[-3:]), 10, b.listen)  # noqa: B023
        replayed_at = len(b.heard)
        a.send([recorded])  # the replay: its tag checks out, its epoch is old
        a.send([own(5, Message(Op.PUT, key, key, 1, 5)) for key in HONEST_KEYS])
        wait_for(lambda: {msg.key for msg, _ in b.heard} >= set(HONEST_KEYS), 30, b.listen)
        time.sleep(0.3)
        b.listen()
    finally:
        _, stderr = stop(bridge)
        for robot in (a, b, c):
            robot.radio.close()
    keys = SwarmKeys(MASTER)
    relayed = {(msg.key, msg.value, msg.timestamp): record for msg, record in b.heard if msg.op is Op.PUT}
    assert all(record is not None and keys.verify(record) and record.message.robot in (5, 200)
               for record in relayed.values()), stderr  # everything on B proven by its writer
    honest = [key for key in HONEST_KEYS if relayed.get((key, key, 1)) == own(5, Message(Op.PUT, key, key, 1, 5))]
    assert len(honest) / len(HONEST_KEYS) == 1.0, stderr  # honest robot 5 gets all through, with its own tags
    assert not {key for key, _, _ in relayed} & {2, 3, 5}, stderr  # no forgery, no unverified entry on B
    assert (1, 1001, 4) not in relayed, stderr
    assert recorded.message not in [msg for msg, _ in b.heard[replayed_at:]], stderr  # the replay went nowhere
    a_name, c_name = Path(a.radio.path).name, Path(c.radio.path).name
    counted = _counters(stderr, a_name)
    assert (counted["drop_untagged"], counted["drop_bad_tag"]) == (1, 2), stderr
    assert "refusing untagged writes claiming robot 99" in stderr, stderr
    assert stderr.count("refusing writes whose tag does not check out claiming robot 5") == 1, stderr
    assert _counters(stderr, "engine")["stale"] >= 1, stderr  # the replay lost, as any old write does
    assert _counters(stderr, c_name)["in"] >= 1 and _counters(stderr, Path(b.radio.path).name)["held_unverified"] >= 1


def test_a_zenoh_peer_stamping_other_sessions_is_refused_whole_and_the_radios_keep_their_pace(tmp_path: Path) -> None:
    """A mixed swarm: two radios of robots without keys (auth=off) and a zenoh link that requires tags, flooded by a
    local peer that stamps a new session id on every sample (the stock API's; the guard how-to: "only authentication
    stops that"). Not one of its messages is stored or reaches radio B; robot A's writes reach B as fast as before
    the flood (median within 2x, or 1 ms, of the quiet run's)."""
    key_file = tmp_path / "swarm.key"
    key_file.write_text(MASTER.hex() + "\n", encoding="ascii")
    key_file.chmod(0o600)
    endpoint = f"tcp/127.0.0.1:{_free_loopback_port()}"
    a, b = Radio(), Radio()
    try:
        with Bridge(f"{a.spec}&auth=off", f"{b.spec}&auth=off", f"zenoh:lab?listen={endpoint}&auth=require",
                    "--swarm-key", str(key_file)) as bridge:
            wait_until_relaying(a, b)
            quiet = honest_delays(a, b, count=40, first=900)
            with zenoh_flood(endpoint, rate=5_000, forge=True):
                time.sleep(1.0)
                delays = honest_delays(a, b)
    finally:
        for radio in (a, b):
            radio.close()
    stderr = bridge.stderr
    zenoh_counts = _counters(stderr, "zenoh-lab")
    assert zenoh_counts["drop_untagged"] >= 1000 and zenoh_counts["drop_untagged"] == zenoh_counts["in"], stderr
    assert not [key for key in b.arrived if key >= FLOOD_FIRST_KEY], stderr  # nothing of the flood on B
    assert stderr.count("refusing untagged writes claiming robot 66") == 1, stderr  # logged once in the episode
    assert zenoh_counts["held_unverified"] >= 1, stderr  # the radios' untagged writes stay off the zenoh link
    assert all(delay is not None for delay in delays), stderr  # every honest write there
    p50, quiet_p50 = quantile(delays, 0.5), quantile(quiet, 0.5)
    print(f"A -> B p50 under the forged flood / quiet: {p50 / quiet_p50:.2f} ({p50 * 1e3:.2f} / "
          f"{quiet_p50 * 1e3:.2f} ms)")
    assert p50 <= max(2 * quiet_p50, quiet_p50 + 0.001), stderr


def test_sniff_with_the_swarm_key_marks_untagged_and_forged_writes_refused(tmp_path: Path) -> None:
    key_file = tmp_path / "swarm.key"
    key_file.write_text(MASTER.hex() + "\n", encoding="ascii")
    key_file.chmod(0o600)
    radio = Robot()
    sniffer = start_vstig("sniff", f"serial:{radio.radio.path}?framing=cobs8&auth=require", "--swarm-key",
                          str(key_file), "--jsonl", "--for", "3")
    try:
        wait_for(lambda: has_open(sniffer.pid, radio.radio.path), 30)  # it never transmits: look at its fds
        time.sleep(0.3)  # pyserial flushes the input right after opening
        radio.send([own(5, Message(Op.PUT, 1, 10, 1, 5)), own(6, Message(Op.PUT, 2, 20, 1, 5))],
                   [Message(Op.PUT, 3, 30, 1, 99)])
        out, err = sniffer.communicate(timeout=60)
    finally:
        if sniffer.poll() is None:
            stop(sniffer)
        radio.radio.close()
    rows = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    # (a unit's refusals are told before what it let through: the order within one read is not kept)
    assert sorted((row["key"], row["robot"], row["refused"]) for row in rows) == \
        [(1, 5, None), (2, 5, "drop_bad_tag"), (3, 99, "drop_untagged")], err
    assert "drop_bad_tag=1" in err and "drop_untagged=1" in err, err
