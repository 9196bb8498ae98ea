"""One fuzz target per parser: bytes in, and only the parser's own error may come out.

Each target takes arbitrary bytes and shapes them into its parser's input (a byte
stream cut into reads, a CAN frame, a line of text, a file, a run of messages for
the guard). A target returns normally for accepted input and for the parser's
defined error (`EXPECTED`); anything else, an exception or a broken invariant,
escapes as a crash. `tests/fuzz/run.py` drives them under atheris (`make fuzz`);
`tests/unit/test_fuzz_targets.py` runs them briefly on random bytes in `make test`.
"""

from __future__ import annotations

import atexit
import contextlib
import io
import logging
import os
import shutil
import struct
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path

import can
from cobs import cobs

from vstig_hw.capture import candump, serial_log
from vstig_hw.capture.fastlog import chunk_to_jsonl
from vstig_hw.capture.pcap import PcapError, PcapReader
from vstig_hw.capture.records import CaptureError
from vstig_hw.capture.rosbag import McapCaptureWriter, read_mcap
from vstig_hw.counters import Counters
from vstig_hw.dialects.bittybuzz import BbzDecodeError, decode_bittybuzz
from vstig_hw.dialects.buzz import BuzzDecodeError, decode_buzz
from vstig_hw.dialects.buzz_packets import xbee_packet
from vstig_hw.dialects.framing import BittyBuzzKilobotFraming, BuzzKh4Framing, RosBuzzDecoder, XbeeMavFraming
from vstig_hw.dialects.mapping import DeploymentError, parse_deployment
from vstig_hw.dialects.xbeemav import fragment_packets
from vstig_hw.framing import TransmitOnlyError, make_serial_framing
from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.framing.xbee import api_frame, receive_packet
from vstig_hw.gateway.guard import Guard, IdSet, LinkPolicy
from vstig_hw.links import examples
from vstig_hw.links import parse as parse_spec
from vstig_hw.wire import DecodeError, Message, decode, decode_many, encode

Target = Callable[[bytes], None]


def wire(data: bytes) -> None:
    try:
        msg = decode(data)
    except DecodeError:
        assert len(data) != 8
    else:
        assert encode(msg) == data  # every 8 bytes are a message, and it encodes back to them
    try:
        assert b"".join(map(encode, decode_many(data))) == data
    except DecodeError:
        assert len(data) % 8


def _reads(data: bytes) -> list[bytes]:
    """The input cut into reads at sizes taken from its first byte, as a UART delivers them."""
    if not data:
        return []
    step = data[0] % 16 + 1
    return [data[i:i + step] for i in range(1, len(data), step)]


def _serial(name: str) -> Target:
    def target(data: bytes) -> None:
        framing = make_serial_framing(name)
        for i, chunk in enumerate(_reads(data)):
            for msg in framing.feed(chunk):
                assert type(msg) is Message
            if i % 7 == 6:
                framing.tick()
    target.__name__ = name.replace("-", "_")
    return target


_STREAM_REASONS = {"noise", "escape", "frame_length", "truncated", "checksum"}


def xbee(data: bytes) -> None:
    """A module's byte stream (API mode 1 or 2, by the first byte's low bit) cut into reads: the transport's
    units are whole frames, so the framing finds nothing wrong with their framing, only with their contents."""
    from vstig_hw.transports.xbee import XBeeTransport

    api = 1 + (data[0] & 1) if data else 1
    transport = XBeeTransport("unopened", api=api)
    framing = make_serial_framing("xbee-api2" if api == 2 else "xbee")
    units = [unit for chunk in _reads(data) for unit in transport.cut(chunk)] + transport.quiet()
    for unit in units:
        messages = framing.feed(unit)
        assert all(type(m) is Message for m in messages)
        sender = framing.sender_of(unit)  # type: ignore[attr-defined]
        assert sender is None or 0 <= sender < 1 << 64
    assert not _STREAM_REASONS & {name for name, n in framing.drops.items() if n}, framing.drops


