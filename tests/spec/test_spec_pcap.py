"""The pcap writer and reader (LINKTYPE_CAN_SOCKETCAN): round trips, python-can registration, bad files."""

from __future__ import annotations

import io
import os
import random
import struct
from pathlib import Path

import can
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vstig_hw.capture.pcap import LINKTYPE_CAN_SOCKETCAN, PcapError, PcapReader, PcapWriter


def random_frames(rng: random.Random, n: int) -> list[can.Message]:
    frames = []
    for i in range(n):
        extended = rng.random() < 0.5
        kind = rng.random()
        common = {"timestamp": 1_700_000_000 + i * 0.001 + rng.randrange(1000) * 1e-6,
                  "arbitration_id": rng.randrange(1 << 29 if extended else 1 << 11), "is_extended_id": extended}
        if kind < 0.1:
            frames.append(can.Message(**common, is_remote_frame=True, dlc=rng.randrange(9)))
        elif kind < 0.3:
            frames.append(can.Message(**common, is_fd=True, bitrate_switch=rng.random() < 0.5,
                                      error_state_indicator=rng.random() < 0.2,
                                      data=rng.randbytes(rng.choice((8, 12, 16, 24, 32, 48, 64)))))
        else:
            frames.append(can.Message(**common, data=rng.randbytes(rng.randrange(9))))
    return frames


def test_round_trip(tmp_path: Path) -> None:
    frames = random_frames(random.Random(8), 500)
    path = tmp_path / "x.pcap"
    with PcapWriter(path) as writer:
        for frame in frames:
            writer.on_message_received(frame)
    with PcapReader(path) as reader:
        back = list(reader)
    assert len(back) == len(frames)
    for sent, got in zip(frames, back, strict=True):
        assert sent.equals(got, timestamp_delta=1e-6, check_channel=False, check_direction=False), (sent, got)


def test_file_layout_by_hand(tmp_path: Path) -> None:
    """One 11-bit and one 29-bit frame, checked byte by byte against the link-type 227 layout."""
    path = tmp_path / "x.pcap"
    with PcapWriter(path) as writer:
        writer.on_message_received(can.Message(timestamp=2.5, arbitration_id=0x6A5, is_extended_id=False,
                                               data=bytes.fromhex("8102abcd800000ff")))
        writer.on_message_received(can.Message(timestamp=3.0, arbitration_id=0x18071234, data=b"\x01"))
    raw = path.read_bytes()
    assert raw[:4] == bytes.fromhex("d4c3b2a1") and struct.unpack("<I", raw[20:24])[0] == LINKTYPE_CAN_SOCKETCAN
    first = raw[24:24 + 16 + 16]
    assert first[:16] == struct.pack("<IIII", 2, 500000, 16, 16)
    assert first[16:] == bytes.fromhex("000006a5" "08" "00" "0000" "8102abcd800000ff")
    second = raw[24 + 32:]
    assert second[16:] == bytes.fromhex("98071234" "01" "00" "0000" "0100000000000000")  # EFF flag set


def test_python_can_picks_pcap_by_extension(tmp_path: Path) -> None:
    frames = random_frames(random.Random(9), 20)
    path = tmp_path / "x.pcap"
    logger = can.Logger(str(path))
    assert isinstance(logger, PcapWriter)
    for frame in frames:
        logger.on_message_received(frame)
    logger.stop()
    back = list(can.LogReader(str(path)))
    assert [m.arbitration_id for m in back] == [m.arbitration_id for m in frames]


def test_reads_big_endian_nanosecond_files() -> None:
    body = bytes.fromhex("00000123" "02" "00" "0000" "abcd000000000000")
    data = struct.pack(">IHHiIII", 0xA1B23C4D, 2, 4, 0, 0, 72, 227) + struct.pack(">IIII", 5, 250_000_000, 16, 16)
    data += body
    (msg,) = list(PcapReader(io.BytesIO(data)))
    assert (msg.timestamp, msg.arbitration_id, msg.is_extended_id, bytes(msg.data)) == (5.25, 0x123, False, b"\xab\xcd")


