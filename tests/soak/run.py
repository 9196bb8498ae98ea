"""`make soak`: one guarded gateway bridging a CAN bus and two pty radios at 5,000 messages/s.

    python tests/soak/run.py [--seconds 600] [--drain 5]

Offered load (messages per second): on the CAN bus (python-can's virtual bus, which
exists only in-process, so the bus robots share the gateway's process) 20 honest
robots x 150 on 10 keys each, one stuck robot repeating one PUT 1,000 times a second
(a flood), and one robot whose counter jumps 1,000 ahead once a second; on each of
two cobs8 pty radios (their robots in a child process) 5 robots x 100 on 10 keys each.
The gateway runs the engine with a guard (--max-jump 255, --rate 600 per sender; a
radio names nobody, so each radio is one sender at 500/s).

Checked at the end, after `--drain` seconds with no new traffic:

* nothing lost on the way in: each link's `in` equals what its robots sent, and no
  framing dropped anything;
* every counter adds up: messages in = engine outcomes + refusals by reason; the
  flood's only STORED message is its first and every other one it sent is SAME or
  drop_rate; every jump is drop_jump; each link's `out` equals what its far end decoded;
* nothing lost that the budget allowed: every robot on every medium ends holding
  the last value every honest robot wrote (the outlets keep the newest per key, so
  that is the only loss-free outcome when keys change faster than the budget);
  the bus's robots hear each other's writes from the writer, so the gateway sends
  them only the radios' (a bus is one broadcast domain: nothing is echoed back);
* memory: resident size after warm-up and at the end (and the growth) is printed; a
  growth over `--max-growth` MB fails the run.
"""

from __future__ import annotations

import argparse
import contextlib
import multiprocessing
import os
import select
import sys
import threading
import time
import tty
from dataclasses import dataclass, field
from typing import Any

import can

from vstig_hw import Message, Op
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.can import can_framing, can_framing_for
from vstig_hw.gateway import Node, favour_latency
from vstig_hw.gateway.guard import Guard
from vstig_hw.links import parse
from vstig_hw.timestamps import is_newer, next_timestamp

STEP = 0.01  # seconds between bursts of each writer
CAN_ROBOTS, CAN_KEYS_EACH, CAN_RATE = 20, 10, 150  # honest CAN robots, keys each, messages/s each
RADIO_ROBOTS, RADIO_KEYS_EACH, RADIO_RATE = 5, 10, 100
FLOOD_RATE, GUARD_RATE = 1000, 600
FLOODER, JUMPER, GATEWAY = 99, 98, 200
FLOOD_KEY, JUMP_KEY = 3000, 4000
RADIO_BASES = (1000, 2000)  # radio-a keys 1000.., radio-b keys 2000..


