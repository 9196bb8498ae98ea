"""A gateway as a systemd service: the unit `vstig service` writes passes `systemd-analyze verify`, and a real
`vstig bridge` speaks the notify protocol to a socket this test plays the service manager on (READY=1 once its
links are open, WATCHDOG=1 from its loop only while the loop runs, STOPPING=1 and a clean exit on SIGTERM)."""

from __future__ import annotations

import itertools
import os
import signal
import socket
import subprocess
import threading
import time
from pathlib import Path

import pytest
from peers import has_open, run_vstig, start_vstig, stop
from required import require_tool
from robots import PtyRobot

from vstig_cli.ops.notify import ServiceNotifier
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


def _env(address: str, **extra: str) -> dict[str, str]:
    return {**os.environ, "NOTIFY_SOCKET": address, "WATCHDOG_USEC": str(int(WATCHDOG_S * 1e6)), **extra}


def test_the_unit_passes_systemd_analyze_verify(tmp_path: Path) -> None:
    analyze = require_tool("systemd-analyze", "systemd")
    folder = tmp_path / "a lab's 100% folder"  # ExecStart= quoting: a space, a quote and a % specifier
    folder.mkdir()
    config = folder / "lab.toml"
    config.write_text('links = ["serial:/dev/ttyUSB0?framing=epuck4", "can:socketcan:can0"]\nrobot-id = 200\n')
    unit = tmp_path / "vstig-lab.service"
    made = run_vstig("service", "--config", str(config), "--user", "vstig", "-o", str(unit))
    assert made.returncode == 0, made.stderr
    text = unit.read_text()
    assert "Type=notify" in text and "WatchdogSec=30" in text and "Restart=on-failure" in text
    checked = subprocess.run([analyze, "verify", str(unit)], capture_output=True, text=True, timeout=60, check=False)
    assert checked.returncode == 0 and checked.stderr.strip() == "", checked.stderr
    quoted = '"' + str(config).replace("%", "%%") + '"'  # one word, % doubled (systemd.service(5))
    assert f"--config {quoted}\n" in text
    again = run_vstig("service", "--config", str(config), "-o", str(unit))
    assert again.returncode == 2 and "--overwrite" in again.stderr  # a unit the user has is not replaced


def test_service_refuses_a_config_the_gateway_would_refuse(tmp_path: Path) -> None:
    config = tmp_path / "lab.toml"
    config.write_text("robot-id = 200\ntick = nan\n")
    done = run_vstig("service", "--config", str(config))
    assert done.returncode == 2 and "lab.toml:2: tick: 'nan' is not a finite number" in done.stderr
    config.write_text("robot-id = 200\n")
    done = run_vstig("service", "--config", str(config))
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
    stop_loop = threading.Event()
    with node:
        loop = threading.Thread(target=node.run, kwargs={"stop": stop_loop})
        loop.start()
        try:
            time.sleep(0.8)
            before = len(manager.said("WATCHDOG=1"))
            with node._lock:  # a stuck participant (a listener that does not return) holds the Node
                stalled = time.monotonic()
                time.sleep(1.2)
            released = time.monotonic()
            time.sleep(0.6)
        finally:
            stop_loop.set()
            loop.join()
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