def mavlink(data: bytes) -> None:
    """A telemetry radio's byte stream cut into reads, read by a link with a key or without (the first byte's low
    bit): the transport's reader cuts whole frames, so the framing finds nothing wrong with their framing."""
    from vstig_hw.counters import Counters
    from vstig_hw.framing.mavlink import MavlinkFraming, MavlinkStreamReader, Signing

    framing = MavlinkFraming(4, signing=Signing(bytes(range(32))) if data and data[0] & 1 else None)
    reader = MavlinkStreamReader(Counters())
    for unit in [unit for chunk in _reads(data) for unit in reader.feed(chunk)] + reader.flush():
        messages = framing.feed(unit)
        assert all(type(m) is Message for m in messages) and len(messages) <= 16
        sender = framing.sender_of(unit)
        assert sender is None or 0 <= sender <= 0xFFFF
    assert not {"noise", "incompat_flags", "crc", "truncated"} & {n for n, c in framing.drops.items() if c}


def xbeemav(data: bytes) -> None:
    """XbeeMav packets from a few modules (the first byte of each 40-byte piece picks the module), each in a
    good Receive Packet, with a tick now and then: reassembly stays bounded, nothing raises."""
    framing = XbeeMavFraming(_DEPLOYMENT)
    for i in range(0, len(data), 40):
        piece = data[i:i + 40]
        framing.feed(api_frame(receive_packet(0x0013A200_00000000 | piece[0] % 3, piece[1:])))
        if piece[0] & 0x80:
            framing.tick()
        assert framing.reassembler.pending <= 8


def kilobot_ohc(data: bytes) -> None:
    """The overhead controller transmits only: any bytes read from it are refused with TransmitOnlyError."""
    framing = make_serial_framing("kilobot-ohc")
    try:
        framing.feed(data)
    except TransmitOnlyError:
        return
    raise AssertionError("kilobot-ohc decoded bytes")


_CAN_SCHEMES = (CanIdScheme(), CanIdScheme(extended=True, stigmergy=3))


def can_framing(data: bytes) -> None:
    """Frames built from the bytes: 4 bytes of ID, a flags byte, a length byte, then data."""
    framings = [CanFraming(scheme, sender=1) for scheme in _CAN_SCHEMES]
    view = memoryview(data)
    while len(view) >= 6:
        ident, flags, length = struct.unpack_from(">IBB", view)
        body = bytes(view[6:6 + length % 65])
        view = view[6 + length % 65:]
        frame = can.Message(arbitration_id=ident & 0x1FFFFFFF, is_extended_id=bool(flags & 1), is_fd=bool(flags & 2),
                            is_remote_frame=bool(flags & 4), is_error_frame=bool(flags & 8), dlc=length,
                            data=body, check=False)
        for framing in framings:
            for msg in framing.feed(frame):
                assert type(msg) is Message


def link_spec(data: bytes) -> None:
    text = data.decode("utf-8", "replace")
    try:
        spec = parse_spec(text)
    except ValueError:
        return
    assert spec.name and " " not in spec.name


def _text_lines(parse: Callable[[str, int, str], object], path: str) -> Target:
    """A line reader's target: every line parses, or is a CaptureError naming path:line."""

    def target(data: bytes) -> None:
        for number, line in enumerate(data.decode("utf-8", "replace").splitlines() or [""], 1):
            try:
                parse(path, number, line)
            except CaptureError as error:
                assert str(error).startswith(f"{path}:")
    return target


candump_line = _text_lines(candump.parse_line, "fuzz.log")
serial_capture_line = _text_lines(serial_log.parse_line, "fuzz.cap")


_PCAP_HEADER = struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65535, 227)


def pcap(data: bytes) -> None:
    """A pcap file: the bytes as they are, and behind a valid header (so records get parsed)."""
    for file in (data, _PCAP_HEADER + data):
        try:
            for frame in PcapReader(io.BytesIO(file)):
                assert isinstance(frame, can.Message)
        except PcapError:
            pass


def _text(data: bytes) -> io.StringIO:
    return io.StringIO(data.decode("utf-8", "replace"))


# python-can's readers for the formats `read_capture` hands to can.LogReader. read_capture turns any
# Exception they raise into a CaptureError, so what must never happen is a hang, a crash or a BaseException.
# They are called directly on in-memory files: can.LogReader looks its plugins up on every call (~5 ms).
_PYTHON_CAN_READERS: dict[str, Callable[[bytes], Iterable[can.Message]]] = {
    ".asc": lambda data: can.ASCReader(_text(data), relative_timestamp=False),
    ".blf": lambda data: can.BLFReader(io.BytesIO(data)),
    ".csv": lambda data: can.CSVReader(_text(data)),
    ".trc": lambda data: can.TRCReader(_text(data)),
}
_PYTHON_CAN_FORMATS = tuple(_PYTHON_CAN_READERS)
logging.getLogger("can.io.trc").setLevel(logging.ERROR)  # it warns about every bad line