@pytest.mark.parametrize(("data", "problem"), [
    (b"", "not a pcap file"),
    (b"\x00" * 24, "not a pcap file"),
    (struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 72, 1), "link type 1"),
    (struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 72, 227) + b"\x01\x02", "cut short"),
    (struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 72, 227) + struct.pack("<IIII", 0, 0, 16, 16)
     + bytes.fromhex("00000123" "40" "00" "0000") + bytes(8), "claims 64"),
])
def test_bad_files_name_the_problem(data: bytes, problem: str) -> None:
    source = io.BytesIO(data)
    source.name = "bad.pcap"
    with pytest.raises(PcapError, match=f"bad.pcap: .*{problem}"):
        list(PcapReader(source))


@given(st.binary(max_size=200))
def test_fuzzed_files_give_frames_or_a_clear_error(tail: bytes) -> None:
    data = struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 72, 227) + tail
    try:
        for msg in PcapReader(io.BytesIO(data)):
            assert isinstance(msg, can.Message)
    except PcapError:
        pass


def test_pcapng_from_wiresharks_own_editcap_reads_the_same_frames(tmp_path: Path) -> None:
    import shutil
    import subprocess

    from vstig_hw.capture.records import read_capture

    editcap = shutil.which("editcap")
    if editcap is None:
        if os.environ.get("VSTIG_REQUIRE_PEERS") == "1":
            pytest.fail("VSTIG_REQUIRE_PEERS=1 but editcap (wireshark-common, with tshark) is missing")
        pytest.skip("editcap (wireshark-common, installed with tshark) is missing")
    frames = random_frames(random.Random(9), 300)
    pcap, pcapng = tmp_path / "x.pcap", tmp_path / "x.pcapng"
    with PcapWriter(pcap) as writer:
        for frame in frames:
            writer.on_message_received(frame)
    done = subprocess.run([editcap, "-F", "pcapng", str(pcap), str(pcapng)], capture_output=True, text=True,
                          check=False)
    assert done.returncode == 0, done.stderr
    assert pcapng.read_bytes()[:4] == bytes.fromhex("0a0d0d0a")
    back = [record.unit for record in read_capture(str(pcapng))]
    assert len(back) == len(frames)
    for sent, got in zip(frames, back, strict=True):
        assert sent.equals(got, timestamp_delta=1e-6, check_channel=False, check_direction=False), (sent, got)


def _block(kind: int, body: bytes) -> bytes:
    body += b"\0" * (-len(body) % 4)
    return struct.pack("<II", kind, len(body) + 12) + body + struct.pack("<I", len(body) + 12)


def test_pcapng_by_hand_nanoseconds_and_a_foreign_interface(tmp_path: Path) -> None:
    from vstig_hw.capture.pcap import PcapngReader

    frame = bytes.fromhex("000006a5" "08" "00" "0000" "8102abcd800000ff")
    ns = struct.pack("<HHB3x", 9, 1, 9) + struct.pack("<HH", 0, 0)  # if_tsresol = 10^-9, end of options
    stamp = 1_700_000_000_123_456_789
    packets = [_block(6, struct.pack("<IIIII", interface, stamp >> 32, stamp & 0xFFFFFFFF, len(frame), len(frame))
                      + frame) for interface in (1, 0)]
    path = tmp_path / "x.pcapng"
    path.write_bytes(_block(0x0A0D0D0A, struct.pack("<IHHq", 0x1A2B3C4D, 1, 0, -1))
                     + _block(1, struct.pack("<HHI", LINKTYPE_CAN_SOCKETCAN, 0, 0) + ns)
                     + _block(1, struct.pack("<HHI", 1, 0, 0))  # an Ethernet interface: its packets are skipped
                     + b"".join(packets))
    with PcapngReader(path) as reader:
        (got,) = list(reader)
        assert reader.skipped == 1
    assert got.arbitration_id == 0x6A5 and got.data == bytes.fromhex("8102abcd800000ff")
    assert got.timestamp == pytest.approx(1_700_000_000.123456789, abs=1e-6)
    path.write_bytes(path.read_bytes()[:-10])
    with pytest.raises(PcapError, match="cut short"), PcapngReader(path) as reader:
        list(reader)