@dataclass
class Writers:
    """Robots that put: each key's next timestamp; what was last written; how many messages were sent."""

    keys: list[int]
    robot_of: Any
    rate: float
    sent: int = 0
    last: dict[int, tuple[int, int]] = field(default_factory=dict)  # key -> (value, timestamp)
    _due: float = 0.0

    def burst(self, elapsed: float) -> list[Message]:
        """The messages due by `elapsed` seconds, round-robin over the keys."""
        due = int(elapsed * self.rate) - self.sent
        out = []
        for _ in range(max(0, due)):
            key = self.keys[self.sent % len(self.keys)]
            ts = next_timestamp(self.last[key][1]) if key in self.last else 1
            value = (self.sent // len(self.keys)) & 0xFFFF
            self.last[key] = (value, ts)
            out.append(Message(Op.PUT, key, value, ts, self.robot_of(key)))
            self.sent += 1
        return out


@dataclass
class Heard:
    """A far end's view of what the gateway sent: how many messages, and the newest entry per key."""

    count: int = 0
    newest: dict[int, tuple[int, int]] = field(default_factory=dict)

    def add(self, msg: Message) -> None:
        self.count += 1
        old = self.newest.get(msg.key)
        if old is None or is_newer(msg.timestamp, old[1]):
            self.newest[msg.key] = (msg.value, msg.timestamp)


def _raw_pty() -> tuple[int, int, str]:
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    os.set_blocking(master, False)
    return master, slave, os.ttyname(slave)


def radios(masters: list[int], conn: Any) -> None:
    """In a child process: the robots on both radios write at their rate and decode what the gateway sends."""
    writers = [Writers([base + k for k in range(RADIO_ROBOTS * RADIO_KEYS_EACH)],
                       lambda key, b=base: 20 + b // 1000 * 10 + key % RADIO_ROBOTS, RADIO_ROBOTS * RADIO_RATE)
               for base in RADIO_BASES]
    framings = [make_serial_framing("cobs8") for _ in masters]
    heard = [Heard() for _ in masters]
    pending = [bytearray() for _ in masters]
    conn.recv()  # "go": the gateway is open
    start = time.monotonic()
    writing, flushed = True, False
    while True:
        if conn.poll():
            if conn.recv() == "report":
                conn.send(([(w.sent, w.last) for w in writers], [(h.count, h.newest) for h in heard]))
                return
            writing = False  # "stop"
        if writing:
            elapsed = time.monotonic() - start
            for i, writer in enumerate(writers):
                pending[i] += b"".join(unit for msg in writer.burst(elapsed) for unit in framings[i].encode(msg))
        elif not flushed and not any(pending):
            conn.send("flushed")
            flushed = True
        waiting = [master for master, data in zip(masters, pending, strict=True) if data]
        readable, writable, _ = select.select(masters, waiting, [], STEP)
        for i, master in enumerate(masters):
            if master in writable:
                with contextlib.suppress(BlockingIOError):
                    del pending[i][:os.write(master, pending[i])]
            if master in readable:
                try:
                    data = os.read(master, 65536)
                except BlockingIOError:
                    continue
                for msg in framings[i].feed(data):
                    heard[i].add(msg)


def rss_mb() -> float:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=float(os.environ.get("SOAK_SECONDS", 600)))
    parser.add_argument("--drain", type=float, default=5.0, help="seconds of quiet at the end for queues to empty")
    parser.add_argument("--max-growth", type=float, default=32.0, help="MB of resident growth after warm-up that fails")
    args = parser.parse_args()
    fork = multiprocessing.get_context("fork")

    ptys = [_raw_pty() for _ in RADIO_BASES]
    conn, child_conn = fork.Pipe()
    child = fork.Process(target=radios, args=([m for m, _, _ in ptys], child_conn), daemon=True)
    child.start()  # before any thread exists here: a fork copies only the calling thread

    channel = f"soak-{os.getpid()}"
    # One handle for every robot on the bus: it sends their frames and hears the gateway's (a second handle
    # that nobody read would queue every frame the gateway sends, and look like a leak).
    robots_bus = can.Bus(interface="virtual", channel=channel)
    links = [parse(f"can:virtual:{channel}").build("bus", robot_id=GATEWAY)]
    links += [parse(f"serial:{path}?framing=cobs8").build(name, robot_id=GATEWAY)
              for (_, _, path), name in zip(ptys, ("radio-a", "radio-b"), strict=True)]
    node = Node(links, GATEWAY, guard=Guard(rate=GUARD_RATE))
    favour_latency()

    honest = Writers(list(range(CAN_ROBOTS * CAN_KEYS_EACH)), lambda key: 1 + key // CAN_KEYS_EACH,
                     CAN_ROBOTS * CAN_RATE)
    codecs = {robot: can_framing_for(robot) for robot in range(1, CAN_ROBOTS + 1)}
    flood = can_framing_for(FLOODER).encode(Message(Op.PUT, FLOOD_KEY, 1, 1, FLOODER))[0]  # the same, over and over
    jump_codec = can_framing_for(JUMPER)
    bus_heard, counts = Heard(), {"flood": 0, "jump": 0}
    stop_listening = threading.Event()

    def listen() -> None:  # the CAN bus's far end: what the gateway sent there
        decode = can_framing()
        while not stop_listening.is_set():
            frame = robots_bus.recv(0.05)
            if frame is not None and frame.arbitration_id & 0xFF == GATEWAY:
                for msg in decode.feed(frame):
                    bus_heard.add(msg)

    listener = threading.Thread(target=listen, daemon=True)
    node.open()  # its loop runs on its own thread
    listener.start()
    conn.send("go")
    warmup = min(30.0, args.seconds / 5)
    rss_warm: float | None = None
    start = time.monotonic()
    next_report = start + 10
    print(f"soak: {args.seconds:.0f} s at {CAN_ROBOTS * CAN_RATE + FLOOD_RATE + 2 * RADIO_ROBOTS * RADIO_RATE:,} "
          f"messages/s offered (warm-up {warmup:.0f} s)", flush=True)
    try:
        while (elapsed := time.monotonic() - start) < args.seconds:
            for msg in honest.burst(elapsed):
                robots_bus.send(codecs[msg.robot].encode(msg)[0])
            while counts["flood"] < int(elapsed * FLOOD_RATE):
                robots_bus.send(flood)
                counts["flood"] += 1
            if counts["jump"] <= int(elapsed):  # timestamp 1 (a new key), then 1001..30001 again and again: jumps
                ahead = 1000 * ((counts["jump"] - 1) % 30 + 1) if counts["jump"] else 0
                jump = Message(Op.PUT, JUMP_KEY, counts["jump"] & 0xFFFF, 1 + ahead, JUMPER)
                robots_bus.send(jump_codec.encode(jump)[0])
                counts["jump"] += 1
            if elapsed >= warmup and rss_warm is None:
                rss_warm = rss_mb()
            if time.monotonic() >= next_report:
                next_report += 10
                print(f"  {elapsed:5.0f} s  rss {rss_mb():6.1f} MB  {node.summary()}", flush=True)
            time.sleep(STEP)
        conn.send("stop")
        conn.recv()  # "flushed": every radio byte is written
        time.sleep(args.drain)
    finally:
        rss_end = rss_mb()
        node.close()
        stop_listening.set()
        listener.join(timeout=5)
        conn.send("report")
        radio_writers, radio_heard = conn.recv()
        child.join(timeout=10)
        robots_bus.shutdown()
        for master, slave, _ in ptys:
            os.close(master)
            os.close(slave)
    return report(node, honest, counts, radio_writers, radio_heard, bus_heard, rss_warm or rss_end, rss_end, args)


def report(node: Node, honest: Writers, counts: dict[str, int], radio_writers: list[Any], radio_heard: list[Any],
           bus_heard: Heard, rss_warm: float, rss_end: float, args: argparse.Namespace) -> int:
    stats = {link.name: node.stats()[link.name] for link in node.links}  # the links (stats() adds the engine's)
    engine = node.engine
    assert engine is not None
    outcomes = {o.name: n for o, n in engine.counts.items() if n}
    problems = []

    def check(ok: bool, what: str) -> None:
        if not ok:
            problems.append(what)

    sent = {"bus": honest.sent + counts["flood"] + counts["jump"]}
    sent.update({name: n for name, (n, _) in zip(("radio-a", "radio-b"), radio_writers, strict=True)})
    heard = {"bus": bus_heard.count, "radio-a": radio_heard[0][0], "radio-b": radio_heard[1][0]}
    refusals = {name: {k: v for k, v in c.items() if k in ("drop_jump", "drop_rate", "drop_untrusted", "drop_key")}
                for name, c in stats.items()}
    for name, c in stats.items():
        framing_drops = {k: v for k, v in c.items() if k.startswith("drop_") and k not in refusals[name]}
        check(c["in"] == sent[name], f"{name}: in={c['in']} but its robots sent {sent[name]}")
        check(not framing_drops, f"{name}: framing drops {framing_drops}")
        check(c["out"] == heard[name], f"{name}: out={c['out']} but its far end decoded {heard[name]}")
    total_in = sum(c["in"] for c in stats.values())
    total_refused = sum(sum(r.values()) for r in refusals.values())
    check(total_in == sum(outcomes.values()) + total_refused,
          f"in={total_in} != engine outcomes {sum(outcomes.values())} + refusals {total_refused}")
    honest_total = honest.sent + sum(n for n, _ in radio_writers)
    check(outcomes.get("STORED", 0) == honest_total + 2,  # + the flood's first + the jumper's first
          f"STORED={outcomes.get('STORED', 0)}, expected every honest message + 2 = {honest_total + 2}")
    check(refusals["bus"].get("drop_jump", 0) == counts["jump"] - 1,
          f"drop_jump={refusals['bus'].get('drop_jump', 0)}, expected {counts['jump'] - 1}")
    check(outcomes.get("SAME", 0) + refusals["bus"].get("drop_rate", 0) == counts["flood"] - 1,
          "the flood's repeats are not all SAME or drop_rate")
    finals = dict(honest.last)
    for _, last in radio_writers:
        finals.update(last)
    # The bus is one broadcast domain: its robots heard each other's writes; the gateway owes it the radios'.
    from_radios = {key: entry for key, entry in finals.items() if key not in honest.last}
    for name, view, due in (("bus", bus_heard.newest, from_radios), ("radio-a", radio_heard[0][1], finals),
                            ("radio-b", radio_heard[1][1], finals)):
        missing = [key for key, entry in due.items() if view.get(key) != entry]
        check(not missing, f"{name}: {len(missing)} of {len(due)} keys do not hold their last write "
                           f"(e.g. key {missing[:1]})")
    growth = rss_end - rss_warm
    check(growth <= args.max_growth, f"resident memory grew {growth:.1f} MB after warm-up")

    print(f"offered: {sum(sent.values()):,} messages in {args.seconds:.0f} s "
          f"({sum(sent.values()) / args.seconds:,.0f}/s); flood {counts['flood']:,}, jumps {counts['jump']}")
    for name, c in stats.items():
        print(f"  {name}: {c.summary()}")
    print(f"  engine: {' '.join(f'{k}={v}' for k, v in outcomes.items())}")
    print(f"resident memory: {rss_warm:.1f} MB after warm-up, {rss_end:.1f} MB at the end: "
          f"growth {growth:+.1f} MB")
    if problems:
        print("soak FAILED:\n  " + "\n  ".join(problems))
        return 1
    print(f"soak ok: 0 lost, counters consistent, {len(finals)} keys hold their last write on every medium")
    return 0


if __name__ == "__main__":
    sys.exit(main())