def capture_files(data: bytes) -> None:
    """The first byte picks the format, the rest is the file."""
    suffix = _PYTHON_CAN_FORMATS[data[0] % len(_PYTHON_CAN_FORMATS)] if data else ".asc"
    try:
        for frame in _PYTHON_CAN_READERS[suffix](data[1:]):
            assert isinstance(frame, can.Message)
    except AssertionError:
        raise
    except Exception:  # read_capture reports these as a CaptureError naming the file
        pass


# read_mcap reads a path: the file goes to memory (/dev/shm) where there is one, as opening a file on disk
# here costs more than parsing it.
# tests/fuzz/run.py hands its children one folder (VSTIG_FUZZ_SCRATCH) and removes it: libFuzzer ends a
# child without running atexit.
_SCRATCH = os.environ.get("VSTIG_FUZZ_SCRATCH") or tempfile.mkdtemp(
    prefix="vstig-fuzz-", dir="/dev/shm" if os.path.isdir("/dev/shm") else None)
if "VSTIG_FUZZ_SCRATCH" not in os.environ:
    atexit.register(shutil.rmtree, _SCRATCH, True)
_MCAP = Path(_SCRATCH) / f"capture-{os.getpid()}.mcap"


def mcap(data: bytes) -> None:
    """A rosbag2 MCAP capture: read_mcap yields records or raises CaptureError naming the file."""
    _MCAP.write_bytes(data)
    try:
        for record in read_mcap(str(_MCAP)):
            assert type(record.unit[0]) is Message
    except CaptureError as error:
        assert str(error).startswith(str(_MCAP))


def _mcap_seed(msgs: list[Message]) -> bytes:
    writer = McapCaptureWriter(str(_MCAP))
    for i, m in enumerate(msgs):
        writer.write_message(1700000000 + i, "can0" if i % 2 else "radio", i or None, m)
    writer.close()
    return _MCAP.read_bytes()


def _python_can_seeds(msgs: list[Message]) -> list[bytes]:
    out = []
    folder = Path(tempfile.mkdtemp(prefix="vstig-fuzz-seeds-"))
    for index, suffix in enumerate(_PYTHON_CAN_FORMATS):
        path = folder / f"seed{suffix}"
        with can.Logger(str(path)) as log:
            for i, m in enumerate(msgs):
                log.on_message_received(can.Message(timestamp=1700000000 + i, arbitration_id=0x605, data=encode(m),
                                                    is_extended_id=False))
        out.append(bytes([index]) + path.read_bytes())
        path.unlink()
    folder.rmdir()
    return out


_DEPLOYMENT_TEXT = '[buzz]\nstigmergy = 1\n[keys]\nx = { key = 1, type = "int16" }\ny = { key = 2, type = "uint16" }\n'
_DEPLOYMENT = parse_deployment(_DEPLOYMENT_TEXT)


def buzz_framings(data: bytes) -> None:
    """Buzz and BittyBuzz links: a Kilobot stream cut into reads, a BuzzKH4 frame, a ROSBuzz block or XbeeMav
    packet (the first byte picks); every one counts what it cannot use and raises nothing (XbeeMav: ValueError)."""
    choice, body = (data[0] % 4, data[1:]) if data else (0, b"")
    if choice == 0:
        kilobot = BittyBuzzKilobotFraming(_DEPLOYMENT)
        messages = [m for chunk in _reads(body) for m in kilobot.feed(chunk)]
    elif choice == 1:
        messages = BuzzKh4Framing(_DEPLOYMENT).feed(body)
    elif choice == 2:
        messages = RosBuzzDecoder(_DEPLOYMENT).feed(body)
    else:
        try:
            messages = RosBuzzDecoder(_DEPLOYMENT).feed_xbee(body)
        except ValueError:
            return
    assert all(type(m) is Message for m in messages)


def buzz_messages(data: bytes) -> None:
    """One Buzz message in either dialect, one BittyBuzz message: each decodes or raises its DecodeError."""
    for dialect in ("current", "pre2017"):
        with contextlib.suppress(BuzzDecodeError):
            decode_buzz(data, dialect)  # type: ignore[arg-type]
    try:
        decode_bittybuzz(data)
    except BbzDecodeError:
        assert len(data) != 9


