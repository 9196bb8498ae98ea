"""libvstig's MAVLink part (vstig_mavlink.[ch]) against vectors/mavlink.json, plain and under ASan+UBSan,
and against the Python framing on random hostile streams (the differential test)."""

from __future__ import annotations

import random
import subprocess
from pathlib import Path
from typing import Any

import pytest
from conftest import BUILDS, C_DIR, STRICT_FLAGS, Driver, load
from required import require_tool

from vstig_hw.auth import SwarmKeys, encode_record
from vstig_hw.counters import Counters
from vstig_hw.framing.mavlink import MavlinkFraming, MavlinkStreamReader, Signing
from vstig_hw.wire import Message, Op, encode

VECTORS_OF = load("mavlink.json")
ORDER = ["noise", "incompat_flags", "crc", "truncated", "mavlink1", "unsigned", "signature", "replay",
         "other_message", "other_payload_type", "not_for_us", "bad_length"]  # vstig_mavlink_drop_t's order


@pytest.fixture(scope="module", params=sorted(BUILDS))
def mavlink_driver(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Driver:
    gcc = require_tool("gcc")
    exe = tmp_path_factory.mktemp("c") / f"mavlink_driver_{request.param}"
    sources = [*sorted(map(str, C_DIR.glob("vstig_*.c"))), str(C_DIR / "tests" / "mavlink_driver.c")]
    done = subprocess.run([gcc, *STRICT_FLAGS, *BUILDS[request.param], "-I", str(C_DIR), "-o", str(exe), *sources],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, f"gcc {request.param} build failed:\n{done.stderr}"
    return Driver(Path(exe))


def _result(frames: list[dict[str, Any]], drops: dict[str, int]) -> str:
    """The driver's line: a tagged TUNNEL's messages as MSG/RECORD."""
    shown = ";".join(f"{f['sender']}=" + ",".join(
        f"{m}/{r}" for m, r in zip(f["messages"], f["records"], strict=True)) if "records" in f
        else f"{f['sender']}={','.join(f['messages'])}" for f in frames) or "-"
    return f"{shown} drops={','.join(f'{n}:{drops[n]}' for n in ORDER if drops.get(n)) or '-'}"


def test_transmit_and_heartbeat(mavlink_driver: Driver) -> None:
    cases = VECTORS_OF["transmit"]
    commands = [f"tx {c['sysid']} {c['compid']} {c['key'] or '-'} {c['link_id']} "
                f"{(max(c['timestamp'] - 1, 0)).to_bytes(6, 'little').hex()} {','.join(c['messages'])}" for c in cases]
    tagged = VECTORS_OF["transmit_tagged"]
    commands += [f"txt {c['sysid']} {c['compid']} {c['key'] or '-'} {c['link_id']} "
                 f"{(max(c['timestamp'] - 1, 0)).to_bytes(6, 'little').hex()} {''.join(c['records'])}" for c in tagged]
    beat = VECTORS_OF["heartbeat"]
    out = mavlink_driver.run([*commands, f"hb {beat['sysid']} {beat['compid']}"])
    assert out == [c["wire"] for c in cases + tagged] + [beat["wire"]]


def test_streams_whole_and_byte_by_byte(mavlink_driver: Driver) -> None:
    receiver = VECTORS_OF["receiver"]
    commands, wanted = [], []
    for case in VECTORS_OF["streams"]:
        stream = case["stream"]
        for chunks in ([stream], [stream[i:i + 2] for i in range(0, len(stream), 2)]):
            commands.append(f"rx {receiver['sysid']} {receiver['compid']} {case['key'] or '-'} {' '.join(chunks)}")
            wanted.append(_result(case["frames"], case["drops"]))
    assert mavlink_driver.run(commands) == wanted


def _python(stream: bytes, key: bytes | None) -> str:
    framing = MavlinkFraming(4, 191, signing=None if key is None else Signing(key))
    drops = Counters()
    reader = MavlinkStreamReader(drops)
    frames = []
    for unit in reader.feed(stream) + reader.flush():
        heard = framing.feed_tagged(unit)
        if heard:
            sender = framing.sender_of(unit) or 0
            frames.append({"sender": f"{sender >> 8}/{sender & 0xFF}", "messages": [encode(m).hex() for m, _ in heard]}
                          | ({"records": [encode_record(r).hex() for _, r in heard if r]} if heard[0][1] else {}))
    drops.update(framing.drops)
    return _result(frames, dict(drops))


_KEYS = SwarmKeys(bytes(range(32, 64)))


def _hostile_stream(rng: random.Random, key: bytes | None) -> bytes:
    """Frames of every kind (ours, tagged or not, signed or not, other messages, MAVLink 1), mangled, cut and glued
    with noise."""
    sender = MavlinkFraming(rng.randrange(1, 256), rng.choice((1, 191)), target=rng.choice((0, 0, 4, 5)),
                            signing=Signing(key) if key and rng.random() < 0.8 else None)
    parts = []
    for _ in range(rng.randrange(1, 8)):
        kind = rng.random()
        if kind < 0.6:
            msgs = [Message(Op(rng.randrange(2)), rng.randrange(32768), rng.randrange(65536), rng.randrange(65536),
                            rng.randrange(65536)) for _ in range(rng.randrange(1, 17))]
            unit = sender.encode_tagged([_KEYS.tag(m, rng.randrange(3)) for m in msgs[:6]])[0] if rng.random() < 0.3 \
                else sender.encode_batch(msgs)[0]
        elif kind < 0.75:
            unit = sender.heartbeat()
        elif kind < 0.85:
            unit = bytes([0xFE, 3, 0, 1, 1, 0, 1, 2, 3, 0x11, 0x22])
        else:
            unit = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 30)))
        unit = bytearray(unit)
        if rng.random() < 0.3 and unit:
            unit[rng.randrange(len(unit))] = rng.randrange(256)
        if rng.random() < 0.15 and unit:
            del unit[rng.randrange(len(unit)):]
        if rng.random() < 0.1 and parts:
            parts.append(parts[-1])  # the same frame again: a replay with a key
        parts.append(bytes(unit))
    return b"".join(parts)


@pytest.mark.parametrize("keyed", [False, True])
def test_c_and_python_agree_on_hostile_streams(mavlink_driver: Driver, keyed: bool) -> None:
    rng = random.Random(49 + keyed)
    key = bytes(range(32)) if keyed else None
    streams = [_hostile_stream(rng, key) for _ in range(300)]
    out = mavlink_driver.run(f"rx 4 191 {key.hex() if key else '-'} {s.hex() or '-'}" for s in streams)
    assert out == [_python(s, key) for s in streams]
