"""The guard's cost per message, beside the engine's (issue 11: the gateway as the swarm's firewall)."""

from __future__ import annotations

from collections.abc import Iterator

from vstig_hw import Stigmergy
from vstig_hw.counters import Counters
from vstig_hw.gateway.guard import Guard, IdSet, LinkPolicy

from .bench_wire import realistic_mix
from .registry import Result, benchmark, rate

_N = 50_000


@benchmark("gateway")
def guard() -> Iterator[Result]:
    """Messages/s through `Guard.filter`, one at a time as the gateway hands them over, with the default
    policy (max jump) and with every policy on, beside `Stigmergy.receive` on the same traffic: the
    guard sits in front of the engine, so the ratio is what it adds to each message's cost."""
    messages = realistic_mix(_N)
    senders = [m.robot % 40 for m in messages]
    every = {"can": LinkPolicy(trust=IdSet.parse("0-39", 0xFFFF), deny=IdSet.parse("41", 0xFFFF),
                               keys=IdSet.parse("0-99", 0x7FFF))}

    def through(**kwargs: object) -> int:
        g = Guard(**kwargs)  # type: ignore[arg-type]
        counters = Counters()
        now = 0.0
        for msg, sender in zip(messages, senders, strict=True):
            now += 1e-4
            g.filter("can", sender, [msg], now, counters)
        return _N

    def engine() -> int:
        s = Stigmergy(200)
        receive = s.receive
        for msg in messages:
            receive(msg)
        s.drain()
        return _N

    engine_rate = rate(engine)
    yield Result("gateway.guard_default", rate(lambda: through()), "msg/s", "Stigmergy.receive", engine_rate)
    yield Result("gateway.guard_every_policy", rate(lambda: through(rate=1000, flap=5, links=every)),
                 "msg/s", "Stigmergy.receive", engine_rate)
