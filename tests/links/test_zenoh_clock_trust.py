"""Clock answers from hostile Zenoh peers (issue 45, item 3), with real `vstig record` processes and a real Zenoh
session playing the attacker on loopback.

A forger answers clock queries under another gateway's clock id with a time 1000 s off: its answers reach the
captures marked unproved, and `analyze` does not merge through them unless told to (`--trust-clock-notes`);
gateways whose TLS certificates name them are merged through their own, proved, answers. A flood of made-up
clock ids, repeated and malformed answers (`"9" * 400`) are counted, and hold the recorder to MAX_PEERS clocks:
bounded metrics series, capture lines and memory.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import threading
import time
import urllib.request
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
import zenoh
from certs import Authority, mtls_config
from ports import free_port

from vstig_hw.clocks import MAX_PEERS
from vstig_hw.transports.zenoh_clock import PROBE_EVERY_S
from vstig_hw.wire import Message, Op, encode

sys.path.append(str(Path(__file__).resolve().parents[1] / "cli"))  # tests/cli's process helpers, as tests/mavlink's
from peers import stop

VSTIG = str(Path(sys.executable).with_name("vstig"))
pytestmark = pytest.mark.slow

FORGED_S = 1000.0  # how far the forger says another gateway's clock is from the truth (the same machine: ~0)
NO_GOSSIP = "{ scouting: { gossip: { enabled: false } } }\n"  # two recorders the forger alone joins stay apart


def _wait(done: Callable[[], bool], seconds: float) -> None:
    end = time.monotonic() + seconds
    while not done():
        assert time.monotonic() < end, "timed out waiting"
        time.sleep(0.05)


def _clock_of(capture: Path) -> str:
    """The recording process's clock id, from the capture's first clock note."""
    found = re.search(r"^# vstig clock ([0-9a-f]+)$", capture.read_text(), re.M) if capture.exists() else None
    return found.group(1) if found else ""


def _offsets(capture: Path) -> list[tuple[str, float, str]]:
    """Each offset the capture noted: the peer's clock, the offset, and who answered (cert=NAME or unproved)."""
    return [(clock, float(offset), proof) for clock, offset, proof in
            re.findall(r"^# vstig clock-offset \(\S+\) (\w+) ([+-]\S+) \S+ ?(\S*)$", capture.read_text(), re.M)]