def deployment(data: bytes) -> None:
    with contextlib.suppress(DeploymentError):
        parse_deployment(data.decode("utf-8", "replace"))


def _classify(can_id: int) -> int | None:
    return (can_id >> 8) & 1 if can_id & 0x600 == 0x600 else None


def candump_chunk(data: bytes) -> None:
    """The vectorised candump path: JSON lines for a uniform chunk, None for anything else."""
    out = chunk_to_jsonl(data, _classify, {})
    assert out is None or out.endswith(b"\n") or out == b""


_POLICIES = {"a": LinkPolicy(trust=IdSet.parse("0-200", 0xFFFF), keys=IdSet.parse("0-40", 0x7FFF)),
             "b": LinkPolicy(deny=IdSet.parse("3,9", 0xFFFF), read_only=True), "c": LinkPolicy()}
_LINKS = tuple(_POLICIES)


def guard(data: bytes) -> None:
    """Runs of 13-byte records: link, sender, time step (ms), then an 8-byte message; every one passes or is counted."""
    g = Guard(max_jump=20, rate=50, flap=2, links=_POLICIES)
    counters = Counters()
    now = 0.0
    records = 0
    passed = 0
    for offset in range(0, len(data) - 12, 13):
        head, sender, step = struct.unpack_from(">BHH", data, offset)
        msg = decode(data[offset + 5:offset + 13])
        now += step / 1000
        link = _LINKS[head % 3]
        passed += len(g.filter(link, None if head & 0x80 else sender, [msg], now, counters))
        records += 1
        g.confined_to(msg)
    assert passed + sum(counters.values()) == records
    assert set(counters) <= {"drop_untrusted", "drop_rate", "drop_key", "drop_jump"}


def _bbz_payloads() -> list[bytes]:
    """BittyBuzz Kilobot payloads (the 9-byte message and its type byte), unframed."""
    framing = BittyBuzzKilobotFraming(_DEPLOYMENT)
    return [cobs.decode(unit[:-1])[:-2] for key in (1, 2) for unit in framing.encode(Message(0, key, 9, 4, 3))]


def _buzz_seeds(msgs: list[Message]) -> list[bytes]:
    ours = [Message(0, 1, 5, 3, 7), Message(1, 2, 6, 4, 8)]
    kilobot = b"".join(u for m in ours for u in BittyBuzzKilobotFraming(_DEPLOYMENT).encode(m))
    kh4 = BuzzKh4Framing(_DEPLOYMENT, robot_id=3, frame_size=64).encode_batch(ours)
    rosbuzz = RosBuzzDecoder(_DEPLOYMENT, robot_id=3).encode_batch(ours)
    xbee = [xbee_packet(3, 1, [int.from_bytes(block[i:i + 8].ljust(8, b"\0"), "big") for i in range(0, len(block), 8)])
            for block in rosbuzz]
    return [b"\0\x03" + kilobot, *(b"\x01" + f for f in kh4), *(b"\x02" + b for b in rosbuzz),
            *(b"\x03" + x for x in xbee)]


