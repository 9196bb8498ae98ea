"""The mavlink framing against pymavlink, MAVLink's own library: every frame we send it decodes (signed and
unsigned), every TUNNEL it sends we decode, and what is not ours is dropped and counted by reason."""

from __future__ import annotations

import hashlib
import os
import struct
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v10 import common as mav1
from pymavlink.dialects.v20 import common as mav2

from vstig_hw.counters import Counters
from vstig_hw.framing.mavlink import (
    MAX_PER_TUNNEL,
    PAYLOAD_TYPE,
    STREAMS_KEPT,
    MavlinkFraming,
    MavlinkStreamReader,
    Signing,
)
from vstig_hw.inputs import InputFileError
from vstig_hw.links import parse
from vstig_hw.links.mavlink import read_key
from vstig_hw.wire import Message, Op

KEY = hashlib.sha256(b"lab swarm").digest()
OTHER_KEY = hashlib.sha256(b"not the lab's").digest()


class _Sink:
    def write(self, data: bytes) -> None:
        pass


def ground_station(sysid: int = 255, compid: int = 190, key: bytes | None = None, link_id: int = 0,
                   stamp: int | None = None) -> Any:
    """pymavlink's MAVLink 2 encoder and parser, signing with `key` when given."""
    mav = mav2.MAVLink(_Sink(), srcSystem=sysid, srcComponent=compid)
    if key is not None:
        mav.signing.secret_key = key
        mav.signing.link_id = link_id
        mav.signing.sign_outgoing = True
        if stamp is not None:
            mav.signing.timestamp = stamp
    return mav


def messages(count: int, robot: int = 7) -> list[Message]:
    return [Message(Op(k % 2), k, k * 3 + 1, k % 65536, robot) for k in range(1, count + 1)]


def their_tunnel(mav: Any, data: bytes, payload_type: int = PAYLOAD_TYPE, target: int = 0) -> bytes:
    return bytes(mav2.MAVLink_tunnel_message(target, 0, payload_type, len(data),
                                             list(data) + [0] * (128 - len(data))).pack(mav))


def packed(msgs: list[Message]) -> bytes:
    return b"".join(struct.pack(">HHHH", *m) for m in msgs)