@contextmanager
def _recording(*argv: str) -> Iterator[subprocess.Popen[str]]:
    process = subprocess.Popen([VSTIG, "record", *argv], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        yield process
    finally:
        stop(process, timeout=20)


def _session(*connect: str, config: str = "{}") -> zenoh.Session:
    """A stock Zenoh peer, as an attacker would run one, connected to `connect`."""
    made = zenoh.Config.from_json5(config)
    made.insert_json5("mode", '"peer"')
    made.insert_json5("connect/endpoints", json.dumps(list(connect)))
    made.insert_json5("listen/endpoints", "[]")
    made.insert_json5("scouting/multicast/enabled", "false")
    made.insert_json5("scouting/gossip/enabled", "false")
    return zenoh.open(made)


def _answer_for(session: zenoh.Session, clock: str, ahead_s: float) -> object:
    """Answer clock queries under `clock`'s id with our time plus `ahead_s`."""
    key = f"vstig/lab/clock/{clock}"
    return session.declare_queryable(key, lambda query: query.reply(key, str(time.time_ns() + int(ahead_s * 1e9))))


def _publish_writes(session: zenoh.Session, stop: threading.Event) -> threading.Thread:
    """A robot's writes into the swarm every 50 ms, so both captures hold messages to merge."""
    def run() -> None:
        value = 0
        while not stop.is_set():
            value += 1
            session.put("vstig/lab/0/7", encode(Message(Op.PUT, 3, value, value, 7)))
            time.sleep(0.05)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def _analyze(*argv: str) -> tuple[dict[str, object] | None, str]:
    done = subprocess.run([VSTIG, "analyze", *argv, "--json"], capture_output=True, text=True, timeout=120,
                          check=False)
    assert done.returncode == 0, done.stderr
    shift = json.loads(done.stdout)["capture"]["clocks"][1]
    return shift, done.stderr


def _record_with_a_forger(folder: Path, a_link: str, b_link: str, connect: tuple[str, ...],
                          forged: Callable[[str, str], dict[str, float]]) -> tuple[Path, Path]:
    """a.cap and b.cap, recorded from `a_link` and `b_link` while a forger connected to `connect` publishes writes
    and answers clock queries under the clock ids `forged(a's clock, b's clock)` maps to the seconds it adds."""
    a_cap, b_cap = folder / "a.cap", folder / "b.cap"
    stop = threading.Event()
    with _recording(a_link, "-o", str(a_cap)), _recording(b_link, "-o", str(b_cap)):
        _wait(lambda: bool(_clock_of(a_cap) and _clock_of(b_cap)), 60)
        forger = _session(*connect)
        writer = None
        try:
            answers = [_answer_for(forger, clock, ahead)
                       for clock, ahead in forged(_clock_of(a_cap), _clock_of(b_cap)).items()]
            writer = _publish_writes(forger, stop)
            _wait(lambda: "clock-offset" in a_cap.read_text() and "clock-offset" in b_cap.read_text(), 60)
            time.sleep(2 * PROBE_EVERY_S)  # a few more rounds
        finally:
            stop.set()
            if writer is not None:
                writer.join(5)
            forger.close()  # type: ignore[no-untyped-call]
    assert answers
    return a_cap, b_cap


def test_a_forged_clock_answer_does_not_move_the_merge(tmp_path: Path) -> None:
    """Two recorders on one machine (true offset ~0) that only a forger joins: it answers each under the other's
    clock id, 1000 s off. The offsets reach the captures, unproved; analyze merges nothing through them."""
    config = tmp_path / "no-gossip.json5"
    config.write_text(NO_GOSSIP)
    a_port, b_port = free_port(), free_port()
    a_cap, b_cap = _record_with_a_forger(
        tmp_path, f"zenoh:lab?listen=tcp/127.0.0.1:{a_port}&config={config}",
        f"zenoh:lab?listen=tcp/127.0.0.1:{b_port}&config={config}",
        (f"tcp/127.0.0.1:{a_port}", f"tcp/127.0.0.1:{b_port}"), lambda a, b: {b: FORGED_S, a: -FORGED_S})

    shift, said = _analyze(str(a_cap), str(b_cap))
    assert shift is None, said  # left on its own clock: the truth here, within the capture's own jitter
    assert "b.cap: no proved clock offset joins it to " in said and "--trust-clock-notes uses them" in said
    forged = _offsets(a_cap)
    assert forged and all(proof == "unproved" and abs(offset - FORGED_S) < 1 for _, offset, proof in forged)

    trusted, _ = _analyze(str(a_cap), str(b_cap), "--trust-clock-notes")  # told to: the forgery is believed
    assert isinstance(trusted, dict) and abs(float(str(trusted["shift_s"])) - FORGED_S) < 1


def test_gateways_a_certificate_names_merge_through_their_own_answers(tmp_path: Path) -> None:
    """Mutual TLS between two recorders, and a loopback TCP listener on the first where a forger answers under the
    second's clock id: the first capture holds both, the proved ones named; analyze merges on the proved ones."""
    lab = Authority(tmp_path, "lab-ca")
    configs = {}
    for name in ("gw-a", "gw-b"):
        configs[name] = tmp_path / f"{name}.json5"
        configs[name].write_text(mtls_config(lab, name).replace('protocols: ["tls"]', 'protocols: ["tls", "tcp"]'))
    tls_port, tcp_port = free_port(), free_port()
    a_cap, b_cap = _record_with_a_forger(
        tmp_path, f"zenoh:lab?listen=tls/localhost:{tls_port},tcp/127.0.0.1:{tcp_port}&config={configs['gw-a']}",
        f"zenoh:lab?connect=tls/localhost:{tls_port}&config={configs['gw-b']}", (f"tcp/127.0.0.1:{tcp_port}",),
        lambda a, b: {b: FORGED_S})

    shift, said = _analyze(str(a_cap), str(b_cap))
    assert isinstance(shift, dict) and abs(float(str(shift["shift_s"]))) < 0.01, said  # ~0: the truth
    assert "b.cap: on " in said
    proofs = {proof for clock, _, proof in _offsets(a_cap) if clock == _clock_of(b_cap)}
    assert proofs == {"cert=gw-b", "unproved"}  # the forger's answers beside b's own, each marked
    assert {proof for _, _, proof in _offsets(b_cap)} == {"cert=gw-a"}


def _rss_kb(pid: int) -> int:
    found = re.search(r"^VmRSS:\s+(\d+) kB", Path(f"/proc/{pid}/status").read_text(), re.M)
    assert found
    return int(found.group(1))


FLOOD_IDS = 2000


def _flood(query: zenoh.Query) -> None:
    """2,000 made-up clocks, one answered twice, one with a 400-digit time, one whose id is no clock id."""
    now = str(time.time_ns())
    for n in range(FLOOD_IDS):
        query.reply(f"vstig/lab/clock/{n:016x}", now)
    query.reply(f"vstig/lab/clock/{0:016x}", now)
    query.reply("vstig/lab/clock/ffffffffffffffff", "9" * 400)
    query.reply("vstig/lab/clock/not-a-clock", now)


def test_a_clock_id_flood_and_malformed_answers_are_counted_and_bounded(tmp_path: Path) -> None:
    port, metrics = free_port(), free_port()
    capture = tmp_path / "f.cap"
    with _recording(f"zenoh:lab?listen=tcp/127.0.0.1:{port}", "-o", str(capture),
                    "--metrics", f"127.0.0.1:{metrics}") as recorder:
        _wait(lambda: bool(_clock_of(capture)), 60)
        time.sleep(2 * PROBE_EVERY_S)
        before = _rss_kb(recorder.pid)
        flooder = _session(f"tcp/127.0.0.1:{port}")
        try:
            flood = flooder.declare_queryable("vstig/lab/clock/*", _flood)
            started = time.monotonic()
            time.sleep(15)
            page = urllib.request.urlopen(f"http://127.0.0.1:{metrics}/metrics", timeout=10).read().decode()
            seconds = time.monotonic() - started
            grown = _rss_kb(recorder.pid) - before
        finally:
            flooder.close()  # type: ignore[no-untyped-call]
        assert flood is not None
        recorder.terminate()
        _, err = recorder.communicate(timeout=20)
    series = re.findall(r"^vstig_clock_offset_seconds\{", page, re.M)
    assert 0 < len(series) <= MAX_PEERS and len(page) < 64 * 1024  # not 20,000 series, a 3.66 MB page
    lines = capture.read_text().count("# vstig clock-offset ")
    rounds = seconds / PROBE_EVERY_S + 2
    assert 0 < lines <= MAX_PEERS * rounds  # not one per made-up id (1,407 in 15 s)
    assert grown < 8 * 1024, f"RSS grew {grown} kB"  # +28 MB before the bound
    assert "Traceback" not in err and "OverflowError" not in err
    counts = dict(re.findall(r"(clock_\w+)=(\d+)", err))
    assert int(counts["clock_peers_over"]) >= FLOOD_IDS - MAX_PEERS  # a round's ids past the cap, at least
    assert int(counts["clock_malformed"]) >= 2 and int(counts["clock_repeated"]) >= 1
