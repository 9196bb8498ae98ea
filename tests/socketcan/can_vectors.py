"""firmware_spec/vectors/can.json as python-can frames and expected Messages (shared by the CAN tests)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import can

from vstig_hw import Message, Op
from vstig_hw.framing.can import CanIdScheme

VECTORS_PATH = Path(__file__).resolve().parents[2] / "firmware_spec" / "vectors" / "can.json"


@dataclass(frozen=True)
class FrameVector:
    name: str
    scheme: CanIdScheme
    frame: can.Message
    cansend: str
    sender: int | None
    drop: str | None
    messages: list[Message]


def _scheme(spec: dict[str, object]) -> CanIdScheme:
    return CanIdScheme(extended=bool(spec["extended"]), base=int(str(spec["base"]), 16),
                       stigmergy=int(str(spec["stigmergy"])))


def load() -> list[FrameVector]:
    doc = json.loads(VECTORS_PATH.read_text())
    schemes = {name: _scheme(spec) for name, spec in doc["schemes"].items()}
    vectors = []
    for v in doc["frames"]:
        frame = can.Message(arbitration_id=int(v["id"], 16), is_extended_id=v["extended"], is_fd=v["fd"],
                            bitrate_switch=v["fd"], is_remote_frame=v.get("remote", False),
                            data=bytes.fromhex(v["data"]))
        messages = [Message(Op[m["op"]], m["key"], m["value"], m["timestamp"], m["robot"]) for m in v["messages"]]
        vectors.append(FrameVector(v["name"], schemes[v["scheme"]], frame, v["cansend"], v["sender"], v["drop"],
                                   messages))
    return vectors