@pytest.mark.parametrize("signed", [False, True])
@pytest.mark.parametrize("count", [1, 15, 16, 17, 40])
def test_pymavlink_decodes_every_tunnel_and_heartbeat_we_send(signed: bool, count: int) -> None:
    framing = MavlinkFraming(12, signing=Signing(KEY, link_id=3) if signed else None)
    units = framing.encode_batch(messages(count)) if count > 1 else framing.encode(messages(1)[0])
    assert len(units) == -(-count // MAX_PER_TUNNEL)
    parser = ground_station(key=KEY if signed else None)
    carried = b""
    for seq, unit in enumerate(units):
        (frame,) = parser.parse_buffer(unit)
        assert frame.get_type() == "TUNNEL" and frame.get_srcSystem() == 12 and frame.get_srcComponent() == 191
        assert frame.get_seq() == seq and frame.get_signed() == signed
        assert (frame.payload_type, frame.target_system, frame.target_component) == (PAYLOAD_TYPE, 0, 0)
        carried += bytes(frame.payload[:frame.payload_length])
    assert carried == packed(messages(count))
    (beat,) = parser.parse_buffer(framing.heartbeat())
    assert (beat.get_type(), beat.type, beat.autopilot, beat.get_signed()) == ("HEARTBEAT", 18, 8, signed)
    assert beat.type == mav2.MAV_TYPE_ONBOARD_CONTROLLER and beat.autopilot == mav2.MAV_AUTOPILOT_INVALID


def test_a_signed_frame_fails_pymavlinks_check_under_another_key() -> None:
    unit = MavlinkFraming(12, signing=Signing(KEY)).encode(messages(1)[0])[0]
    with pytest.raises(mav2.MAVError, match="Invalid signature"):
        ground_station(key=OTHER_KEY).parse_buffer(unit)
    assert ground_station(key=KEY).parse_buffer(unit)[0].get_type() == "TUNNEL"


@pytest.mark.parametrize("signed", [False, True])
def test_we_decode_pymavlinks_tunnels_and_name_their_sender(signed: bool) -> None:
    sent = messages(16, robot=9)
    ours = MavlinkFraming(4, signing=Signing(KEY) if signed else None)
    theirs = ground_station(sysid=9, compid=1, key=KEY if signed else None, link_id=2)
    for count in (1, 8, 16):
        unit = their_tunnel(theirs, packed(sent[:count]))
        assert ours.feed(unit) == sent[:count]
        assert ours.sender_of(unit) == 9 << 8 | 1
    assert not ours.drops


def _drops_of(units: list[bytes], framing: MavlinkFraming) -> tuple[list[Message], dict[str, int]]:
    heard = [m for unit in units for m in framing.feed(unit)]
    return heard, dict(framing.drops)


def test_with_a_key_unsigned_forged_and_replayed_frames_are_dropped_and_counted() -> None:
    ours = MavlinkFraming(4, signing=Signing(KEY))
    honest = ground_station(sysid=9, key=KEY, stamp=1_000_000_000)
    good = their_tunnel(honest, packed(messages(2)))
    forged = their_tunnel(ground_station(sysid=9, key=OTHER_KEY, stamp=2_000_000_000), packed(messages(2)))
    unsigned = their_tunnel(ground_station(sysid=9), packed(messages(2)))
    tampered = bytearray(good)
    tampered[-1] ^= 1
    heard, drops = _drops_of([good, good, forged, unsigned, bytes(tampered)], ours)
    assert heard == messages(2)
    assert drops == {"replay": 1, "signature": 2, "unsigned": 1}


def test_replay_is_per_stream_and_an_old_new_stream_is_a_replay() -> None:
    ours = MavlinkFraming(4, signing=Signing(KEY))
    base = 5_000_000_000
    a = ground_station(sysid=9, key=KEY, link_id=1, stamp=base)
    b = ground_station(sysid=9, key=KEY, link_id=2, stamp=base - 100)  # another link id: its own stream
    late = ground_station(sysid=10, key=KEY, stamp=base - 7_000_000)  # a new stream starting 70 s behind
    units = [their_tunnel(a, packed(messages(1))), their_tunnel(b, packed(messages(1))),
             their_tunnel(late, packed(messages(1)))]
    heard, drops = _drops_of(units, ours)
    assert len(heard) == 2 and drops == {"replay": 1}


def test_the_stream_table_is_bounded() -> None:
    signing = Signing(KEY)
    framing = MavlinkFraming(4, signing=signing)
    stamp = 9_000_000_000
    for sysid in range(1, 256):
        for link_id in range(6):
            mav = ground_station(sysid=sysid, key=KEY, link_id=link_id, stamp=stamp)
            stamp += 1
            assert framing.feed(their_tunnel(mav, packed(messages(1))))
    assert len(signing._heard) == STREAMS_KEPT


def test_mavlink1_other_messages_other_payload_types_and_targets_are_counted_never_taken() -> None:
    ours = MavlinkFraming(4)
    them = ground_station(sysid=9)
    v1 = mav1.MAVLink(_Sink(), srcSystem=9, srcComponent=1)
    units = [
        bytes(mav1.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3).pack(v1)),
        bytes(mav2.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(them)),
        bytes(mav2.MAVLink_param_request_list_message(4, 191).pack(them)),
        their_tunnel(them, packed(messages(1)), payload_type=PAYLOAD_TYPE - 1),
        their_tunnel(them, packed(messages(1)), target=5),  # for system 5, not us
        their_tunnel(them, packed(messages(1)), target=4),  # for us
        their_tunnel(them, packed(messages(1))[:7]),  # not whole messages
    ]
    heard, drops = _drops_of(units, ours)
    assert heard == messages(1)
    assert drops == {"mavlink1": 1, "other_message": 2, "other_payload_type": 1, "not_for_us": 1, "bad_length": 1}


