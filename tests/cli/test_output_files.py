"""No command replaces a file the user names (decode -o, sim --capture/--snapshot, analyze --plot) unless
--overwrite says so: one line naming the file, exit 2, the file as it was. `record` is in test_record_files.py."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from vstig_cli.main import cli
from vstig_hw.capture.records import read_capture

LOG = "".join(f"(1700000000.{i}00000) can0 60{i}#000300{i:02X}00010001\n" for i in range(1, 4))
PRECIOUS = b"an earlier capture"


def _vstig(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(cli, list(args))
    return result.exit_code, result.output


def _refused(code: int, output: str, path: Path) -> bool:
    return (code == 2 and f"{path} exists: --overwrite replaces it" in output and "Traceback" not in output
            and path.read_bytes() == PRECIOUS)


@pytest.fixture
def log(tmp_path: Path) -> Path:
    path = tmp_path / "swarm.log"
    path.write_text(LOG)
    return path


def test_decode_refuses_an_existing_mcap_unless_overwrite(tmp_path: Path, log: Path) -> None:
    bag = tmp_path / "run.mcap"
    bag.write_bytes(PRECIOUS)
    assert _refused(*_vstig("decode", str(log), "--format", "mcap", "-o", str(bag)), bag)
    code, output = _vstig("decode", str(log), "--format", "mcap", "-o", str(bag), "--overwrite")
    assert code == 0, output
    assert len(list(read_capture(str(bag)))) == 3


def test_decode_into_an_empty_file_is_no_loss(tmp_path: Path, log: Path) -> None:
    bag = tmp_path / "made-by-mktemp.mcap"
    bag.touch()
    code, output = _vstig("decode", str(log), "--format", "mcap", "-o", str(bag))
    assert code == 0, output
    assert len(list(read_capture(str(bag)))) == 3


def test_decode_never_writes_over_one_of_its_inputs(tmp_path: Path, log: Path) -> None:
    bag = tmp_path / "run.mcap"
    assert _vstig("decode", str(log), "--format", "mcap", "-o", str(bag))[0] == 0
    before = bag.read_bytes()
    code, output = _vstig("decode", str(bag), str(log), "--format", "mcap", "-o", str(bag), "--overwrite")
    assert code == 2 and f"{bag} is also an input" in output
    assert bag.read_bytes() == before


def test_decode_names_a_wrong_extension_before_the_existing_file(tmp_path: Path, log: Path) -> None:
    out = tmp_path / "run.txt"
    out.write_bytes(PRECIOUS)
    code, output = _vstig("decode", str(log), "--format", "mcap", "-o", str(out))
    assert code == 2 and "an MCAP capture is named *.mcap" in output and out.read_bytes() == PRECIOUS


def test_sim_refuses_an_existing_capture_before_running(tmp_path: Path) -> None:
    capture = tmp_path / "sim.log"
    capture.write_bytes(PRECIOUS)
    sim = ["sim", "--topology", "line", "--robots", "5", "--runs", "1", "--workers", "1", "--capture", str(capture)]
    code, output = _vstig(*sim)
    assert _refused(code, output, capture) and "convergence steps" not in output  # refused before any run
    code, output = _vstig(*sim, "--overwrite")
    assert code == 0, output
    assert len(list(read_capture(str(capture)))) == 25  # 5 robots x 5 steps


def test_sim_refuses_an_existing_snapshot_unless_overwrite(tmp_path: Path) -> None:
    png = tmp_path / "d1.png"
    png.write_bytes(PRECIOUS)
    sim = ["sim", "--topology", "motion", "--robots", "10", "--density", "1", "--snapshot", str(png)]
    assert _refused(*_vstig(*sim), png)
    code, output = _vstig(*sim, "--overwrite")
    assert code == 0, output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_analyze_refuses_an_existing_plot_file_unless_overwrite(tmp_path: Path, log: Path) -> None:
    other = tmp_path / "other.log"
    other.write_bytes(PRECIOUS)
    assert _refused(*_vstig("analyze", str(log), "--plot", str(other)), other)  # a capture typed as --plot
    png = tmp_path / "key3.png"
    png.write_bytes(PRECIOUS)
    assert _refused(*_vstig("analyze", str(log), "--plot", str(png)), png)
    code, output = _vstig("analyze", str(log), "--plot", str(png), "--overwrite")
    assert code == 0, output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_sim_paper_regenerates_its_reports_in_the_folder(tmp_path: Path) -> None:
    out = tmp_path / "paper"
    out.mkdir()
    (out / "comparison.md").write_text("from an older run")
    code, output = _vstig("sim", "paper", "--runs", "1", "--robots", "10", "--workers", "1", "-o", str(out))
    assert code == 0, output
    assert "| cluster N=10 P=0.75 |" in (out / "comparison.md").read_text()


# Every command that writes a file the user names refuses a symbolic link there, dangling or not, with or
# without --overwrite (or --append): exit 2, one line, nothing written where the link points.
_THROUGH_A_LINK = [
    ["record", "can:virtual:x", "-o", "{out}.log", "--for", "0.1"],
    ["record", "can:virtual:x", "-o", "{out}.log", "--for", "0.1", "--overwrite"],
    ["record", "can:virtual:x", "-o", "{out}.log", "--for", "0.1", "--append"],
    ["decode", "{log}", "-o", "{out}.log"],
    ["decode", "{log}", "-o", "{out}.log", "--overwrite"],
    ["analyze", "{log}", "--plot", "{out}.png", "--overwrite"],
    ["sim", "--runs", "1", "--robots", "10", "--capture", "{out}.log", "--overwrite"],
    ["sim", "--topology", "motion", "--robots", "10", "--snapshot", "{out}.png", "--overwrite"],
]


@pytest.mark.parametrize("dangling", [True, False], ids=["dangling", "live"])
@pytest.mark.parametrize("args", _THROUGH_A_LINK, ids=lambda args: " ".join(args[:1] + args[3:]))
def test_no_output_is_written_through_a_symbolic_link(tmp_path: Path, log: Path, args: list[str],
                                                      dangling: bool) -> None:
    line = [arg.format(out=tmp_path / "out", log=log) for arg in args]
    link = Path(next(arg for arg in line if arg.startswith(str(tmp_path / "out"))))
    target = tmp_path / f"elsewhere{link.suffix}"
    if not dangling:
        target.write_bytes(PRECIOUS)
    link.symlink_to(target)
    code, output = _vstig(*line)
    assert code == 2, output
    assert f"{link} is a symbolic link" in output and "Traceback" not in output, output
    assert (target.read_bytes() == PRECIOUS) if not dangling else not target.exists()


def test_sim_paper_writes_no_report_through_a_link(tmp_path: Path) -> None:
    out = tmp_path / "paper"
    out.mkdir()
    target = tmp_path / "elsewhere.csv"
    target.write_bytes(PRECIOUS)
    (out / "runs.csv").symlink_to(target)
    code, output = _vstig("sim", "paper", "--runs", "1", "--robots", "10", "--workers", "1", "-o", str(out))
    assert code == 2 and f"{out / 'runs.csv'} is a symbolic link" in output, output
    assert target.read_bytes() == PRECIOUS


def test_an_output_folder_that_is_a_link_is_fine(tmp_path: Path, log: Path) -> None:
    real = tmp_path / "real"
    real.mkdir()
    (tmp_path / "linked").symlink_to(real)
    code, output = _vstig("decode", str(log), "-o", str(tmp_path / "linked" / "copy.log"))
    assert code == 0, output
    assert len(list(read_capture(str(real / "copy.log")))) == 3


@pytest.mark.parametrize("bits", [0o4755, 0o2755, 0o6755])
def test_a_file_replaced_never_keeps_its_setuid_or_setgid_bit(tmp_path: Path, log: Path, bits: int) -> None:
    """What replaces it holds bytes robots sent: with the bits, anyone could run them as its owner (root keeps
    them when it writes; Linux clears them for everyone else)."""
    import stat

    from peers import run_vstig

    out = tmp_path / "run.log"  # a candump log, as robots' frames are kept
    out.write_bytes(PRECIOUS)
    out.chmod(bits)
    done = run_vstig("decode", str(log), "-o", str(out), "--overwrite")
    assert done.returncode == 0, done.stderr
    mode = out.stat().st_mode
    assert not mode & (stat.S_ISUID | stat.S_ISGID) and stat.S_IMODE(mode) == 0o755  # the rest as it was
    assert out.read_bytes() != PRECIOUS
