"""record, decode, replay, put and get on a zenoh link, against real Zenoh sessions on loopback."""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import pytest
from peers import run_vstig, start_vstig, stop, wait_for

from vstig_hw.engine import Stigmergy
from vstig_hw.gateway import Node
from vstig_hw.links import Link, parse
from vstig_hw.wire import Message, Op

BATCH = [Message(Op.PUT, 9, 100 + i, i + 1, 201) for i in range(4)]


def _listener() -> Link[object]:
    """A zenoh link (not yet open) publishing as gateway 201."""
    return parse("zenoh:lab?stigmergy=3").build(robot_id=201)


def _connecting_to(link: Link[object]) -> str:
    """The spec of a link that connects to `link`, once open (its port is the one really bound)."""
    [endpoint] = link.transport.listening  # type: ignore[attr-defined]
    return f"zenoh:lab?stigmergy=3&connect={endpoint}"


@pytest.mark.slow
def test_record_decode_and_replay_a_zenoh_link(tmp_path: Path) -> None:
    capture = tmp_path / "lab.zcap"
    gateway = _listener()
    gateway.open()
    spec = _connecting_to(gateway)
    try:
        recorder = start_vstig("record", spec, "-o", str(capture))
        try:
            def recorded() -> bool:
                gateway.send_many(BATCH)  # again until the recorder has joined
                time.sleep(0.2)
                return capture.exists() and " rx " in capture.read_text()

            wait_for(recorded, 30)
        finally:
            stop(recorder)
        assert recorder.returncode == 0
        lines = capture.read_text().splitlines()
        assert lines[0] == "# vstig zenoh capture v1"
        assert lines[1].startswith("# vstig clock ")  # whose clock its times are on (clock notes)
        samples = [line for line in lines if not line.startswith("#")]
        assert " zenoh rx vstig/lab/3/201 " in samples[0]  # one sample per batch, under the sender's key

        decoded = run_vstig("decode", str(capture), "--format", "jsonl")
        assert decoded.returncode == 0, decoded.stderr
        rows = [json.loads(line) for line in decoded.stdout.splitlines()]
        assert len(rows) % len(BATCH) == 0 and rows
        assert [(r["op"], r["key"], r["value"], r["timestamp"], r["robot"]) for r in rows[:4]] == [
            ("PUT", 9, 100 + i, i + 1, 201) for i in range(4)]

        gateway.receive(0.2)
        done = run_vstig("replay", str(capture), "--onto", spec, "--speed", "50")
        assert done.returncode == 0, done.stderr
        heard = []
        end = time.monotonic() + 10
        while len(heard) < len(rows) and time.monotonic() < end:
            heard += gateway.receive(0.2)
        assert [h.message for h in heard] == [Message(Op.PUT, 9, 100 + i, i + 1, 201) for i in range(4)] * (
            len(rows) // 4)  # every sample, in order (BLOCK congestion control), under its original key
        assert {h.sender for h in heard} == {201}
    finally:
        gateway.close()


@pytest.mark.slow
def test_put_and_get_through_a_zenoh_link() -> None:
    gateway = _listener()
    node = Node([gateway], 201)  # a gateway in this process is the neighbour that answers
    engine = node.engine
    assert isinstance(engine, Stigmergy)
    with node:
        spec = _connecting_to(gateway)
        put = start_vstig("put", "5", "1234", "--on", spec, "--robot-id", "77")
        out, err = put.communicate(timeout=30)  # the node answers its asking meanwhile: that confirms it
        assert put.returncode == 0, err
        assert engine.entry(5) == (1234, 1, 77)
        got = start_vstig("get", "5", "--on", spec, "--wait", "20")
        out, err = got.communicate(timeout=30)
        assert got.returncode == 0, err
        assert out.strip() == "key=5 value=1234 timestamp=1 robot=77"


@pytest.mark.slow
def test_demo_with_two_gateways_converges_across_zenoh() -> None:
    done = run_vstig("demo", "--gateways", "2", "--robots", "12", "--drop", "0.5", "--max-steps", "200", timeout=90)
    assert done.returncode == 0, done.stderr
    assert "converged: all 12 robots hold 12" in done.stdout  # the highest id sits in the second gateway's arena
    # "each gateway's links": one line per gateway/link, "  250/zenoh: in=5 out=14 ..."
    traffic = {m[1]: m[2] for m in re.finditer(r"^  (\d+/\w+): (.*)$", done.stdout, flags=re.M)}
    assert set(traffic) == {"250/can", "250/cobs8", "250/zenoh", "251/epuck4", "251/zenoh"}
    assert "in=" in traffic["250/zenoh"] and " out=" in traffic["251/zenoh"]


def test_a_put_nobody_hears_is_an_error_not_a_success() -> None:
    done = run_vstig("put", "1", "5", "--on", "zenoh:lonely", "--learn", "0", "--wait", "1")
    assert done.returncode == 1
    assert done.stderr.strip().startswith("Error: key 1: no neighbour on zenoh-lonely took our write")


@pytest.mark.parametrize(("args", "budget"), [
    (["get", "3", "--wait", "1"], 1.0),
    (["put", "3", "5", "--learn", "0.5", "--wait", "1"], 1.5),
])
def test_the_wait_bounds_the_whole_command_when_the_peer_is_unreachable(args: list[str], budget: float) -> None:
    """Opening counts against the wait: a peer that never answers no longer adds 3 s to it (measured in
    process, so the interpreter's start is not counted; 0.8 s covers the Zenoh session's own start)."""
    from click.testing import CliRunner

    from vstig_cli.main import cli

    started = time.monotonic()
    result = CliRunner().invoke(cli, [*args, "--on", "zenoh:lab?connect=tcp/127.0.0.1:1"])
    took = time.monotonic() - started
    assert result.exit_code == 1 and "no neighbour on zenoh-lab" in result.output, result.output
    assert took < budget + 0.8, f"{took:.2f} s for a budget of {budget} s"
