"""`vstig analyze`: the table, the JSON schema, the plot, bad and empty captures, serial captures, the progress bar."""

from __future__ import annotations

import json
import os
import select
import statistics
import struct
import subprocess
import time
from pathlib import Path

import pytest
from click.testing import CliRunner
from peers import VSTIG, PtyPeer

from vstig_cli.main import cli
from vstig_hw import Message, Op, encode
from vstig_hw.analysis import Analyzer
from vstig_hw.analysis_plot import draw
from vstig_hw.capture.analyzefile import analyze_captures
from vstig_hw.framing import make_serial_framing

T0 = 1_700_000_000.0


def _line(t: float, sender: int, msg: Message) -> str:
    return f"({T0 + t:.6f}) can0 {0x600 | msg.op << 8 | sender:03X}#{encode(msg).hex().upper()}\n"


def _swarm_log(path: Path) -> Path:
    """Robot 1 writes key 3 twice; the 0.1 s write reaches robots 2 and 3 after 0.2 and 0.4 s, the 1.0 s one
    reaches robot 2 only."""
    first, second = Message(Op.PUT, 3, 10, 1, 1), Message(Op.PUT, 3, 11, 2, 1)
    path.write_text("".join([
        _line(0.1, 1, first), _line(0.2, 2, Message(Op.GET, 3, 0, 0, 2)), _line(0.3, 2, first),
        _line(0.5, 3, Message(Op.GET, 3, 10, 1, 1)), _line(1.0, 1, second), _line(1.2, 2, second),
        _line(1.3, 3, Message(Op.GET, 3, 10, 1, 1)),
    ]))
    return path


