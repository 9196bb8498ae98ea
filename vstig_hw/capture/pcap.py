"""CAN captures as pcap files (LINKTYPE_CAN_SOCKETCAN), which Wireshark and tshark read.

python-can has no pcap format, so this adds one in python-can's own shape: a
`MessageWriter` (a Listener: hand it to a Notifier, or call `on_message_received`)
and a `MessageReader` (iterate it for `can.Message`s). pyproject.toml registers
both under python-can's `can.io.message_writer/reader` entry points, so
`can.Logger("x.pcap")` and `can.LogReader("x.pcap")` pick them by extension.

Each record is the Linux SocketCAN frame as tcpdump/Wireshark define link type 227:
CAN ID in network byte order with the EFF/RTR/ERR flags in its top bits, the
payload length, the CAN FD flags, two reserved bytes, then the data padded to 8
bytes (classic, 16-byte record) or 64 bytes (CAN FD, 72-byte record, FDF flag).
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterator
from typing import Any, BinaryIO

import can
from can.io.generic import BinaryIOMessageWriter, FileIOMessageReader

__all__ = ["LINKTYPE_CAN_SOCKETCAN", "PcapError", "PcapReader", "PcapWriter", "PcapngReader"]

LINKTYPE_CAN_SOCKETCAN = 227
_MAGIC_US = 0xA1B2C3D4
_MAGIC_NS = 0xA1B23C4D
_SNAPLEN = 72
_GLOBAL = struct.Struct("<IHHiIII")  # we write little-endian, microsecond timestamps
_RECORD = "IIII"
_FRAME = struct.Struct(">IBBxx")  # can_id (network order), len, fd flags, reserved

_EFF_FLAG = 0x80000000
_RTR_FLAG = 0x40000000
_ERR_FLAG = 0x20000000
_EFF_MASK = 0x1FFFFFFF
_SFF_MASK = 0x7FF
_CANFD_BRS = 0x01
_CANFD_ESI = 0x02
_CANFD_FDF = 0x04  # marks a CAN FD frame in the fd flags byte
_CLASSIC_DATA = 8
_FD_DATA = 64


class PcapError(ValueError):
    """A file that is not a SocketCAN pcap capture; the message names the file and the problem."""


class PcapWriter(BinaryIOMessageWriter):
    """Writes every `can.Message` it receives as one pcap record."""

    def __init__(self, file: str | os.PathLike[str] | BinaryIO, **kwargs: Any) -> None:
        super().__init__(file, mode="wb")
        self.file.write(_GLOBAL.pack(_MAGIC_US, 2, 4, 0, 0, _SNAPLEN, LINKTYPE_CAN_SOCKETCAN))

    def on_message_received(self, msg: can.Message) -> None:
        can_id = msg.arbitration_id & (_EFF_MASK if msg.is_extended_id else _SFF_MASK)
        if msg.is_extended_id:
            can_id |= _EFF_FLAG
        if msg.is_remote_frame:
            can_id |= _RTR_FLAG
        if msg.is_error_frame:
            can_id |= _ERR_FLAG
        data = bytes(msg.data)
        if msg.is_fd:
            flags = _CANFD_FDF | (_CANFD_BRS if msg.bitrate_switch else 0)
            flags |= _CANFD_ESI if msg.error_state_indicator else 0
            body = _FRAME.pack(can_id, len(data), flags) + data.ljust(_FD_DATA, b"\0")
        else:
            length = msg.dlc if msg.is_remote_frame else len(data)
            body = _FRAME.pack(can_id, length, 0) + data.ljust(_CLASSIC_DATA, b"\0")
        seconds = int(msg.timestamp)
        micros = round((msg.timestamp - seconds) * 1_000_000)
        if micros == 1_000_000:
            seconds, micros = seconds + 1, 0
        self.file.write(struct.pack("<" + _RECORD, seconds, micros, len(body), len(body)) + body)


def _opened(file: str | os.PathLike[str] | BinaryIO, unnamed: str) -> tuple[str, BinaryIO]:
    """(name for messages, binary file) of a path, opened here, or of a file the caller opened."""
    if isinstance(file, str | os.PathLike):
        return str(file), open(file, "rb")  # closed by stop(), as python-can readers do
    return getattr(file, "name", unnamed), file


class PcapReader(FileIOMessageReader[BinaryIO]):
    """Iterates the `can.Message`s of a SocketCAN pcap file (either byte order, us or ns timestamps)."""

    def __init__(self, file: str | os.PathLike[str] | BinaryIO, **kwargs: Any) -> None:
        self.name, self.file = _opened(file, "<pcap>")
        header = self.file.read(_GLOBAL.size)
        if len(header) < _GLOBAL.size:
            raise PcapError(f"{self.name}: not a pcap file (only {len(header)} bytes)")
        for order in "<>":
            magic = struct.unpack(order + "I", header[:4])[0]
            if magic in (_MAGIC_US, _MAGIC_NS):
                break
        else:
            raise PcapError(f"{self.name}: not a pcap file (magic {header[:4].hex()})")
        self._order = order
        self._scale = 1e-6 if magic == _MAGIC_US else 1e-9
        linktype = struct.unpack(order + "I", header[20:24])[0] & 0x0FFFFFFF
        if linktype != LINKTYPE_CAN_SOCKETCAN:
            raise PcapError(f"{self.name}: link type {linktype} is not CAN SocketCAN ({LINKTYPE_CAN_SOCKETCAN})")

    def __iter__(self) -> Iterator[can.Message]:
        record = struct.Struct(self._order + _RECORD)
        index = 0
        while head := self.file.read(record.size):
            index += 1
            if len(head) < record.size:
                raise PcapError(f"{self.name}: record {index} is cut short")
            seconds, fraction, captured, _ = record.unpack(head)
            body = self.file.read(captured)
            if len(body) < captured or captured < _FRAME.size:
                raise PcapError(f"{self.name}: record {index} is cut short")
            yield self._message(seconds + fraction * self._scale, body, index)

    def _message(self, timestamp: float, body: bytes, index: int) -> can.Message:
        return _socketcan_message(self.name, timestamp, body, index)


def _socketcan_message(name: str, timestamp: float, body: bytes, index: int) -> can.Message:
    """One LINKTYPE_CAN_SOCKETCAN packet (pcap record or pcapng block body) as a python-can message."""
    if len(body) < _FRAME.size:
        raise PcapError(f"{name}: record {index} is cut short")
    can_id, length, flags = _FRAME.unpack_from(body)
    is_fd = bool(flags & _CANFD_FDF) or len(body) == _FRAME.size + _FD_DATA
    if length > (_FD_DATA if is_fd else _CLASSIC_DATA):
        raise PcapError(f"{name}: record {index} claims {length} data bytes")
    remote = bool(can_id & _RTR_FLAG)
    data = b"" if remote else body[_FRAME.size:_FRAME.size + length]
    if len(data) < length and not remote:
        raise PcapError(f"{name}: record {index} holds fewer data bytes than it claims")
    extended = bool(can_id & _EFF_FLAG)
    return can.Message(
        timestamp=timestamp,
        arbitration_id=can_id & (_EFF_MASK if extended else _SFF_MASK),
        is_extended_id=extended,
        is_remote_frame=remote,
        is_error_frame=bool(can_id & _ERR_FLAG),
        is_fd=is_fd,
        bitrate_switch=bool(flags & _CANFD_BRS),
        error_state_indicator=bool(flags & _CANFD_ESI),
        dlc=length,
        data=data,
    )


_PCAPNG_SHB = 0x0A0D0D0A  # section header block (its byte-order magic says how to read the section)
_PCAPNG_IDB = 1  # interface description: link type, timestamp resolution
_PCAPNG_EPB = 6  # enhanced packet: interface, timestamp, data
_PCAPNG_BYTE_ORDER = 0x1A2B3C4D
_PCAPNG_IF_TSRESOL = 9


class PcapngReader(FileIOMessageReader[BinaryIO]):
    """Iterates the `can.Message`s of a pcapng file (what Wireshark and `tshark -w` write by default).

    Packets of SocketCAN interfaces are read; packets of other link types are skipped and counted
    in `skipped` (a capture of several interfaces). Read-only: vstig-hw writes .pcap.
    """

    def __init__(self, file: str | os.PathLike[str] | BinaryIO, **kwargs: Any) -> None:
        self.name, self.file = _opened(file, "<pcapng>")
        self.skipped = 0

    def __iter__(self) -> Iterator[can.Message]:
        order = "<"
        interfaces: list[tuple[int, float]] = []  # (link type, seconds per timestamp unit), by interface id
        index = 0
        while head := self.file.read(8):
            if len(head) < 8:
                raise PcapError(f"{self.name}: block {index + 1} is cut short")
            if index == 0 and struct.unpack("<I", head[:4])[0] != _PCAPNG_SHB:
                raise PcapError(f"{self.name}: not a pcapng file (first block {head[:4].hex()})")
            if struct.unpack("<I", head[:4])[0] == _PCAPNG_SHB:
                magic = self.file.read(4)
                order = "<" if struct.unpack("<I", magic)[0] == _PCAPNG_BYTE_ORDER else ">"
                interfaces = []
                head += magic
            kind, length = struct.unpack(order + "II", head[:8])
            rest = self.file.read(length - len(head))
            index += 1
            if length < 12 or len(rest) < length - len(head):
                raise PcapError(f"{self.name}: block {index} is cut short")
            body = (head + rest)[8:length - 4]
            if kind == _PCAPNG_IDB:
                interfaces.append((struct.unpack_from(order + "H", body)[0], _resolution(body[8:], order)))
            elif kind == _PCAPNG_EPB:
                interface, high, low, captured = struct.unpack_from(order + "IIII", body)
                if interface >= len(interfaces):
                    raise PcapError(f"{self.name}: block {index} names interface {interface}, never described")
                linktype, unit = interfaces[interface]
                if linktype != LINKTYPE_CAN_SOCKETCAN:
                    self.skipped += 1
                    continue
                yield _socketcan_message(self.name, (high << 32 | low) * unit, body[20:20 + captured], index)


def _resolution(options: bytes, order: str) -> float:
    """Seconds per timestamp unit from an interface's if_tsresol option (microseconds when absent)."""
    at = 0
    while at + 4 <= len(options):
        code, size = struct.unpack_from(order + "HH", options, at)
        if code == 0:
            break
        if code == _PCAPNG_IF_TSRESOL and size >= 1:
            value = options[at + 4]
            return float(2 ** -(value & 0x7F)) if value & 0x80 else float(10 ** -value)
        at += 4 + (size + 3) // 4 * 4
    return 1e-6
