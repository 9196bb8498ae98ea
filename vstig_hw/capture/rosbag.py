"""Captures as rosbag2 MCAP files: one topic per link, `vstig_msgs/msg/Message` in CDR.

Written with the `mcap` library (the container) and `rosbags` (the message
definition and its CDR encoding), so the file opens in Foxglove and `ros2 bag`.
An MCAP capture holds decoded messages, not link units: each keeps its op, key,
value, timestamp, robot and sender (-1 where the medium names none), stamped
with the time it was heard; what a recording gateway sent is on the link's topic
plus `/sent` (channel metadata `direction: tx`), read back as `tx` records. Reading one back yields records of the
`MESSAGE_FRAMING` "framing", which hands the message on as it is.

Both libraries come with the `mcap` extra (`pip install 'vstig-hw[mcap]'`).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator
from typing import IO, Any

from ..counters import Counters
from ..extras import install_hint
from ..framing.ros2 import cdr_message, ros_name, sender_of_wire  # MSGDEF in CDR, packed by struct (no rosbags)
from ..wire import Message, Op
from .decoded import Decoder
from .records import MESSAGE_FRAMING, STRICT, CaptureError, Damage, Record, cut_short
from .writer import CaptureWriter

__all__ = ["MESSAGE_FRAMING", "MSGDEF", "NOTE_METADATA", "TOPIC_PREFIX", "TYPE_NAME", "McapCaptureWriter",
           "cdr_message", "read_mcap", "read_mcap_notes", "topic_for"]

TYPE_NAME = "vstig_msgs/msg/Message"
MSGDEF = """\
# One virtual stigmergy message as heard on a link (vstig-hw; firmware_spec/SPEC.md section 7).
uint8 PUT=0
uint8 GET=1
uint8 op
uint16 key
uint16 value
uint16 timestamp
uint16 robot
int64 sender
"""
# Files written before XBee links (whose senders are 64-bit addresses) carry `int32 sender`: still read.
_MSGDEF_INT32 = MSGDEF.replace("int64 sender", "int32 sender")
TOPIC_PREFIX = "/vstig/"
SENT_TOPIC = "/sent"  # after a link's topic: what a recording gateway sent on the link (`bridge --record`)
_MAGIC = b"\x89MCAP0\r\n"  # an MCAP file starts and, once closed, ends with it


def _needs_extra(path: str) -> CaptureError:
    return CaptureError(path, None, f"reading or writing .mcap needs the mcap extra: {install_hint('mcap')}")


def _typestore(path: str) -> Any:
    try:
        return _our_typestore()
    except ImportError:
        raise _needs_extra(path) from None


@functools.cache
def _our_typestore(definition: str = MSGDEF) -> Any:
    """Built once per process and definition: parsing one takes ~10 ms, more than reading a small capture."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(definition, TYPE_NAME))
    return store


def _store_for(schema: Any, store: Any) -> Any:
    """The typestore for a file's schema: ours, or the one of files whose sender is an int32."""
    return _our_typestore(_MSGDEF_INT32) if b"int32 sender" in bytes(schema.data) else store


def topic_for(link: str) -> str:
    """A valid ROS 2 topic for a link name (letters, digits, underscores; no leading digit)."""
    return TOPIC_PREFIX + ros_name(link)


NOTE_METADATA = "vstig note"  # a metadata record holding one note (`capture.notes`), its text under "text"


class McapCaptureWriter(CaptureWriter):
    """Writes every message in the records it is given, on its link's topic; `CaptureWriter` for .mcap files."""

    def __init__(self, path: str, decoder: Decoder | None = None) -> None:
        try:
            from mcap.writer import Writer
        except ImportError:
            raise _needs_extra(path) from None
        self.path = path
        self._file: IO[bytes] = open(path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._file)
        self._writer.start(profile="ros2", library="vstig-hw")
        self._schema = self._writer.register_schema(name=TYPE_NAME, encoding="ros2msg", data=MSGDEF.encode())
        self._channels: dict[str, int] = {}
        self._decoder = decoder or Decoder()
        self.messages = 0

    @property
    def drops(self) -> Counters:
        return self._decoder.drops()

    def write(self, record: Record) -> None:
        decoded = self._decoder.decode(record)
        if not decoded:
            return
        sender = self._decoder.sender_of(record)
        where = record.link if record.direction == "rx" else f"{record.link} {record.direction}"
        channel = self._channels.get(where)
        if channel is None:  # what a recording gateway sent goes on a topic of its own, `<link>/sent`
            sent = record.direction != "rx"
            channel = self._channels[where] = self._writer.register_channel(
                topic=topic_for(record.link) + (SENT_TOPIC if sent else ""), message_encoding="cdr",
                schema_id=self._schema, metadata={"link": record.link, **({"direction": "tx"} if sent else {})})
        stamp = round(record.t * 1e9)
        for d in decoded:
            self._writer.add_message(channel, log_time=stamp, data=cdr_message(d.message, sender),
                                     publish_time=stamp, sequence=self.messages)
            self.messages += 1

    takes_notes = True

    def note(self, text: str) -> None:
        """A note (a clock's, a bridge's decision) as a metadata record: what `read_mcap_notes` reads back."""
        self._writer.add_metadata(NOTE_METADATA, {"text": text})

    def write_message(self, t: float, link: str, sender: int | None, message: Message) -> None:
        self.write(Record(t, link, MESSAGE_FRAMING, (message, sender)))

    def size(self) -> int:
        return self._file.tell()

    def flush(self) -> None:
        """End the chunk in progress and push it to the file: a killed recorder loses one tick at most.

        The file then lacks only its summary and footer, which `read_mcap` does without.
        """
        self._writer.flush()  # type: ignore[no-untyped-call]

    def close(self) -> None:
        self._writer.finish()  # type: ignore[no-untyped-call]
        self._file.close()


