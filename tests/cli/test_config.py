"""`--config FILE` and `--print-config`: commands that run from a TOML file, real processes on real ptys.

The file is refused where the command line would be (the same types and checks), errors name the file, the line
and the option, the command line overrides the file, and the file follows the deployment-file rules.
"""

from __future__ import annotations

import os
import threading
import time
import tomllib
from pathlib import Path

import pytest
from peers import run_vstig, start_vstig, stop, wait_for
from robots import PtyRobot


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def test_a_bridge_runs_from_its_config_file_alone(tmp_path: Path) -> None:
    writer, reader = PtyRobot(5), PtyRobot(6, watch=(7,))
    config = _write(tmp_path / "lab.toml",
                    f'links = ["{writer.spec}", "{reader.spec}"]\nrobot-id = 200\ntick = 0.05\n')
    gateway = start_vstig("bridge", "--config", str(config))
    try:
        wait_for(lambda: reader.value(7) == 42, 30,
                 step=lambda: (writer.put(7, 42), reader.step(), time.sleep(0.05)))
    finally:
        _, err = stop(gateway)
        writer.close()
        reader.close()
    assert gateway.returncode == 0, err
    assert "robot 200" in err  # the file's robot id


def test_the_command_line_overrides_the_file_and_print_config_reads_back(tmp_path: Path) -> None:
    config = _write(tmp_path / "lab.toml", 'links = ["serial:/dev/ttyUSB0"]\nrobot-id = 200\ntick = 0.5\n'
                                           'trust = ["ttyUSB0=1-3"]\nrefresh = false\nfor = 60\n')
    shown = run_vstig("bridge", "--config", str(config), "can:socketcan:can0", "--tick", "0.2", "--deny", "can0=9",
                      "--print-config")
    assert shown.returncode == 0, shown.stderr
    effective = tomllib.loads(shown.stdout)
    assert effective["links"] == ["can:socketcan:can0"]  # LINKs on the command line replace the file's
    assert effective["tick"] == 0.2 and effective["robot-id"] == 200 and effective["for"] == 60.0
    assert effective["trust"] == ["ttyUSB0=1-3"] and effective["deny"] == ["can0=9"]
    assert effective["refresh"] is False and effective["budget"] == 64  # a default, written out too
    assert "learn" not in effective and "# learn: not set" in shown.stdout
    again = _write(tmp_path / "effective.toml", shown.stdout)
    round_trip = run_vstig("bridge", "--config", str(again), "--print-config")
    assert round_trip.returncode == 0 and tomllib.loads(round_trip.stdout) == effective


@pytest.mark.parametrize(("body", "said"), [
    ("tick = nan", "lab.toml:2: tick: 'nan' is not a finite number"),
    ("tick = inf", "lab.toml:2: tick: 'inf' is not a finite number"),
    ("budget = 0", "lab.toml:2: budget: 0 is not in the range"),
    ("max-jump = 40000", "lab.toml:2: max-jump: 40000 is not in the range"),
    ("rate = -1.0", "lab.toml:2: rate:"),
    ("\n\ntikc = 1", "lab.toml:4: 'tikc' is not an option of vstig bridge"),
    ("trust = \"can0=1\"", "lab.toml:2: trust: a list"),
    ("trust = [\"can0\"]", "lab.toml:2: trust: 'can0' is not LINK=IDS"),
    ("foxglove = \"a:b\"", "lab.toml:2: foxglove: 'a:b': the port must be a number"),
    ("robot-id = 70000", "lab.toml:2: robot-id: 70000 is not in the range"),
    ("[bridge]\nraw = true", "lab.toml:2: 'bridge' is not an option"),
    ("raw = [true]", "lab.toml:2: raw: a list is not a value this option takes"),
    ("tick = = 1", "lab.toml: not valid TOML: Invalid value (at line 2"),
    ("trust = " + "[" * 100_000 + "]" * 100_000, "lab.toml: arrays or tables nested too deeply to read"),
])
def test_a_bad_value_is_refused_naming_the_file_line_and_option(tmp_path: Path, body: str, said: str) -> None:
    config = _write(tmp_path / "lab.toml", f'links = ["serial:/dev/ttyUSB0"]\n{body}\n')
    done = run_vstig("bridge", "--config", str(config), "--robot-id", "1")
    assert done.returncode == 2, done.stderr
    assert said in done.stderr and "Traceback" not in done.stderr


