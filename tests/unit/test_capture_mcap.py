"""rosbag2 MCAP captures: rosbags and mcap-ros2-support each read our file back field for field; so do we."""

from __future__ import annotations

import json
from pathlib import Path

import can
import pytest
from click.testing import CliRunner
from hypothesis import given
from hypothesis import strategies as st

from vstig_cli.main import cli
from vstig_hw.capture.records import CAN_FRAMING, CaptureError, Record, read_capture
from vstig_hw.capture.rosbag import TYPE_NAME, McapCaptureWriter, cdr_message, topic_for
from vstig_hw.framing import make_serial_framing
from vstig_hw.wire import Message, Op, encode

T0 = 1_700_000_000.0
# (t, link, sender, message): a CAN bus whose IDs name senders, a cobs8 radio whose chunks do not
TRAFFIC = [
    (0.00, "can0", 3, Message(Op.PUT, 7, 1234, 1, 3)),
    (0.05, "radio0", None, Message(Op.GET, 7, 1234, 1, 3)),
    (0.10, "can0", 9, Message(Op.GET, 7, 0, 0, 9)),
    (0.25, "radio0", None, Message(Op.PUT, 8, 65535, 65535, 65535)),
]


def _records() -> list[Record]:
    cobs8 = make_serial_framing("cobs8")
    records = []
    for t, link, sender, msg in TRAFFIC:
        if sender is None:
            records.append(Record(T0 + t, link, "cobs8", b"".join(cobs8.encode(msg))))
        else:
            frame = can.Message(timestamp=T0 + t, arbitration_id=0x600 | msg.op << 8 | sender, data=encode(msg),
                                is_extended_id=False)
            records.append(Record(T0 + t, link, CAN_FRAMING, frame))
    return records


@pytest.fixture
def bag(tmp_path: Path) -> Path:
    path = tmp_path / "run.mcap"
    writer = McapCaptureWriter(str(path))
    for record in _records():
        writer.write(record)
    writer.close()
    assert writer.messages == len(TRAFFIC)
    return path


def _expected() -> list[tuple[str, int, dict[str, int]]]:
    return [(topic_for(link), round((T0 + t) * 1e9),
             {"op": int(m.op), "key": m.key, "value": m.value, "timestamp": m.timestamp, "robot": m.robot,
              "sender": -1 if sender is None else sender}) for t, link, sender, m in TRAFFIC]


FIELDS = ("op", "key", "value", "timestamp", "robot", "sender")


def test_rosbags_reads_it_back_field_for_field(bag: Path) -> None:
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    with Reader(bag) as reader:
        assert {c.topic for c in reader.connections} == {"/vstig/can0", "/vstig/radio0"}
        assert {c.msgtype for c in reader.connections} == {TYPE_NAME}
        store.register(get_types_from_msg(reader.connections[0].msgdef.data, TYPE_NAME))  # the schema we wrote
        got = [(c.topic, stamp, {f: getattr(store.deserialize_cdr(raw, c.msgtype), f) for f in FIELDS})
               for c, stamp, raw in reader.messages()]
    assert got == _expected()


def test_mcap_ros2_support_reads_it_back_field_for_field(bag: Path) -> None:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(bag, "rb") as file:
        decoded = list(make_reader(file, decoder_factories=[DecoderFactory()]).iter_decoded_messages())
    got = [(channel.topic, message.log_time, {f: getattr(ros_msg, f) for f in FIELDS})
           for _, channel, message, ros_msg in decoded]
    assert got == _expected()
    assert {schema.name for schema, _, _, _ in decoded} == {TYPE_NAME}