def read_mcap(path: str, damage: Damage = STRICT,
              opened: Callable[[IO[Any]], None] | None = None) -> Iterator[Record]:
    """The messages of an MCAP capture in log-time order, as `MESSAGE_FRAMING` records named by link.

    A file with no footer (its recorder was killed) is read in file order up to its last complete
    chunk, and the cut is reported by `cut_short`. `opened` (every reader's signature) is not called:
    the file is read through its index, so how far into it the reader is says nothing of progress.
    """
    try:
        from mcap.reader import make_reader
    except ImportError:
        raise _needs_extra(path) from None
    store = _typestore(path)
    try:
        with open(path, "rb") as file:
            if not _has_footer(file):
                yield from _recover(path, file, store, damage)
                return
            for schema, channel, raw in make_reader(file).iter_messages(log_time_order=True):
                if schema is None or schema.name != TYPE_NAME:
                    continue  # another type on another topic: not ours
                yield _record(_store_for(schema, store), channel, raw)
    except CaptureError:
        raise
    except Exception as error:  # a damaged file surfaces as any of McapError, zstd, lz4, CDR, struct errors...
        raise CaptureError(path, None, f"cannot read as rosbag2 MCAP: {type(error).__name__}: {error}") from None


def read_mcap_notes(path: str) -> Iterator[str]:
    """The notes of an MCAP capture as comment lines (`# text`), in file order; none from a file cut short."""
    try:
        from mcap.reader import make_reader
    except ImportError:
        raise _needs_extra(path) from None

    with open(path, "rb") as file:
        if not _has_footer(file):
            return
        try:
            for metadata in make_reader(file).iter_metadata():
                if metadata.name == NOTE_METADATA and "text" in metadata.metadata:
                    yield f"# {metadata.metadata['text']}\n"
        except Exception as error:  # as read_mcap: any of the container's errors is a capture error
            raise CaptureError(path, None, f"cannot read as rosbag2 MCAP: {type(error).__name__}: {error}") from None


def _record(store: Any, channel: Any, raw: Any) -> Record:
    m = store.deserialize_cdr(raw.data, TYPE_NAME)
    link = channel.metadata.get("link") or channel.topic.removeprefix(TOPIC_PREFIX)
    message = Message(Op(m.op), m.key, m.value, m.timestamp, m.robot)
    sender = sender_of_wire(m.sender)
    return Record(raw.log_time / 1e9, link, MESSAGE_FRAMING, (message, sender), channel.metadata.get("direction", "rx"))


def _has_footer(file: IO[bytes]) -> bool:
    """Whether the file ends in the magic a finished MCAP file ends in (a killed recorder's does not)."""
    size = file.seek(0, 2)
    file.seek(max(0, size - len(_MAGIC)))
    ends_well = size > 2 * len(_MAGIC) and file.read() == _MAGIC
    file.seek(0)
    return ends_well


def _recover(path: str, file: IO[bytes], store: Any, damage: Damage) -> Iterator[Record]:
    """Every message of the file's complete records (chunks), in file order; then the cut, in one line."""
    from mcap.exceptions import EndOfFile
    from mcap.records import Channel, Chunk, Schema
    from mcap.records import Message as McapMessage
    from mcap.stream_reader import StreamReader, breakup_chunk

    schemas: dict[int, Any] = {}
    channels: dict[int, Any] = {}
    kept = chunks = end = 0  # end: where the last complete record ended
    records = StreamReader(file, emit_chunks=True).records  # a chunk is decompressed only once it is whole
    while True:
        try:
            record = next(records)
        except (EndOfFile, StopIteration):  # the first incomplete record ends what can be read
            break
        end = file.tell()
        chunks += isinstance(record, Chunk)
        for item in breakup_chunk(record) if isinstance(record, Chunk) else [record]:
            if isinstance(item, Schema):
                schemas[item.id] = item
            elif isinstance(item, Channel):
                channels[item.id] = item
            elif isinstance(item, McapMessage) and item.channel_id in channels:
                channel = channels[item.channel_id]
                schema = schemas.get(channel.schema_id)
                if schema is not None and schema.name == TYPE_NAME:
                    kept += 1
                    yield _record(_store_for(schema, store), channel, item)
    lost = file.seek(0, 2) - end
    cut_short(path, kept, f"messages in {chunks} chunks",
              f"the {lost} bytes after them are incomplete" if lost else "it has no summary or footer", damage)
