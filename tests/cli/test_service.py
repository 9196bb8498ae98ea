"""A gateway as a systemd service: the unit `vstig service` writes passes `systemd-analyze verify`, and a real
`vstig bridge` speaks the notify protocol to a socket this test plays the service manager on (READY=1 once its
links are open, WATCHDOG=1 from its loop only while the loop runs, STOPPING=1 and a clean exit on SIGTERM)."""

from __future__ import annotations

import grp
import itertools
import os
import re
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import click
import pytest
from peers import has_open, start_vstig, stop, wait_for
from ports import free_port
from real_systemd import RealSystemd
from required import require_tool
from robots import PtyRobot
from service_install import service_vstig

from vstig_cli.ops.notify import ServiceNotifier
from vstig_cli.ops.unit_file import write_new_file
from vstig_hw.gateway import Node
from vstig_hw.links import parse

WATCHDOG_S = 0.4  # pings every 0.2 s


class ServiceManager:
    """The manager's end of $NOTIFY_SOCKET: every datagram, with the time it came."""

    def __init__(self, address: str) -> None:
        self.socket = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.socket.bind("\0" + address[1:] if address.startswith("@") else address)
        self.socket.settimeout(0.1)
        self.address = address
        self.heard: list[tuple[float, str]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._listen, daemon=True)
        self._thread.start()

    def _listen(self) -> None:
        while not self._stop.is_set():
            try:
                data = self.socket.recv(4096)
            except TimeoutError:
                continue
            except OSError:
                return
            self.heard.append((time.monotonic(), data.decode()))

    def said(self, field: str) -> list[float]:
        return [t for t, text in self.heard if field in text.split("\n")]

    def wait(self, field: str, deadline: float = 30) -> float:
        end = time.monotonic() + deadline
        while not self.said(field):
            assert time.monotonic() < end, f"no {field} in {self.heard}"
            time.sleep(0.01)
        return self.said(field)[0]

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self.socket.close()