def test_the_stream_reader_resynchronises_after_noise_bad_crc_and_truncation() -> None:
    them = ground_station(sysid=9)
    good = their_tunnel(them, packed(messages(3)))
    bad_crc = bytearray(good)
    bad_crc[12] ^= 0x40
    flags = bytearray(good)
    flags[2] = 0x02
    drops = Counters()
    reader = MavlinkStreamReader(drops)
    stream = b"noise" + good + bytes(bad_crc) + bytes(flags) + good + good[:20]
    frames = []
    for i in range(0, len(stream), 7):  # byte runs as a UART delivers them
        frames += reader.feed(stream[i:i + 7])
    frames += reader.flush()
    assert frames == [good, good]
    assert dict(drops) == {"noise": 1, "crc": 1, "incompat_flags": 1, "truncated": 1}


def test_a_unit_holding_a_broken_frame_never_raises() -> None:
    framing = MavlinkFraming(4)
    rng = __import__("random").Random(49)
    good = their_tunnel(ground_station(sysid=9), packed(messages(16)))
    for _ in range(2000):
        unit = bytearray(good[:rng.randrange(1, len(good) + 1)])
        for _ in range(rng.randrange(4)):
            unit[rng.randrange(len(unit))] = rng.randrange(256)
        framing.feed(bytes(unit))
    assert sum(framing.drops.values()) > 0


def test_a_capture_filter_keeps_the_tunnels_sender() -> None:
    framing = MavlinkFraming(4)
    unit = their_tunnel(ground_station(sysid=9, compid=3), packed(messages(4)))
    narrowed = framing.narrow(unit, messages(4)[1:2])
    assert narrowed is not None
    assert framing.feed(narrowed) == messages(4)[1:2] and framing.sender_of(narrowed) == 9 << 8 | 3


def _key_file(tmp_path: Path, text: str, mode: int = 0o600) -> str:
    path = tmp_path / "swarm.key"
    path.write_text(text)
    os.chmod(path, mode)
    return str(path)


def test_key_files_hex_or_passphrase_and_their_mode_is_checked(tmp_path: Path) -> None:
    assert read_key(_key_file(tmp_path, KEY.hex() + "\n")) == KEY
    assert read_key(_key_file(tmp_path, "lab swarm\n")) == KEY  # MAVProxy's `signing setup`: SHA-256 of it
    with pytest.raises(InputFileError, match=r"swarm.key: .*readable or writable by others.*chmod 600"):
        read_key(_key_file(tmp_path, "lab swarm", 0o644))
    with pytest.raises(InputFileError, match="is empty"):
        read_key(_key_file(tmp_path, "\n"))
    with pytest.raises(InputFileError, match="regular file"):
        read_key(str(tmp_path))


@pytest.mark.parametrize(("spec", "problem"), [
    ("mavlink:tcp:127.0.0.1:5760", "serial:, udpin: or udpout:"),
    ("mavlink:udpin:14550", "needs <host>:<port>"),
    ("mavlink:udpout:127.0.0.1:99999", "port=99999 is outside"),
    ("mavlink:udpout:127.0.0.1:14550?baud=57600", "baud= is for mavlink:serial:"),
    ("mavlink:serial:/dev/ttyUSB0?sysid=0", "sysid=0 is outside 1..255"),
    ("mavlink:serial:/dev/ttyUSB0?air_rte=64000", "did you mean air_rate?"),
])
def test_bad_specs_name_the_bad_part(spec: str, problem: str) -> None:
    with pytest.raises(ValueError, match=problem.replace("?", r"\?").replace("(", r"\(")):
        parse(spec)


def test_a_link_needs_a_sysid_and_warns_without_a_key(caplog: pytest.LogCaptureFixture) -> None:
    spec = parse("mavlink:udpout:127.0.0.1:14550")
    with pytest.raises(ValueError, match=r"no MAVLink sysid.*--robot-id 1\.\.255 or sysid="):
        spec.build(robot_id=0)
    link = spec.build(robot_id=7)
    assert link.framing.sysid == 7  # type: ignore[attr-defined]
    assert "not signed (no key=)" in caplog.text
    listener = spec.build(robot_id=0, listen_only=True)
    assert listener.transport.heartbeat is None  # type: ignore[attr-defined]
