"""Several links in one capture: record keeps each link's name, filters cut, replay maps links to targets."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import can
import pytest
from click.testing import CliRunner
from peers import PtyPeer, SlcanAdapter, run_vstig, start_vstig, stop, wait_for

from vstig_cli.main import cli
from vstig_hw import Message, Op, encode
from vstig_hw.capture.records import CaptureError, read_capture
from vstig_hw.framing import make_serial_framing
from vstig_hw.links import parse

T0 = 1_700_000_000.0


def test_record_two_radios_into_one_filtered_capture_then_replay_one_link(tmp_path: Path) -> None:
    capture = tmp_path / "both.cap"
    radios = [PtyPeer(), PtyPeer()]
    names = [os.path.basename(radio.path) for radio in radios]  # a serial link is named after its device
    cobs8 = make_serial_framing("cobs8")
    wanted = [Message(Op.PUT, 3, 100 + i, i + 1, 5 + i) for i in range(2)]
    other = Message(Op.PUT, 4, 9, 1, 1)
    recorder = start_vstig("record", *(f"serial:{radio.path}?framing=cobs8" for radio in radios),
                           "-o", str(capture), "--key", "3")
    try:
        def both_recorded() -> bool:
            for radio, msg in zip(radios, wanted, strict=True):
                for m in (other, msg):
                    radio.write(b"".join(cobs8.encode(m)))
            text = capture.read_text() if capture.exists() else ""
            return all(f") {name} cobs8 rx " in text for name in names)

        wait_for(both_recorded, 30, step=lambda: time.sleep(0.2))
    finally:
        _out, err = stop(recorder)
        for radio in radios:
            radio.close()
    assert recorder.returncode == 0, err

    decoded = CliRunner().invoke(cli, ["decode", str(capture), "--format", "jsonl"])
    assert decoded.exit_code == 0, decoded.output
    rows = [json.loads(line) for line in decoded.stdout.splitlines()]
    assert rows and {r["key"] for r in rows} == {3}  # the other key was filtered out when recording
    by_link = {name: {(r["value"], r["robot"]) for r in rows if r["link"] == name} for name in names}
    assert by_link == {name: {(msg.value, msg.robot)} for name, msg in zip(names, wanted, strict=True)}

    analyzed = CliRunner().invoke(cli, ["analyze", str(capture), "--json"])
    assert analyzed.exit_code == 0, analyzed.output
    report = json.loads(analyzed.stdout)
    assert sorted(report["capture"]["links_without_sender"]) == sorted(names)
    assert {w["link"] for w in report["writes"]} == set(names)  # each write first heard on its own link

    target = PtyPeer()
    try:
        done = run_vstig("replay", str(capture), "--onto", f"{names[0]}=serial:{target.path}?framing=cobs8",
                         "--speed", "50")
        assert done.returncode == 0, done.stderr
        assert f"skipped links with no --onto: {names[1]}" in done.stderr
        heard: list[Message] = []
        receiver = make_serial_framing("cobs8")
        while chunk := target.read(0.5):
            heard += receiver.feed(chunk)
    finally:
        target.close()
    assert heard and set(heard) == {wanted[0]}  # only the first radio's link went onto the target


def _candump(path: Path, lines: list[tuple[float, str, int, Message]]) -> Path:
    path.write_text("".join(f"({T0 + t:.6f}) {link} {0x600 | msg.op << 8 | sender:03X}#{encode(msg).hex()}\n"
                            for t, link, sender, msg in lines))
    return path


def test_decode_and_analyze_filters_and_links_kept_apart(tmp_path: Path) -> None:
    log = _candump(tmp_path / "two_buses.log", [
        (0.0, "can0", 1, Message(Op.PUT, 3, 7, 1, 1)), (0.1, "can1", 2, Message(Op.PUT, 3, 7, 1, 1)),
        (0.2, "can0", 2, Message(Op.GET, 3, 7, 1, 1)), (0.3, "can1", 3, Message(Op.GET, 4, 1, 1, 3)),
        (2.0, "can0", 1, Message(Op.PUT, 3, 8, 2, 1)),
    ])
    runner = CliRunner()

    def decoded(*args: str) -> list[tuple[str, int, str]]:
        result = runner.invoke(cli, ["decode", str(log), "--format", "jsonl", *args])
        assert result.exit_code == 0, result.output
        return [(r["link"], r["can_id"] & 0xFF, r["op"]) for r in map(json.loads, result.stdout.splitlines())]

    assert decoded("--link", "can1") == [("can1", 2, "PUT"), ("can1", 3, "GET")]
    assert decoded("--sender", "2", "--op", "get") == [("can0", 2, "GET")]
    assert decoded("--robot", "3") == [("can1", 3, "GET")]
    assert decoded("--since", "0.15", "--until", "1") == [("can0", 2, "GET"), ("can1", 3, "GET")]
    assert decoded("--key", "4", "--key", "3", "--until", "0.05") == [("can0", 1, "PUT")]

    result = runner.invoke(cli, ["analyze", str(log), "--json", "--key", "3"])
    report = json.loads(result.stdout)
    assert set(report["bandwidth"]["links"]) == {"can0", "can1"}
    first = report["writes"][0]
    assert first["heard"]["can0"]["copies"] == 2 and first["heard"]["can1"]["copies"] == 1
    assert report["capture"]["messages"] == 4
    result = runner.invoke(cli, ["analyze", str(log), "--json", "--link", "can1"])
    assert set(json.loads(result.stdout)["bandwidth"]["links"]) == {"can1"}
    result = runner.invoke(cli, ["decode", str(log), "--since", "2", "--until", "1"])
    assert result.exit_code == 2 and "is not after --since" in result.output


@pytest.mark.slow  # python-can's slcan driver sleeps 2 s after opening its port
def test_record_can_and_a_radio_into_one_mcap(tmp_path: Path) -> None:
    capture = tmp_path / "bridged.mcap"
    bus, radio = SlcanAdapter(), PtyPeer()
    cobs8 = make_serial_framing("cobs8")
    on_bus, on_radio = Message(Op.PUT, 3, 1500, 1, 7), Message(Op.GET, 3, 1500, 1, 7)
    recorder = start_vstig("record", f"can:slcan:{bus.path}", f"serial:{radio.path}?framing=cobs8",
                           "-o", str(capture))
    try:
        wait_for(lambda: "O" in bus.commands, 30)
        assert recorder.stderr is not None
        started = recorder.stderr.readline()  # said once both links and the file are open
        assert started.startswith("recording "), started
        bus.inject(can.Message(arbitration_id=0x600 | 7, data=encode(on_bus), is_extended_id=False))
        time.sleep(0.1)
        radio.write(b"".join(cobs8.encode(on_radio)))
        time.sleep(1.0)
    finally:
        _out, err = stop(recorder)
        bus.close()
        radio.close()
    assert recorder.returncode == 0, err
    records = list(read_capture(str(capture)))
    names = [parse(f"can:slcan:{bus.path}").name, parse(f"serial:{radio.path}").name]  # as record names them
    assert [(r.link, r.unit) for r in records] == [(names[0], (on_bus, 7)), (names[1], (on_radio, None))]


def test_can_and_serial_links_need_an_mcap_capture(tmp_path: Path) -> None:
    result = CliRunner().invoke(cli, ["record", "can:virtual:x", "serial:/dev/null", "-o", str(tmp_path / "x.log")])
    assert result.exit_code == 2 and "go into a .mcap capture" in result.output


def _frames_in(capture: Path) -> int:
    """Frames readable so far from a capture still being written (0 until its first block is flushed)."""
    try:
        return len(list(read_capture(str(capture))))
    except CaptureError:
        return 0


@pytest.mark.slow  # python-can's slcan driver sleeps 2 s after opening its port
@pytest.mark.parametrize("ext", [".log", ".asc", ".blf"])  # a channel name, a numbered channel with a note
def test_two_can_buses_in_one_capture_keep_their_names(tmp_path: Path, ext: str) -> None:
    capture = tmp_path / f"two_buses{ext}"
    buses = [SlcanAdapter(), SlcanAdapter()]
    specs = [f"can:slcan:{bus.path}" for bus in buses]
    recorder = start_vstig("record", *specs, "-o", str(capture))
    try:
        wait_for(lambda: all("O" in bus.commands for bus in buses), 30)
        time.sleep(0.5)
        for i, bus in enumerate(buses):
            msg = Message(Op.PUT, 3, 100 + i, 1, 5 + i)
            bus.inject(can.Message(arbitration_id=0x600 | 5 + i, data=encode(msg), is_extended_id=False))
        wait_for(lambda: capture.exists() and _frames_in(capture) >= 2, 20)
    finally:
        _out, err = stop(recorder)
        for bus in buses:
            bus.close()
    assert recorder.returncode == 0, err
    names = [parse(spec).name for spec in specs]
    assert sorted((r.link, r.unit.arbitration_id) for r in read_capture(str(capture))) == \
        sorted([(names[0], 0x605), (names[1], 0x606)])
    report = json.loads(run_vstig("analyze", str(capture), "--json").stdout)
    assert set(report["bandwidth"]["links"]) == set(names)
    assert set(report["bandwidth"]["senders"]) == {"5", "6"}


def test_an_mcap_capture_replays_onto_a_radio_re_encoded(tmp_path: Path) -> None:
    from vstig_hw.capture.rosbag import McapCaptureWriter

    bag = tmp_path / "run.mcap"
    writer = McapCaptureWriter(str(bag))
    sent = [Message(Op.PUT, 3, 100 + i, i + 1, 7) for i in range(3)]
    for i, msg in enumerate(sent):
        writer.write_message(T0 + i * 0.01, "can0", 7, msg)
    writer.close()
    radio = PtyPeer()
    try:
        done = run_vstig("replay", str(bag), "--onto", f"serial:{radio.path}?framing=epuck4", "--speed", "10")
        assert done.returncode == 0, done.stderr
        heard: list[Message] = []
        receiver = make_serial_framing("epuck4")
        while chunk := radio.read(0.5):
            heard += receiver.feed(chunk)
    finally:
        radio.close()
    assert heard == sent