def run_service(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    """`vstig service ARGS` from a vstig its unit's own user can see (service_install.py)."""
    return subprocess.run([service_vstig(), "service", *args], capture_output=True, text=True, timeout=timeout,
                          check=False)


def _env(address: str, **extra: str) -> dict[str, str]:
    return {**os.environ, "NOTIFY_SOCKET": address, "WATCHDOG_USEC": str(int(WATCHDOG_S * 1e6)), **extra}


@pytest.fixture
def outside_tmp() -> Iterator[Path]:
    """A folder a unit with its own user can see (its /tmp is its own)."""
    with tempfile.TemporaryDirectory(dir="/dev/shm", prefix="vstig-service-") as folder:
        yield Path(folder)


LAB = 'links = ["serial:/dev/ttyUSB0?framing=epuck4", "can:socketcan:can0", "zenoh:lab"]\nrobot-id = 200\n'


def _analyze(*args: str) -> subprocess.CompletedProcess[str]:
    analyze = require_tool("systemd-analyze", "systemd")
    return subprocess.run([analyze, *args], capture_output=True, text=True, timeout=60, check=False)


def _exposure(unit: Path) -> float:
    """systemd-analyze security's overall exposure (0 safest, 10 UNSAFE) of a unit file, offline."""
    done = _analyze("security", "--offline=true", "--no-pager", str(unit))
    found = re.search(r"Overall exposure level for \S+: (\d+\.\d)", done.stdout)
    assert found, done.stdout[-500:] + done.stderr
    return float(found[1])


def _settings(text: str) -> dict[str, list[str]]:
    values: dict[str, list[str]] = {}
    for line in text.splitlines():
        key, sep, value = line.partition("=")
        if sep and not line.startswith("#"):
            values.setdefault(key, []).append(value)
    return values


def test_the_unit_passes_systemd_analyze_verify(tmp_path: Path) -> None:
    folder = tmp_path / "a lab's 100% folder"  # ExecStart= quoting: a space, a quote and a % specifier
    folder.mkdir()
    config = folder / "lab.toml"
    config.write_text(LAB)
    unit = tmp_path / "vstig-lab.service"
    made = run_service("--config", str(config), "--user", "daemon", "-o", str(unit))
    assert made.returncode == 0, made.stderr
    text = unit.read_text()
    assert "Type=notify" in text and "WatchdogSec=30" in text and "Restart=on-failure" in text
    checked = _analyze("verify", str(unit))
    assert checked.returncode == 0 and checked.stderr.strip() == "", checked.stderr
    quoted = '"' + str(config).replace("%", "%%") + '"'  # one word, % doubled (systemd.service(5))
    assert f"--config {quoted}\n" in text
    assert "PrivateTmp=yes" not in text  # the config is in /tmp: a /tmp of its own would hide it
    assert "warning: user daemon cannot read" in made.stderr  # pytest's folders are root's alone
    again = run_service("--config", str(config), "--user", "daemon", "-o", str(unit))
    assert again.returncode == 2 and "--overwrite" in again.stderr  # a unit the user has is not replaced


@pytest.mark.parametrize(("body", "devices", "families"), [
    (LAB, ["char-ttyUSB rw"], "AF_UNIX AF_CAN AF_INET AF_INET6 AF_NETLINK"),
    ('links = ["serial:/dev/ttyACM3", "serial:loop://"]\nrobot-id = 1\n', ["char-ttyACM rw"], "AF_UNIX"),
    ('links = ["can:virtual:lab", "serial:socket://localhost:7000"]\nrobot-id = 1\nmetrics = "9108"\n', [],
     "AF_UNIX AF_INET AF_INET6"),
], ids=["serial-can-zenoh", "serial-only", "no-devices"])
def test_the_unit_is_sandboxed_to_what_its_config_needs(outside_tmp: Path, body: str, devices: list[str],
                                                         families: str) -> None:
    """issue 45: the unit scored 9.6 UNSAFE (9.2 with --user); sandboxed it must score 3.0 or better."""
    config = outside_tmp / "lab.toml"
    config.write_text(body)
    unit = outside_tmp / "vstig-lab.service"
    made = run_service("--config", str(config), "-o", str(unit))
    assert made.returncode == 0, made.stderr
    settings = _settings(unit.read_text())
    assert settings["User"] == ["vstig"] and settings["DynamicUser"] == ["yes"]  # not root, by default
    assert settings["RestrictAddressFamilies"] == [families]
    assert settings["CapabilityBoundingSet"] == [""] and settings["UMask"] == ["0077"]
    assert settings["DevicePolicy"] == ["closed"] and settings.get("DeviceAllow", []) == devices
    assert ("PrivateDevices" in settings) == (not devices)  # no device at all: a /dev of its own
    assert ("SupplementaryGroups" in settings) == bool(devices)  # dialout for serial devices
    assert ("PrivateNetwork" in settings) == (families == "AF_UNIX")  # serial only: no network at all
    assert _analyze("verify", str(unit)).stderr.strip() == ""
    assert _exposure(unit) <= 3.0


def test_root_is_warned_and_still_sandboxed(outside_tmp: Path) -> None:
    config = outside_tmp / "lab.toml"
    config.write_text(LAB)
    unit = outside_tmp / "vstig-lab.service"
    made = run_service("--config", str(config), "--user", "root", "-o", str(unit))
    assert made.returncode == 0 and "warning: the unit runs the gateway as root (uid 0)" in made.stderr
    assert "User=" not in unit.read_text() and _exposure(unit) <= 3.5


def test_a_user_that_does_not_exist_is_refused(outside_tmp: Path) -> None:
    config = outside_tmp / "lab.toml"
    config.write_text(LAB)
    done = run_service("--config", str(config), "--user", "nosuchuser")
    assert done.returncode == 2 and "no user 'nosuchuser' on this machine" in done.stderr
    assert "useradd --system" in done.stderr and done.stdout == ""


@pytest.mark.parametrize("bad", ["\n", "\r", "\x01", "\x1b", "\x7f", "\x85"],
                         ids=["LF", "CR", "SOH", "ESC", "DEL", "NEL"])
def test_a_control_character_in_any_value_is_refused(outside_tmp: Path, bad: str) -> None:
    """issue 45: a config path with a newline wrote its lines into Description= and ExecStart=."""
    folder = outside_tmp / f"lab{bad}ExecStartPre=touch {outside_tmp}/pwned"
    folder.mkdir(parents=True)
    (folder / "lab.toml").write_text(LAB)
    done = run_service("--config", str(folder / "lab.toml"))
    assert done.returncode == 2 and "--config '" in done.stderr and "holds a control character" in done.stderr
    assert done.stdout == ""
    named = outside_tmp / f"lab{bad}.toml"  # the description, from the file's name
    named.write_text(LAB)
    assert "holds a control character" in run_service("--config", str(named)).stderr
    record = outside_tmp / "record.toml"  # ReadWritePaths=, from the record output in the file
    record.write_text(f'links = ["serial:loop://"]\noutput = "{outside_tmp}/caps{_toml(bad)}x/"\n')
    (outside_tmp / f"caps{bad}x").mkdir()
    done = run_service("--command", "record", "--config", str(record))
    assert done.returncode == 2 and "the folder recorded into '" in done.stderr, done.stderr
    clean = outside_tmp / "clean.toml"
    clean.write_text(LAB)
    done = run_service("--config", str(clean), "--user", f"x{bad}")
    assert done.returncode == 2 and "is not a user name" in done.stderr


def _toml(character: str) -> str:
    return f"\\u{ord(character):04x}"


def test_a_link_planted_at_the_output_is_never_followed(outside_tmp: Path) -> None:
    """issue 45: the symlink check and open(output, "w") were 0.5 s apart: a planted link overwrote its target."""
    config = outside_tmp / "lab.toml"
    config.write_text(LAB)
    target = outside_tmp / "passwd"
    target.write_text("root:x:0:0\n")
    unit = outside_tmp / "vstig-lab.service"
    for dangling in (False, True):
        unit.symlink_to(outside_tmp / "absent" if dangling else target)
        for extra in ((), ("--overwrite",)):
            done = run_service("--config", str(config), "-o", str(unit), *extra)
            assert done.returncode == 2 and f"{unit} is a symbolic link" in done.stderr, done.stderr
        unit.unlink()
    assert target.read_text() == "root:x:0:0\n" and not (outside_tmp / "absent").exists()
    made = run_service("--config", str(config), "-o", str(unit))
    assert made.returncode == 0 and stat.S_IMODE(unit.stat().st_mode) == 0o644, made.stderr
    before = unit.stat().st_ino
    replaced = run_service("--config", str(config), "--watchdog", "7", "-o", str(unit), "--overwrite")
    assert replaced.returncode == 0 and "WatchdogSec=7" in unit.read_text()
    assert unit.stat().st_ino != before  # a new file renamed over the old name, not the old one rewritten
    assert [p.name for p in outside_tmp.iterdir() if p.name.endswith(".tmp")] == []


_RACER = """
import os, signal, sys
swaps = 0
def done(*_):
    print(swaps)
    sys.exit(0)
signal.signal(signal.SIGTERM, done)
while True:
    try:
        os.symlink(sys.argv[1], sys.argv[2])
    except OSError:
        pass
    try:
        os.unlink(sys.argv[2])
    except OSError:
        pass
    swaps += 1
"""


def test_a_link_planted_at_any_moment_is_never_followed(outside_tmp: Path) -> None:
    """The race itself: a process swaps the output between a link to a target and nothing, as fast as it can,
    while units are written there with and without --overwrite. Whatever each write meets, the target is
    never written through; each write either lands as a whole unit or is refused."""
    target = outside_tmp / "target"
    target.write_text("keep\n")
    output = outside_tmp / "unit.service"
    racer = subprocess.Popen([sys.executable, "-c", _RACER, str(target), str(output)], stdout=subprocess.PIPE,
                             text=True)
    outcomes: Counter[str] = Counter()
    try:
        time.sleep(0.3)  # racing
        deadline = time.monotonic() + 20  # 400 writes at least, then on until both sides of the race were met
        n = 0
        while n < 400 or (len(outcomes) < 2 and time.monotonic() < deadline):
            n += 1
            try:
                write_new_file(str(output), f"unit {n}\n", overwrite=n % 2 == 1)
                outcomes["written"] += 1
            except click.UsageError as error:
                assert "symbolic link" in error.message or "exists" in error.message, error.message
                outcomes["refused"] += 1
    finally:
        racer.send_signal(signal.SIGTERM)
        swaps = int(racer.communicate(timeout=10)[0])
    assert target.read_text() == "keep\n" and swaps > 1000, swaps
    assert outcomes["written"] > 0 and outcomes["refused"] > 0, outcomes  # both sides of the race were met
    assert [p.name for p in outside_tmp.iterdir() if p.name.endswith(".tmp")] == []


def test_a_typo_in_the_config_is_named_as_vstig_service(outside_tmp: Path) -> None:
    """issue 44: `vstig service --config typo.toml` printed `Usage: vstig bridge ...`."""
    config = outside_tmp / "typo.toml"
    config.write_text('links = ["serial:loop://"]\nrobot_id = 200\n')
    done = run_service("--config", str(config))
    assert done.returncode == 2 and "Usage: vstig service" in done.stderr and "vstig bridge [" not in done.stderr
    assert f"{config}:2: 'robot_id' is not an option of vstig bridge; did you mean robot-id?" in done.stderr
    done = run_service("--config", str(outside_tmp / "none.toml"))
    assert done.returncode == 2 and "Usage: vstig service" in done.stderr and "none.toml" in done.stderr


def test_the_default_user_cannot_see_a_config_in_tmp(tmp_path: Path) -> None:
    config = tmp_path / "lab.toml"
    config.write_text(LAB)
    done = run_service("--config", str(config))
    assert done.returncode == 2 and f"move {config} out of /tmp, or give --user NAME" in done.stderr


def test_a_record_service_needs_a_folder_to_record_into(outside_tmp: Path) -> None:
    config = outside_tmp / "rec.toml"
    config.write_text('links = ["serial:loop://"]\n')
    done = run_service("--command", "record", "--config", str(config))
    assert done.returncode == 2 and "a record service needs output" in done.stderr
    (outside_tmp / "caps").mkdir()
    config.write_text(f'links = ["serial:loop://"]\noutput = "{outside_tmp}/caps"\n')
    done = run_service("--command", "record", "--config", str(config))
    assert done.returncode == 0 and f"ReadWritePaths={outside_tmp}/caps\n" in done.stdout


def test_service_refuses_a_config_the_gateway_would_refuse(tmp_path: Path) -> None:
    config = tmp_path / "lab.toml"
    config.write_text("robot-id = 200\ntick = nan\n")
    done = run_service("--config", str(config))
    assert done.returncode == 2 and "lab.toml:2: tick: 'nan' is not a finite number" in done.stderr
    config.write_text("robot-id = 200\n")
    done = run_service("--config", str(config))
    assert done.returncode == 2 and "needs links" in done.stderr


@pytest.mark.parametrize("abstract", [False, True], ids=["path", "abstract"])
def test_a_bridge_is_ready_once_its_links_are_open_pings_while_its_loop_runs_and_stops_on_sigterm(
        tmp_path: Path, abstract: bool) -> None:
    address = f"@vstig-test-{os.getpid()}" if abstract else str(tmp_path / "notify")
    manager = ServiceManager(address)
    a, b = PtyRobot(1), PtyRobot(2)
    gateway = start_vstig("bridge", a.spec, b.spec, "--robot-id", "200", env=_env(address))
    try:
        ready = manager.wait("READY=1")
        assert has_open(gateway.pid, a.radio.path) and has_open(gateway.pid, b.radio.path)
        time.sleep(1.5)
        pings = [t for t in manager.said("WATCHDOG=1") if t > ready]
        assert len(pings) >= 4, manager.heard  # ~7 in 1.5 s at one per 0.2 s
        assert max(b - a for a, b in itertools.pairwise(pings)) < 2.5 * WATCHDOG_S  # late under load, not lost

        gateway.send_signal(signal.SIGSTOP)  # the whole process stalls: no ping may come
        stalled = time.monotonic()
        time.sleep(1.0)
        assert not [t for t in manager.said("WATCHDOG=1") if t > stalled + 0.05]
        gateway.send_signal(signal.SIGCONT)
        resumed = time.monotonic()
        time.sleep(0.6)
        assert [t for t in manager.said("WATCHDOG=1") if t > resumed]

        asked = time.monotonic()
        _, err = stop(gateway, timeout=15)  # SIGTERM, as systemctl stop sends it
        took = time.monotonic() - asked
    finally:
        manager.close()
        a.close()
        b.close()
    assert gateway.returncode == 0 and took < 5, (took, err)
    assert manager.said("STOPPING=1")
    assert "\x1b" not in err  # stderr is no terminal: plain lines, no colour or redraws
    assert "\nengine: " in err  # the counters, printed on the way out


def test_pings_for_another_process_are_not_ours_to_send(tmp_path: Path) -> None:
    address = str(tmp_path / "notify")
    manager = ServiceManager(address)
    robot = PtyRobot(1)
    gateway = start_vstig("sniff", robot.spec, "--jsonl", env=_env(address, WATCHDOG_PID="1"))
    try:
        manager.wait("READY=1")
        time.sleep(1.0)
        assert not manager.said("WATCHDOG=1")
    finally:
        stop(gateway)
        manager.close()
        robot.close()


def test_a_loop_that_stalls_stops_the_pings(tmp_path: Path) -> None:
    """The lock held by a stuck participant: the loop cannot tick, so it must not say it is alive."""
    address = str(tmp_path / "notify")
    manager = ServiceManager(address)
    robot = PtyRobot(1)
    notifier = ServiceNotifier(address, WATCHDOG_S)
    node = Node([parse(robot.spec).build()], 200, period=0.05)
    node.listen(tick=notifier.tick)
    with node:
        time.sleep(0.8)
        before = len(manager.said("WATCHDOG=1"))
        with node._lock:  # a stuck participant (a listener that does not return) holds the Node
            stalled = time.monotonic()
            time.sleep(1.2)
        released = time.monotonic()
        time.sleep(0.6)
    notifier.close()
    manager.close()
    robot.close()
    pings = manager.said("WATCHDOG=1")
    assert before >= 3
    assert not [t for t in pings if stalled + 0.05 < t < released]
    assert [t for t in pings if t > released]  # a loop that runs again says so again


def test_the_environment_is_taken_out_for_children() -> None:
    env = {"NOTIFY_SOCKET": "@x", "WATCHDOG_USEC": "2000000", "WATCHDOG_PID": str(os.getpid()), "PATH": "/bin"}
    notifier = ServiceNotifier.from_environment(env)
    assert notifier is not None and notifier.ping_every == 1.0 and env == {"PATH": "/bin"}
    notifier.close()
    assert ServiceNotifier.from_environment({"NOTIFY_SOCKET": "relative/path"}) is None
    assert ServiceNotifier.from_environment({}) is None


def _status(systemd: RealSystemd, pid: int) -> dict[str, str]:
    """/proc/PID/status in the manager's PID namespace."""
    fields = (line.partition(":") for line in systemd.run("cat", f"/proc/{pid}/status").stdout.splitlines())
    return {key: value.strip() for key, _, value in fields}


@pytest.mark.parametrize("zenoh", [False, True], ids=["serial", "serial-zenoh-metrics"])
def test_the_gateway_runs_under_its_sandboxed_unit_in_a_real_systemd(outside_tmp: Path, zenoh: bool) -> None:
    """issue 45: whether the gateway still runs under the sandbox, shown: the unit `vstig service` writes (its
    own dynamic user, every setting) started by a real systemd, the robots' writes crossing it, then stopped."""
    writer, reader = PtyRobot(5), PtyRobot(6, watch=(7,))
    dialout = grp.getgrnam("dialout").gr_gid
    for radio in (writer.radio.path, reader.radio.path):  # as udev leaves a USB radio: root:dialout 0660
        os.chown(radio, 0, dialout)
        os.chmod(radio, 0o660)
    outside_tmp.chmod(0o755)  # as /etc/vstig: the service's user reads the config
    config = outside_tmp / "lab.toml"
    zenoh_lines = f', "zenoh:lab"]\nmetrics = "{free_port()}"\n' if zenoh else "]\n"  # AF_INET, AF_NETLINK
    config.write_text(f'robot-id = 200\ntick = 0.05\nlinks = ["{writer.spec}", "{reader.spec}"{zenoh_lines}')
    units = outside_tmp / "units"
    units.mkdir()
    made = run_service("--config", str(config), "--watchdog", "5", "-o", str(units / "vstig-lab.service"))
    assert made.returncode == 0 and "warning" not in made.stderr, made.stderr
    sentinel = tempfile.NamedTemporaryFile(prefix="vstig-sentinel-")  # noqa: SIM115  # the host's /tmp, untouched
    try:
        with RealSystemd(units) as systemd:
            started = systemd.systemctl("start", "vstig-lab")  # Type=notify: returns once READY=1 came
            assert started.returncode == 0, started.stderr + systemd.run("journalctl", "-u", "vstig-lab").stdout
            pid = int(systemd.show("vstig-lab", "MainPID"))
            seen = _status(systemd, pid)
            assert seen["Uid"].split()[0] != "0" and str(dialout) in seen["Groups"].split()  # DynamicUser
            assert seen["NoNewPrivs"] == "1" and int(seen["CapBnd"], 16) == 0 and seen["Seccomp"] == "2"
            mounts = {line.split()[4]: line.split()[5] for line in
                      systemd.run("cat", f"/proc/{pid}/mountinfo").stdout.splitlines()}
            assert mounts["/"].startswith("ro") and mounts["/tmp"].startswith("rw")  # ProtectSystem, PrivateTmp
            wait_for(lambda: reader.value(7) == 42, 30,
                     step=lambda: (writer.put(7, 42), reader.step(), time.sleep(0.05)))
            time.sleep(6)  # past WatchdogSec=5: pinging, not restarted
            assert systemd.show("vstig-lab", "NRestarts") == "0" and systemd.show("vstig-lab", "MainPID") == str(pid)
            stopped = systemd.systemctl("stop", "vstig-lab")
            assert stopped.returncode == 0, stopped.stderr
            assert systemd.show("vstig-lab", "Result") == "success"
            assert systemd.show("vstig-lab", "ExecMainStatus") == "0"
        assert os.path.exists(sentinel.name)
    finally:
        sentinel.close()
        writer.close()
        reader.close()
