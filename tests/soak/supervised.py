"""`make supervised`: a `vstig bridge` run from a config file under systemd's supervision, played here, for hours.

    python tests/soak/supervised.py [--seconds 1800] [--watchdog 5]

This plays the service manager of a `Type=notify` unit with `WatchdogSec`: it gives the gateway a notify
socket, waits for READY=1, and would end it with SIGABRT (as systemd does) on a watchdog ping missing for
`--watchdog` seconds. Two robots on pty radios (cobs8) write through it: robot A puts ten keys round-robin
every 10 ms, robot B gets them every control step. Checked at the end, after SIGTERM:

* the watchdog never fired (the longest gap between pings is printed beside the limit);
* 0 lost: B holds A's last value of every key, and no counter of the gateway counts a drop;
* the stop: STOPPING=1 said, exit 0, within 15 s (the unit's TimeoutStopSec).
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "cli"))  # the tests' peers and robots
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from peers import VSTIG
from played_systemd import PlayedSystemd
from robots import PtyRobot

KEYS = range(1, 11)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=1800)
    parser.add_argument("--watchdog", type=float, default=5.0)
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="vstig-supervised-"))
    a, b = PtyRobot(1), PtyRobot(2, watch=KEYS)
    config = folder / "lab.toml"
    config.write_text(f'links = ["{a.spec}", "{b.spec}"]\nrobot-id = 200\n')
    manager = PlayedSystemd(folder / "notify", args.watchdog)
    gateway = subprocess.Popen([VSTIG, "bridge", "--config", str(config)], env={**os.environ, **manager.env()},
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    manager.watch(gateway)
    fired = manager.fired
    end = time.monotonic() + 30
    while not manager.ready:
        if time.monotonic() > end or gateway.poll() is not None:
            gateway.kill()
            print(f"FAIL: no READY=1 within 30 s: {gateway.communicate()[1][-2000:]}", file=sys.stderr)
            return 1
        time.sleep(0.05)
    print(f"ready; running {args.seconds:.0f} s", file=sys.stderr)
    last: dict[int, int] = {}
    started = time.monotonic()
    sent = 0
    while time.monotonic() - started < args.seconds and not fired.is_set():
        key = KEYS[sent % len(KEYS)]
        sent += 1
        last[key] = sent & 0xFFFF
        a.put(key, last[key])
        a.step()
        b.step()
        time.sleep(0.01)
    settle = time.monotonic() + 10
    while time.monotonic() < settle and any(b.value(k) != v for k, v in last.items()):
        a.step()
        b.step()
        time.sleep(0.05)
    asked = time.monotonic()
    manager.stopping()
    gateway.send_signal(signal.SIGTERM)
    try:
        _, err = gateway.communicate(timeout=15)
    except subprocess.TimeoutExpired:
        gateway.kill()
        _, err = gateway.communicate()
    took = time.monotonic() - asked
    manager.join()
    pings, gap = manager.pings, manager.longest_gap
    lost = {k: (v, b.value(k)) for k, v in last.items() if b.value(k) != v}
    drops = re.findall(r"\b((?:drop_\w+|tx_overflow|tx_dropped|lost)=\d+)", err)
    stopping = manager.said("STOPPING=1")
    print(f"writes {sent}, pings {len(pings)}, longest gap {gap:.2f} s (limit {args.watchdog:.1f}), watchdog fired "
          f"{fired.is_set()}, lost {len(lost)} {lost or ''}, drop counters {drops or 'none'}, STOPPING=1 {stopping}, "
          f"exit {gateway.returncode} in {took:.2f} s", file=sys.stderr)
    print(err.strip().splitlines()[-3:], file=sys.stderr)
    a.close()
    b.close()
    ok = not fired.is_set() and not lost and not drops and stopping and gateway.returncode == 0 and took < 15
    print("PASS" if ok else "FAIL", file=sys.stderr)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
