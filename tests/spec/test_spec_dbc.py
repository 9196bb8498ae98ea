"""firmware_spec/vstig.dbc read by cantools decodes our frames exactly as our decoder does."""

from __future__ import annotations

import random
import subprocess
import sys
from pathlib import Path

import cantools
import pytest
from conftest import SPEC, VECTORS, can_id_fields, load

from vstig_hw import decode

DBC = SPEC / "vstig.dbc"
MASK = 0x1E010700  # documented in the DBC generator and SPEC.md


@pytest.fixture(scope="module")
def db() -> cantools.database.can.Database:
    return cantools.database.load_file(str(DBC), frame_id_mask=MASK)


def _expect(can_id: int, extended: bool, data: bytes) -> dict[str, object]:
    """Our decoder: the wire codec on the payload, the ID scheme on the ID."""
    msg = decode(data)
    return {"op": msg.op.name, "key": msg.key, "value": msg.value, "timestamp": msg.timestamp,
            "robot_id": msg.robot, "id_op": ("PUT", "GET")[can_id_fields(can_id, extended)["op"]]}


def _cantools(db: cantools.database.can.Database, can_id: int, extended: bool, data: bytes) -> dict[str, object]:
    message = db.get_message_by_frame_id(can_id, force_extended_id=extended)
    signals = message.decode(data)
    return {**{name: str(v) if name == "op" else v for name, v in signals.items()},
            "id_op": "GET" if "_GET" in message.name else "PUT"}


def test_dbc_is_what_the_generator_writes(tmp_path: Path) -> None:
    out = tmp_path / "vstig.dbc"
    subprocess.run([sys.executable, str(SPEC / "tools" / "make_dbc.py"), str(out)], check=True, timeout=60)
    assert out.read_text(encoding="utf-8") == DBC.read_text(encoding="utf-8")


def test_vectors(db: cantools.database.can.Database) -> None:
    frames = load("can_frames.json")["frames"]
    if (VECTORS / "can.json").exists():  # the CAN framing's own vectors, once merged
        frames += [f for f in load("can.json")["frames"] if f["drop"] is None and not f["fd"]
                   and f["scheme"] in ("std600", "ext18", "ext18s3")]
    for frame in frames:
        can_id, data = int(frame["id"], 16), bytes.fromhex(frame["data"])
        assert _cantools(db, can_id, frame["extended"], data) == _expect(can_id, frame["extended"], data), frame["name"]
        fields = can_id_fields(can_id, frame["extended"])
        assert fields["sender"] == frame["sender"], frame["name"]
        if "stigmergy" in frame:
            assert fields["stigmergy"] == frame["stigmergy"]


def test_random_frames(db: cantools.database.can.Database) -> None:
    rng = random.Random(7)
    for _ in range(5000):
        extended = rng.random() < 0.5
        op = rng.randrange(2)
        if extended:
            can_id = 0x18000000 | rng.randrange(256) << 17 | op << 16 | rng.randrange(0x10000)
        else:
            can_id = 0x600 | op << 8 | rng.randrange(256)
        data = bytes([(op << 7) | rng.randrange(128)]) + rng.randbytes(7)
        assert _cantools(db, can_id, extended, data) == _expect(can_id, extended, data), hex(can_id)


def test_cantools_cli_decodes_a_candump_line() -> None:
    line = "  vcan0  7A5   [8]  81 02 AB CD 80 00 00 FF\n"
    done = subprocess.run([str(Path(sys.executable).with_name("cantools")), "decode", "--frame-id-mask", hex(MASK),
                           str(DBC)], input=line, capture_output=True, text=True, timeout=60, check=True)
    assert "VSTIG_GET(" in done.stdout and "key: 258" in done.stdout and "robot_id: 255" in done.stdout
