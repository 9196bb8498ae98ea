"""libvstig's vstig_tagged against vstig_hw.tagged.TaggedStigmergy, its Python reference: the same random traffic
(honest tagged writes across the timestamp wrap, forgeries, replays, untagged writes, GETs, the node's own puts,
under every policy) gives the same results, refusals, drained messages and records, command by command."""

from __future__ import annotations

import random
import subprocess

import pytest
from conftest import BUILDS, C_DIR, STRICT_FLAGS, Driver
from required import require_tool

from vstig_hw.auth import SwarmKeys, Tagged
from vstig_hw.engine import Outcome, Stigmergy
from vstig_hw.tagged import AuthPolicy, Refusal, TaggedStigmergy
from vstig_hw.timestamps import next_timestamp
from vstig_hw.wire import Message, Op, encode

MASTER = bytes(range(0xA0, 0xC0))
NODE, STIGMERGY = 200, 3
POLICIES = list(AuthPolicy)  # the C enum's order: require, prefer, off
REFUSALS = {Refusal.UNTAGGED: 16, Refusal.BAD_TAG: 17}


# The gateway's build (vstig_hw._vstig): every key its own place, and writers' prepared keys cached.
TAGGED_BUILDS = {**BUILDS, "gateway": ["-O2", "-DVSTIG_KEYS=32768u", "-DVSTIG_WRITER_KEYS=4u"]}


@pytest.fixture(scope="module", params=sorted(TAGGED_BUILDS))
def tagged_driver(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Driver:
    gcc = require_tool("gcc")
    exe = tmp_path_factory.mktemp("tagged") / f"tagged_{request.param}"
    sources = [*sorted(C_DIR.glob("vstig_*.c")), C_DIR / "tests" / "tagged_driver.c"]
    done = subprocess.run([gcc, *STRICT_FLAGS, *TAGGED_BUILDS[request.param], "-I", str(C_DIR), "-o", str(exe),
                           *map(str, sources)], capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, f"gcc {request.param} build failed:\n{done.stderr}"
    return Driver(exe)


def _scenario(seed: int, steps: int = 400) -> tuple[list[str], list[str]]:
    """(driver commands, the lines the Python reference gives for them)."""
    rng = random.Random(seed)
    keys = SwarmKeys(MASTER, STIGMERGY)
    node = TaggedStigmergy(Stigmergy(NODE), keys)
    clocks = {key: (0, rng.choice([0, 65520])) for key in range(4)}  # (epoch, timestamp) of the honest writes
    heard: list[Tagged] = []
    commands, lines = [f"init {NODE} {STIGMERGY} {MASTER.hex()}"], ["ok"]

    def result(value: Outcome | Refusal) -> str:
        return str(REFUSALS[value] if isinstance(value, Refusal) else int(value))

    for _ in range(steps):
        roll, key = rng.random(), rng.randrange(4)
        policy = rng.choice(POLICIES)
        if roll < 0.1:
            value = rng.randrange(1 << 16)
            node.put(key, value)
            commands.append(f"put {key} {value}")
            lines.append("0")
            continue
        if roll < 0.2:
            drained = node.engine.drain()
            commands.append("drain")
            shown = []
            for msg in drained:
                record = node.record_of(msg)
                proof = "-" if record is None else f"{record.epoch}/{record.tag.hex()}"
                shown.append(f"{encode(msg).hex()}/{proof}")
            lines.append(",".join(shown))
            continue
        epoch, ts = clocks[key]
        if roll < 0.55:  # an honest write, tagged by its writer, stepping the epoch at the wrap
            following = next_timestamp(ts)
            epoch, ts = epoch + (1 if ts and following < ts else 0), following
            clocks[key] = (epoch, ts)
            writer = rng.choice([5, 7, 99])
            record = keys.tag(Message(Op.PUT, key, rng.randrange(1 << 16), ts, writer), epoch)
            heard.append(record)
            msg, sent = record.message, record
        elif roll < 0.65 and heard:  # a replay of something heard before, maybe as a GET
            old = rng.choice(heard)
            msg = old.message.replace(op=rng.choice([Op.PUT, Op.GET]))
            sent = Tagged(msg, old.epoch, old.tag)
        elif roll < 0.75:  # a forgery: a guessed tag, or another writer's key
            msg = Message(Op.PUT, key, rng.randrange(1 << 16), next_timestamp(ts), rng.choice([5, 7]))
            sent = Tagged(msg, epoch, bytes(rng.randrange(256) for _ in range(8)))
        elif roll < 0.9:  # untagged, from a robot or a stranger
            msg = Message(rng.choice([Op.PUT, Op.GET]), key, rng.randrange(1 << 16),
                          rng.choice([ts, next_timestamp(ts), 0]), rng.choice([5, 99, 250]))
            outcome = node.receive(msg, policy)
            commands.append(f"recv {POLICIES.index(policy)} {encode(msg).hex()} - -")
            lines.append(result(outcome))
            continue
        else:  # an empty GET
            msg = Message(Op.GET, key, 0, 0, rng.choice([5, 7]))
            sent = Tagged(msg, 0, bytes(8))
        outcome = node.receive(msg, policy, sent.epoch, sent.tag)
        commands.append(f"recv {POLICIES.index(policy)} {encode(msg).hex()} {sent.epoch} {sent.tag.hex()}")
        lines.append(result(outcome))
    refused = {reason: sum(n for (r, _w), n in node.refused.items() if r is reason) for reason in Refusal}
    commands.append("counts")
    lines.append(f"{refused[Refusal.UNTAGGED]} {refused[Refusal.BAD_TAG]} {node.replays}")
    return commands, lines


@pytest.mark.parametrize("seed", range(6))
def test_c_twin_matches_python_on_random_traffic(tagged_driver: Driver, seed: int) -> None:
    commands, expected = _scenario(seed)
    got = tagged_driver.run(commands)
    for command, want, have in zip(commands, expected, got, strict=True):
        assert have == want, f"seed {seed}: {command}"
    assert expected[-1].split() != ["0", "0", "0"], "the traffic refused nothing: the scenario tests too little"