def seeds() -> dict[str, list[bytes]]:
    """Valid inputs per target, for the fuzzer to mutate from: random bytes rarely spell `can:` or a CRC."""
    msgs = [Message(0, 5, 1234, 7, 42), Message(1, 0x7FFF, 0, 0, 9), Message(0, 1, 0xFFFF, 0xFFFF, 0xFFFF)]
    serial = {name: [bytes([n]) + b"".join(u for m in msgs for u in make_serial_framing(name).encode(m))
                     for n in (0, 3, 15)] for name in ("cobs8", "epuck4", "kilobot")}
    frames = [struct.pack(">IBB", ident, flags, 8) + encode(m) for m in msgs
              for ident, flags in ((0x605, 0), (0x705, 0), (0x18060005, 1), (0x605, 2), (0x605, 4))]
    candump_lines = [f"(1700000000.{i:06d}) can0 {0x600 | i:03X}#{encode(m).hex().upper()}\n"
                     for i, m in enumerate(msgs)]
    candump_lines += ["(1700000000.5) can0 18060005##1" + encode(msgs[0]).hex() * 2 + "\n",
                      "(1700000000.6) can0 605#R\n", "(1700000000.7) can0 605#0102_9\n"]
    uniform = "".join(f"(1700000000.{i:06d}) can0 {0x600 | i:03X}#{encode(m).hex().upper()}\n"
                      for i, m in enumerate(msgs * 3))
    cobs8 = make_serial_framing("cobs8")
    capture = "# vstig serial capture v1\n" + "".join(
        f"(1700000000.{i:06d}) radio cobs8 {'rx' if i % 2 else 'tx'} {cobs8.encode(m)[0].hex()}\n"
        for i, m in enumerate(msgs))
    pcap_file = _PCAP_HEADER + b"".join(
        struct.pack("<IIII", 1700000000, i, 16, 16) + struct.pack(">IBBxx", 0x605, 8, 0) + encode(m)
        for i, m in enumerate(msgs))
    records = [struct.pack(">BHH", link, sender, step) + encode(m)
               for link, sender, step in ((0, 5, 10), (1, 3, 0), (2, 7, 1000), (0x80, 0, 5)) for m in msgs]
    return {
        "wire": [encode(m) for m in msgs] + [b"".join(map(encode, msgs))],
        **serial,
        "kilobot-ohc": [b"\x55" + bytes(131)],
        "can": [b"".join(frames)],
        "link-spec": [spec.encode() for group in examples().values() for spec in group],
        "candump": [line.encode() for line in candump_lines],
        "candump-chunk": [uniform.encode()],
        "serial-capture": [capture.encode()],
        "pcap": [pcap_file, pcap_file[len(_PCAP_HEADER):]],
        "capture-files": _python_can_seeds(msgs),
        "mcap": [_mcap_seed(msgs)],
        "guard": [b"".join(records)],
        "buzz-framings": _buzz_seeds(msgs),
        "buzz-messages": [frame[4:4 + int.from_bytes(frame[2:4], "little")]  # u16 robot, u16 length, message
                          for frame in BuzzKh4Framing(_DEPLOYMENT, frame_size=64).encode(Message(0, 1, 5, 3, 7))]
                         + [payload[:9] for payload in _bbz_payloads()],
        "deployment": [_DEPLOYMENT_TEXT.encode()],
        "xbee": [bytes([n]) + b"".join(api_frame(receive_packet(0x0013A20040A1B2C3, encode(m)), n % 2 == 1)
                                       for m in msgs) for n in (0, 3, 14)],
        "xbeemav": _xbeemav_seeds(),
        "mavlink": _mavlink_seeds(msgs),
    }


def _mavlink_seeds(msgs: list[Message]) -> list[bytes]:
    """A drone's TUNNELs and a HEARTBEAT, unsigned (first byte even) and signed with the target's key (odd)."""
    from vstig_hw.framing.mavlink import MavlinkFraming, Signing

    seeds = []
    for first in (0, 1, 6, 9):
        drone = MavlinkFraming(9, 1, signing=Signing(bytes(range(32))) if first & 1 else None)
        seeds.append(bytes([first]) + b"".join(drone.encode_batch(msgs)) + drone.heartbeat())
    return seeds


def _xbeemav_seeds() -> list[bytes]:
    """S packets, then F fragments and a P ping, each in a 40-byte piece: a module byte, then RF data."""
    words = [2, 0, 0, 0, 0] + [int.from_bytes(b.ljust(8, b"\0")[i:i + 8], "little")
                               for b in RosBuzzDecoder(_DEPLOYMENT, robot_id=3).encode_batch([Message(0, 1, 5, 3, 7)])
                               for i in range(0, len(b), 8)]
    serialized = bytes((3, 1)) + b"".join(w.to_bytes(8, "big") for w in words)
    pieces = [b"S" + serialized[:38]]
    pieces += [f[:39] for f in fragment_packets(serialized + bytes(300), 1, 3)] + [b"P\x01\x03\x02"]
    return [b"".join(bytes([k]) + p.ljust(39, b"\0") for k, p in enumerate(pieces))]


TARGETS: dict[str, Target] = {
    "wire": wire,
    "cobs8": _serial("cobs8"),
    "epuck4": _serial("epuck4"),
    "kilobot": _serial("kilobot"),
    "kilobot-ohc": kilobot_ohc,
    "can": can_framing,
    "link-spec": link_spec,
    "candump": candump_line,
    "candump-chunk": candump_chunk,
    "serial-capture": serial_capture_line,
    "pcap": pcap,
    "capture-files": capture_files,
    "mcap": mcap,
    "guard": guard,
    "buzz-framings": buzz_framings,
    "buzz-messages": buzz_messages,
    "deployment": deployment,
    "xbee": xbee,
    "xbeemav": xbeemav,
    "mavlink": mavlink,
}