def invoke(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(cli, ["analyze", *args])
    return result.exit_code, result.stdout, result.stderr


def test_json_has_every_field_the_schema_promises(tmp_path: Path) -> None:
    code, out, err = invoke(str(_swarm_log(tmp_path / "swarm.log")), "--json")
    assert code == 0, err
    report = json.loads(out)
    first, second = report["writes"]
    assert {"key", "value", "timestamp", "robot", "t", "converged_after_s", "senders_total",
            "senders_caught_up"} <= first.keys()
    assert (first["key"], first["value"], first["timestamp"], first["robot"]) == (3, 10, 1, 1)
    assert first["t"] == pytest.approx(T0 + 0.1)
    assert first["converged_after_s"] == pytest.approx(0.4)
    assert (first["senders_total"], first["senders_caught_up"], first["senders_behind"]) == (3, 3, [])
    assert second["converged_after_s"] is None and second["senders_behind"] == [3]
    assert second["senders_caught_up"] == 2
    assert report["summary"] == {"writes": 2, "measured": 2, "converged": 1, "median": pytest.approx(0.4),
                                 "min": pytest.approx(0.4), "max": pytest.approx(0.4)}
    bandwidth = report["bandwidth"]
    assert bandwidth["links"]["can0"]["messages"] == 7 and bandwidth["links"]["can0"]["bytes"] == 56
    assert bandwidth["senders"]["2"]["gets"] == 1 and bandwidth["senders"]["2"]["puts"] == 2
    assert (bandwidth["first_copies"], bandwidth["rebroadcasts"]) == (2, 2)
    assert report["capture"]["messages"] == 7 and report["window_s"] == 10.0


def test_text_table_is_sorted_by_convergence_with_median_min_max(tmp_path: Path) -> None:
    code, out, _ = invoke(str(_swarm_log(tmp_path / "swarm.log")), "--value-type", "int16")
    assert code == 0
    assert "convergence: median 0.400 s  min 0.400 s  max 0.400 s  (1 of 2 writes" in out
    rows = [line.split() for line in out.splitlines() if line.strip().startswith(("0.", "-")) and "3" in line]
    assert [row[0] for row in rows[:2]] == ["0.400", "-"]  # converged first, the unconverged write last
    assert rows[1][-1] == "3"  # robot 3 is still behind
    assert "link can0" in out and "sender 2" in out and "re-broadcasts" in out


def test_key_filter_and_window(tmp_path: Path) -> None:
    log = _swarm_log(tmp_path / "swarm.log")
    code, _, err = invoke(str(log), "--json", "--key", "4", "--op", "put", "--since", "0.5")
    assert code == 1 and err.strip().endswith(
        f"{log}: the filters (--key 4 --op PUT --since 0.5) left out all 7 stigmergy messages in the capture")
    (tmp_path / "empty.log").write_text("")  # two files: read record by record, not in bulk
    code, _, err = invoke(str(log), str(tmp_path / "empty.log"), "--key", "3", "--since", "5")
    assert code == 1 and "(--key 3 --since 5) left out all 7 stigmergy messages" in err
    code, out, _ = invoke(str(log), "--json", "--window", "0.25")  # robot 3 (1.3 s) is not heard near 1.0 s
    assert json.loads(out)["writes"][1]["converged_after_s"] == pytest.approx(0.2)


def _shell(command: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["bash", "-c", command], capture_output=True, text=True, timeout=120, check=False)


@pytest.mark.parametrize("reading", ["cat {log} | {vstig} analyze - --json",
                                     "{vstig} analyze /dev/stdin --json < {log}",
                                     "{vstig} analyze <(cat {log}) --json", "{vstig} analyze {bare} --json",
                                     "cat {bare} | {vstig} analyze - --json --input-format log"])
def test_reads_stdin_pipes_and_unnamed_files_as_decode_does(tmp_path: Path, reading: str) -> None:
    log = _swarm_log(tmp_path / "swarm.log")
    bare = tmp_path / "swarm"  # no extension: told by its first bytes
    bare.write_bytes(log.read_bytes())
    done = _shell(reading.format(vstig=VSTIG, log=log, bare=bare))
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["summary"]["converged"] == 1


def test_a_bad_stream_is_named_as_the_user_gave_it(tmp_path: Path) -> None:
    done = _shell(f"echo garbage | {VSTIG} analyze -")
    assert done.returncode == 2 and "<stdin>: cannot tell the capture type from its first bytes" in done.stderr
    log = _swarm_log(tmp_path / "swarm.log")
    log.write_text(log.read_text() + "not a frame\n")
    done = _shell(f"cat {log} | {VSTIG} analyze -")
    assert done.returncode == 1 and "Error: <stdin>:8: not a candump line" in done.stderr, done.stderr
    done = _shell(f"cat {log} | {VSTIG} analyze - --skip-bad --json")
    assert done.returncode == 0 and "skipped <stdin>:8: not a candump line" in done.stderr
    assert json.loads(done.stdout)["capture"]["files"] == ["<stdin>"]


def _png_size(png: Path) -> tuple[int, int]:
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", data[16:24])
    return width, height


def test_plot_is_a_png_at_column_width(tmp_path: Path) -> None:
    png = tmp_path / "swarm.png"
    code, _, err = invoke(str(_swarm_log(tmp_path / "swarm.log")), "--plot", str(png))
    assert code == 0, err
    assert _png_size(png) == (1020, 1860)  # 3.4 x 6.2 in at 300 dpi: panels (a), (b), (c)
    analyzer = Analyzer()
    analyze_captures([str(tmp_path / "swarm.log")], analyzer)
    legend = draw(analyzer.report()).axes[0].get_legend()  # a few writes: each named
    assert [text.get_text() for text in legend.get_texts()] == ["ts 1, robot 1", "ts 2, robot 1 (1 behind)"]


def test_plot_of_a_serial_capture_draws_its_traffic(tmp_path: Path) -> None:
    """No link names a sender, so convergence cannot be measured; the traffic can, and is the figure."""
    from matplotlib.image import imread

    framing = make_serial_framing("cobs8")
    capture = tmp_path / "radio.cap"
    lines = ["# vstig serial capture v1\n"]
    for step in range(50):
        msg = Message(Op.PUT, 3, 7, 1 + step // 10, 4)
        lines += [f"({T0 + step * 0.1:.6f}) radio0 cobs8 rx {unit.hex()}\n" for unit in framing.encode(msg)]
    capture.write_text("".join(lines))
    png = tmp_path / "radio.png"
    code, _, err = invoke(str(capture), "--plot", str(png))
    assert code == 0, err
    assert _png_size(png) == (1020, 660)  # 3.4 x 2.2 in: the traffic panel alone
    pixels = (imread(png)[:, :, :3] * 255).round()
    line = (abs(pixels - (0x00, 0x72, 0xB2)).max(axis=2) < 8).sum()  # the link's line, in the first colour
    assert line > 500, line


def test_plot_panels_tell_their_writes_apart_and_keep_exact_times(tmp_path: Path) -> None:
    """A simulated swarm (12 robots, one message each per 0.1 s step): (a) says what its curves are, (b) steps
    at the convergence times themselves, (c) shows 12 messages per 0.1 s."""
    log = tmp_path / "sim.log"
    done = subprocess.run([VSTIG, "sim", "--topology", "line", "--robots", "12", "--drop", "0.5", "--runs", "1",
                           "--capture", str(log)], capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    analyzer = Analyzer()
    analyze_captures([str(log)], analyzer)
    report = analyzer.report()
    assert len(report.writes) == 12
    spread, convergence, traffic = draw(report).axes[:3]
    legend = spread.get_legend()
    assert legend is not None
    assert {text.get_text() for text in legend.get_texts()} == {"one write", "interquartile range", "median"}
    times = sorted(t for w in report.writes if (t := w.converged_after) is not None)
    ecdf = convergence.get_lines()[0]
    assert list(ecdf.get_xdata())[1:-1] == times  # no bins: each write's own time
    labels = [text.get_text() for text in convergence.get_legend().get_texts()]
    assert labels == ["converged by then", f"median of those: {statistics.median(times):.3g} s"]
    edges_and_rates = traffic.patches[0].get_data()  # the stairs: messages/s per bin
    assert edges_and_rates.values == pytest.approx(120.0)  # 12 robots x 1 message per 0.1 s


def test_empty_capture_says_so_and_exits_1(tmp_path: Path) -> None:
    empty = tmp_path / "empty.log"
    empty.write_text("")
    code, _, err = invoke(str(empty))
    assert code == 1 and f"{empty}: no stigmergy messages in the capture" in err
    foreign = tmp_path / "foreign.log"
    foreign.write_text("(1700000000.000000) can0 123#0001000200030004\n")
    code, _, err = invoke(str(foreign))
    assert code == 1 and "unknown_id" in err


def test_bad_line_names_file_and_line_and_skip_bad_counts_it(tmp_path: Path) -> None:
    log = _swarm_log(tmp_path / "swarm.log")
    log.write_text(log.read_text() + "not a frame\n")
    code, _, err = invoke(str(log))
    assert code == 1 and f"{log}:8: not a candump line" in err and "Traceback" not in err
    code, out, err = invoke(str(log), "--skip-bad", "--json")
    assert code == 0 and "1 bad line skipped" in err and f"skipped {log}:8" in err
    assert json.loads(out)["capture"]["bad_lines_skipped"] == 1


@pytest.mark.parametrize(("args", "says"), [(["--window", "0"], "--window"), (["--id-base", "zz"], "'zz'"),
                                            (["--conflict", "oldest"], "--conflict")])
def test_usage_errors_exit_2(tmp_path: Path, args: list[str], says: str) -> None:
    code, _, err = invoke(str(_swarm_log(tmp_path / "swarm.log")), *args)
    assert code == 2 and says in err


def test_serial_capture_reports_what_it_can(tmp_path: Path) -> None:
    framing = make_serial_framing("cobs8")
    capture = tmp_path / "radio.cap"
    lines = ["# vstig serial capture v1\n"]
    for t, msg in ((0.0, Message(Op.PUT, 3, 7, 1, 4)), (0.1, Message(Op.GET, 3, 7, 1, 4)),
                   (0.9, Message(Op.PUT, 3, 7, 1, 4))):
        lines += [f"({T0 + t:.6f}) radio0 cobs8 rx {unit.hex()}\n" for unit in framing.encode(msg)]
    capture.write_text("".join(lines))
    code, out, err = invoke(str(capture), "--json")
    assert code == 0, err
    report = json.loads(out)
    assert report["capture"]["links_without_sender"] == ["radio0"]
    (write,) = report["writes"]
    assert write["converged_after_s"] is None and write["senders_total"] == 0
    assert write["heard"]["radio0"] == {"first": pytest.approx(T0), "last": pytest.approx(T0 + 0.9), "copies": 3}
    assert report["summary"]["measured"] == 0
    code, out, _ = invoke(str(capture))
    assert "name no sender" in out and "0.000..0.900" in out


def test_progress_bar_goes_to_a_terminal_stderr_only(tmp_path: Path) -> None:
    log = tmp_path / "big.log"
    line = _line(0.1, 1, Message(Op.PUT, 3, 10, 1, 1))
    log.write_text(line * (1_200_000 // len(line) + 1))  # over 1 MB
    terminal = PtyPeer()
    try:
        process = subprocess.Popen([VSTIG, "analyze", str(log), "--json"], stdout=subprocess.PIPE,
                                   stderr=terminal.slave, text=True)
        out, _ = process.communicate(timeout=120)
        seen = b""
        end = time.monotonic() + 5
        while time.monotonic() < end and select.select([terminal.master], [], [], 0.2)[0]:
            seen += os.read(terminal.master, 65536)
    finally:
        terminal.close()
    assert process.returncode == 0
    assert json.loads(out)["capture"]["messages"] > 10_000  # stdout is the JSON alone
    assert b"analyzing big.log" in seen
    piped = subprocess.run([VSTIG, "analyze", str(log), "--json"], capture_output=True, text=True, timeout=120,
                           check=False)
    assert "analyzing" not in piped.stderr and piped.returncode == 0