@pytest.mark.parametrize(("key", "meant"), [("robot_id", "robot-id"), ("max_jump", "max-jump"), ("tikc", "tick"),
                                           ("Larger-Value-Wins", "larger-value-wins")])
def test_a_misspelled_key_gets_the_closest_one(tmp_path: Path, key: str, meant: str) -> None:
    config = _write(tmp_path / "lab.toml", f'links = ["serial:loop://"]\n{key} = 1\n')
    done = run_vstig("bridge", "--config", str(config))
    assert done.returncode == 2 and f"lab.toml:2: {key!r} is not an option of vstig bridge; did you mean {meant}?" \
        in done.stderr, done.stderr
    far = _write(tmp_path / "far.toml", 'links = ["serial:loop://"]\nzzzzzz = 1\n')
    assert "did you mean" not in run_vstig("bridge", "--config", str(far)).stderr  # nothing close: no guess


MEGABYTE = "x" * 1_000_000


@pytest.mark.parametrize("body", [f'tick = "{MEGABYTE}"', f'"{MEGABYTE}" = 1',
                                  f'links = ["serial:loop://", "{MEGABYTE}"]',
                                  f'trust = ["{MEGABYTE}"]', f'foxglove = "{MEGABYTE}"'],
                         ids=["value", "key", "link", "list item", "address"])
def test_an_error_echoes_at_most_the_start_of_a_huge_value(tmp_path: Path, body: str) -> None:
    links = "" if body.startswith("links") else 'links = ["serial:loop://"]'
    config = _write(tmp_path / "lab.toml", f'robot-id = 1\n{links}\n{body}\n')
    done = run_vstig("bridge", "--config", str(config))
    assert done.returncode == 2 and "lab.toml:3" in done.stderr, done.stderr[:300]
    assert "x" * 80 + "'… (1000000 bytes)" in done.stderr  # what it was, cut, and how long
    assert max(len(line) for line in done.stderr.splitlines()) < 1200  # from a 1,000,143-byte line


def test_a_bad_link_in_the_file_is_refused_as_on_the_command_line(tmp_path: Path) -> None:
    config = _write(tmp_path / "lab.toml", 'robot-id = 1\nlinks = ["serial:/dev/ttyUSB0", "bogus:x"]\n')
    done = run_vstig("bridge", "--config", str(config))
    assert done.returncode == 2 and "lab.toml:2: links: " in done.stderr and "bogus" in done.stderr


def test_the_config_file_must_be_a_bounded_regular_file(tmp_path: Path) -> None:
    fifo = tmp_path / "fifo.toml"
    os.mkfifo(fifo)  # nobody writes it: reading it plainly would wait for ever
    big = _write(tmp_path / "big.toml", "# padding\n" * 120_000)
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b'links = ["serial:/dev/ttyUSB0"]\nrobot-id = 1 \xff\n')
    for path, said in ((fifo, "must be a regular file"), (Path("/dev/zero"), "must be a regular file"),
                       (tmp_path, "must be a regular file"), (tmp_path / "none.toml", "No such file"),
                       (big, "larger than the 1 MiB"), (binary, "binary.toml:2: not UTF-8")):
        started = time.monotonic()
        done = run_vstig("sniff", "--config", str(path), timeout=30)
        assert done.returncode == 2 and said in done.stderr and str(path) in done.stderr, (path, done.stderr)
        assert time.monotonic() - started < 20


def test_record_takes_its_output_and_duration_from_the_file(tmp_path: Path) -> None:
    radio = PtyRobot(3)
    capture = tmp_path / "swarm.cap"
    config = _write(tmp_path / "rec.toml", f'links = ["{radio.spec}"]\noutput = "{capture}"\nfor = 3.0\n')
    recorder = start_vstig("record", "--config", str(config))
    keep_writing = threading.Event()

    def robot() -> None:
        while not keep_writing.is_set():
            radio.put(1, 7)
            time.sleep(0.05)

    threading.Thread(target=robot, daemon=True).start()
    try:
        _, err = recorder.communicate(timeout=30)  # `for` ends it by itself
    finally:
        keep_writing.set()
        radio.close()
    assert recorder.returncode == 0, err
    assert capture.read_text().count("\n") > 2, err
    refused = run_vstig("record", "--config", str(config))  # the file's output exists: --overwrite is still needed
    assert refused.returncode == 2 and "--overwrite" in refused.stderr