def test_our_readers_read_it_back_with_links_and_senders(bag: Path) -> None:
    records = list(read_capture(str(bag)))
    assert [(r.link, r.t, r.unit) for r in records] == \
        [(link, pytest.approx(T0 + t), (m, sender)) for t, link, sender, m in TRAFFIC]
    result = CliRunner().invoke(cli, ["analyze", str(bag), "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["capture"]["links_without_sender"] == ["radio0"]
    assert set(report["bandwidth"]["senders"]) == {"3", "9"}
    table = CliRunner().invoke(cli, ["replay", str(bag), "--table"])
    assert table.exit_code == 0 and "65535" in table.stdout


def test_decode_writes_mcap_from_several_captures_merged_and_filtered(tmp_path: Path) -> None:
    log = tmp_path / "bus.log"
    log.write_text("".join(f"({T0 + t:.6f}) can0 {0x600 | m.op << 8 | s:03X}#{encode(m).hex()}\n"
                           for t, link, s, m in TRAFFIC if s is not None))
    radio = tmp_path / "radio.cap"
    cobs8 = make_serial_framing("cobs8")
    radio.write_text("# vstig serial capture v1\n" + "".join(
        f"({T0 + t:.6f}) radio0 cobs8 rx {b''.join(cobs8.encode(m)).hex()}\n"
        for t, link, s, m in TRAFFIC if s is None))
    out = tmp_path / "merged.mcap"
    result = CliRunner().invoke(cli, ["decode", str(log), str(radio), "--format", "mcap", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert [(r.link, r.unit) for r in read_capture(str(out))] == [(link, (m, s)) for _, link, s, m in TRAFFIC]
    result = CliRunner().invoke(cli, ["decode", str(log), str(radio), "--format", "mcap", "-o", str(out),
                                      "--key", "8", "--overwrite"])
    assert result.exit_code == 0, result.output
    assert [r.unit[0].key for r in read_capture(str(out))] == [8]
    result = CliRunner().invoke(cli, ["decode", str(log), "--format", "mcap"])
    assert result.exit_code == 2 and "-o FILE.mcap" in result.output


def test_a_damaged_mcap_names_the_file(tmp_path: Path, bag: Path) -> None:
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(bag.read_bytes()[:40])
    result = CliRunner().invoke(cli, ["decode", str(cut)])
    assert result.exit_code == 1 and f"{cut}: cannot read as rosbag2 MCAP" in result.output


def test_every_damaged_byte_is_read_or_refused_as_a_capture_error(tmp_path: Path, bag: Path) -> None:
    """Found by `make fuzz`: a corrupt compressed chunk escaped as zstandard's ZstdError."""
    data = bag.read_bytes()
    damaged = tmp_path / "damaged.mcap"
    for at in range(0, len(data), max(1, len(data) // 400)):
        damaged.write_bytes(data[:at] + bytes([data[at] ^ 0x5A]) + data[at + 1:])
        try:
            list(read_capture(str(damaged)))
        except CaptureError as error:
            assert str(error).startswith(str(damaged))


def test_topics_are_valid_ros_names() -> None:
    assert topic_for("can0") == "/vstig/can0"
    assert topic_for("3") == "/vstig/link_3"
    assert topic_for("ttyUSB0.radio-1") == "/vstig/ttyUSB0_radio_1"


@given(op=st.sampled_from(list(Op)), key=st.integers(0, 0x7FFF), value=st.integers(0, 0xFFFF),
       timestamp=st.integers(0, 0xFFFF), robot=st.integers(0, 0xFFFF),
       sender=st.none() | st.integers(0, 0x7FFF_FFFF_FFFF_FFFF))
def test_cdr_message_is_what_rosbags_serializes(op: Op, key: int, value: int, timestamp: int, robot: int,
                                                 sender: int | None) -> None:
    """The struct-packed CDR (MCAP captures and the live view) is byte for byte rosbags' encoding of MSGDEF."""
    from vstig_hw.capture.rosbag import _our_typestore

    store = _our_typestore()
    expected = store.serialize_cdr(store.types[TYPE_NAME](op=int(op), key=key, value=value, timestamp=timestamp,
                                                          robot=robot, sender=-1 if sender is None else sender),
                                   TYPE_NAME)
    assert cdr_message(Message(op, key, value, timestamp, robot), sender) == bytes(expected)


def test_files_whose_sender_is_an_int32_still_read(tmp_path: Path) -> None:
    """Captures written before senders could be 64-bit XBee addresses declare `int32 sender`: read as such."""
    from mcap.writer import Writer

    from vstig_hw.capture.rosbag import _MSGDEF_INT32, _our_typestore

    old = _our_typestore(_MSGDEF_INT32)
    path = tmp_path / "old.mcap"
    with open(path, "wb") as file:
        writer = Writer(file)
        writer.start(profile="ros2", library="vstig-hw")
        schema = writer.register_schema(name=TYPE_NAME, encoding="ros2msg", data=_MSGDEF_INT32.encode())
        channel = writer.register_channel(topic="/vstig/can0", message_encoding="cdr", schema_id=schema,
                                          metadata={"link": "can0"})
        for i, sender in enumerate((3, -1)):
            data = old.serialize_cdr(old.types[TYPE_NAME](op=0, key=7, value=1234, timestamp=1 + i, robot=3,
                                                          sender=sender), TYPE_NAME)
            writer.add_message(channel, log_time=i, data=bytes(data), publish_time=i)
        writer.finish()
    assert [(r.unit[0].timestamp, r.unit[1]) for r in read_capture(str(path))] == [(1, 3), (2, None)]
    new = McapCaptureWriter(str(tmp_path / "new.mcap"))
    new.write_message(T0, "radio", 0x0013A20040A1B2C3, Message(Op.PUT, 1, 2, 3, 4))
    new.close()
    assert [r.unit[1] for r in read_capture(str(tmp_path / "new.mcap"))] == [0x0013A20040A1B2C3]
