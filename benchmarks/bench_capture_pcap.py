"""pcap capture rates beside python-can's own candump .log writer and reader (issue: firmware_spec)."""

from __future__ import annotations

import random
import tempfile
from collections.abc import Iterator
from pathlib import Path

import can
from can.io.canutils import CanutilsLogReader, CanutilsLogWriter

from vstig_hw.capture.pcap import PcapReader, PcapWriter

from .registry import Result, benchmark, rate

_N = 50_000


def _frames() -> list[can.Message]:
    rng = random.Random(3)
    return [can.Message(timestamp=1_700_000_000 + i / 1000, arbitration_id=0x600 | rng.randrange(0x200),
                        is_extended_id=False, data=rng.randbytes(8), channel="vcan0") for i in range(_N)]


@benchmark("capture")
def pcap() -> Iterator[Result]:
    frames = _frames()
    with tempfile.TemporaryDirectory() as tmp:
        pcap_path, log_path = Path(tmp) / "x.pcap", Path(tmp) / "x.log"

        def write(writer_class: type[can.io.generic.MessageWriter], path: Path) -> int:
            with writer_class(path) as writer:
                for frame in frames:
                    writer.on_message_received(frame)
            return _N

        def read(reader_class: type[can.io.generic.MessageReader], path: Path) -> int:
            with reader_class(path) as reader:
                return sum(1 for _ in reader)

        log_write = rate(lambda: write(CanutilsLogWriter, log_path))
        yield Result("capture.pcap.write", rate(lambda: write(PcapWriter, pcap_path)), "frame/s",
                     "python-can candump .log writer", log_write)
        log_read = rate(lambda: read(CanutilsLogReader, log_path))
        yield Result("capture.pcap.read", rate(lambda: read(PcapReader, pcap_path)), "frame/s",
                     "python-can candump .log reader", log_read)
