"""`make chaos`: three `vstig bridge` gateways federated over Zenoh on 127.0.0.1, and a fault every 30 s.

    python tests/chaos/run.py [--seconds 1800] [--fault-every 30] [--rate 800] [--summary FILE]

The swarm (tests/chaos/swarm.py, a process of its own): five robots on cobs8 pty radios
and one behind an slcan adapter we play on a pty, writing --rate PUTs a second in all.
Gateway 0 has radios 1 and 2, gateway 1 radios 3 and 4, gateway 2 radio 5 and the
adapter of robot 6; the gateways reach each other only through cables we can pull
(tests/chaos/proxy.py). Every --fault-every seconds one fault, from this rotation:

    partition   a gateway's cables pulled, then put back
    sigterm     a gateway stopped (its stop timed: <= 2 s, status 0, counters), then started again
    kill        a gateway killed (SIGKILL) and started again at once
    deaf-radio  a robot stops reading its radio, whose line fills, then reads again
    deaf-can    the same for the slcan adapter
    garbage     noise on a radio's or the adapter's line, in bursts (each ends a frame or line)
    liar        a robot on a radio claims other robots' keys far ahead
    unplug      a radio or the adapter unplugged, then plugged back under the same name
    flood       a foreign Zenoh peer floods a gateway with 64 KiB samples, then leaves

The judge (swarm.py) owes every write to every other robot; a pair is late past 2 s,
lost if never settled, excused only where the fault touched its path (a gateway
stopped, a cable pulled, a robot's radio deaf or unplugged): noise, lies and floods
excuse nothing. After each fault that heals, every robot must hold every key's
timestamp of that moment within the time left before the next fault. Resident memory
of each gateway is sampled every 2 s; each stop is timed. Each gateway runs under a
played systemd (tests/played_systemd.py, as `make supervised`): a notify socket,
READY=1 awaited, WatchdogSec --watchdog (a gateway whose pings stop that long is ended
with SIGABRT, which fails the run), the longest gap between pings reported, STOPPING=1
owed at every stop. One table at the end; the run fails on any lost pair, a stop over
2 s or that did not end cleanly (status 0, counters printed, STOPPING=1 said), a heal
that did not converge, a gateway that died by itself, or more than --max-growth MB
grown by one life of a gateway (counted from --warmup s after its start).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import multiprocessing
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the played systemd, shared with `make supervised`

from played_systemd import PlayedSystemd
from proxy import Cable
from swarm import LATE_S, serve

VSTIG = str(Path(sys.executable).with_name("vstig"))
FLOOD = str(Path(__file__).with_name("flood.py"))
SWARM = "chaos"
STOP_S = 2.0  # what a stop may take
SETTLE_S = 3.0  # after a heal, the paths it touched stay excused this long (Zenoh redials, a gateway starts)
# (robot, gateway, on CAN); the liar and the garbage rotate over these robots
LAYOUT = [(1, 0, False), (2, 0, False), (3, 1, False), (4, 1, False), (5, 2, False), (6, 2, True)]
RADIOS = [robot for robot, _, on_can in LAYOUT if not on_can]
ADAPTER = next(robot for robot, _, on_can in LAYOUT if on_can)
CABLES = [(1, 0), (2, 0), (2, 1)]  # who dials whom
ZENOH_CONFIG = ("{ scouting: { gossip: { enabled: false } }, "  # no gateway learns another's address: cables only
                "transport: { link: { tx: { lease: 2000, keep_alive: 4 } } } }")  # a pulled cable noticed in 2 s
Heal = Callable[[], object]


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def rss_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except (FileNotFoundError, ProcessLookupError):
        return None
    return None


@dataclass
class Life:
    """One run of a gateway process: its resident memory over time (seconds since the run began, MB)."""

    started: float
    manager: PlayedSystemd
    rss: list[tuple[float, float]] = field(default_factory=list)


class Gateway:
    def __init__(self, index: int, argv: list[str], folder: str, watchdog: float, record: str | None = None) -> None:
        self.index = index
        self.argv = argv
        self.record = record  # a folder: each life records into gw<index>-<life>.mcap there (`vstig why` reads them)
        self.folder = Path(folder)
        self.watchdog = watchdog
        self.process: subprocess.Popen[str] | None = None
        self.log: list[str] = []
        self.lives: list[Life] = []
        self.deaths: list[str] = []  # ends nobody asked for

    def start(self, now: float, wait: float = 60.0) -> None:
        self.log = []
        manager = PlayedSystemd(self.folder / f"notify-{self.index}-{len(self.lives)}", self.watchdog)
        argv = self.argv if self.record is None else \
            [*self.argv, "--record", str(Path(self.record) / f"gw{self.index}-{len(self.lives)}.mcap")]
        process = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                   env={**os.environ, **manager.env()})
        manager.watch(process)
        self.process = process
        log = self.log
        threading.Thread(target=lambda: log.extend(process.stderr or ()), daemon=True).start()
        end = time.monotonic() + wait
        while not (manager.ready and any("Ctrl-C stops" in line for line in log)):
            if process.poll() is not None or time.monotonic() > end:
                raise RuntimeError(f"gateway {self.index} did not start (READY=1 {manager.ready}): "
                                   f"{''.join(log)[-2000:]}")
            time.sleep(0.02)
        self.lives.append(Life(now, manager))

    def stop(self, signum: int = signal.SIGTERM) -> tuple[float, int, bool]:
        """Signal it and wait: (seconds it took, exit status, whether it printed its counters and said STOPPING=1)."""
        process = self.process
        assert process is not None
        manager = self.lives[-1].manager
        manager.stopping()
        started = time.monotonic()
        process.send_signal(signum)
        try:
            status = process.wait(timeout=60)
        except subprocess.TimeoutExpired:
            process.kill()
            status = process.wait()
        took = time.monotonic() - started
        time.sleep(0.1)  # the pump reads the last lines
        manager.join()
        self.process = None
        return took, status, any(line.startswith("engine: ") for line in self.log) and manager.said("STOPPING=1")

    def check(self, now: float) -> None:
        """A gateway that ended by itself is a failure of the run, said at once; then it is started again
        (systemd's Restart=on-failure), so the run goes on and its table still comes out."""
        process = self.process
        if process is not None and process.poll() is not None:
            manager = self.lives[-1].manager
            manager.join()
            death = (f"gateway {self.index} died at {now:.0f} s (status {process.returncode}, watchdog fired "
                     f"{manager.fired.is_set()}, longest ping gap {manager.longest_gap:.2f} s): "
                     f"{''.join(self.log)[-1500:]}")
            print(f"  {death}", flush=True)
            self.deaths.append(death)
            self.process = None
            self.start(now)

    def sample(self, now: float) -> None:
        if self.process is not None and self.lives:
            rss = rss_mb(self.process.pid)
            if rss is not None:
                self.lives[-1].rss.append((now, rss))


@dataclass
class Fault:
    number: int
    kind: str
    target: str
    started: float
    parts: frozenset[tuple[Any, ...]]
    heal: Heal
    stop_s: float | None = None  # a sigterm's stop
    rss_delta: float | None = None  # a flood's, on the flooded gateway
    converged_s: float | None = None
    healed: bool = False


class Chaos:
    def __init__(self, args: argparse.Namespace, folder: str) -> None:
        self.args = args
        self.folder = folder
        self.t0 = time.monotonic()
        fork = multiprocessing.get_context("fork")
        self.conn, child_conn = fork.Pipe()
        self.child = fork.Process(target=serve, args=(folder, LAYOUT, args.rate, self.t0, child_conn), daemon=True)
        self.child.start()  # before any thread: a fork copies only the calling thread
        assert self.conn.recv() == "ready"
        self.ports = [free_port() for _ in range(3)]
        self.cables = {pair: Cable(self.ports[pair[1]]) for pair in CABLES}
        config = Path(folder) / "zenoh.json5"
        config.write_text(ZENOH_CONFIG + "\n")
        self.gateways = []
        for g in range(3):
            specs = [f"serial:{folder}/radio{r}?framing=cobs8" if not can else f"can:slcan:{folder}/can{r}"
                     for r, gw, can in LAYOUT if gw == g]
            zenoh = f"zenoh:{SWARM}?listen=tcp/127.0.0.1:{self.ports[g]}&config={config}"
            dials = [self.cables[pair].port for pair in CABLES if pair[0] == g]
            if dials:
                zenoh += "&connect=" + ",".join(f"tcp/127.0.0.1:{port}" for port in dials)
            self.gateways.append(Gateway(g, [VSTIG, "bridge", *specs, zenoh, "--robot-id", str(200 + g)], folder,
                                         args.watchdog, args.record))
        self.faults: list[Fault] = []
        # (which, seconds, status, counters printed and STOPPING=1 said)
        self.stops: list[tuple[str, float, int, bool]] = []

    def now(self) -> float:
        return time.monotonic() - self.t0

    def tell(self, *command: Any) -> Any:
        self.conn.send(command)
        return self.conn.recv()

    # -- the faults ----------------------------------------------------------------
    def rotation(self, n: int) -> tuple[str, str, frozenset[tuple[Any, ...]], Callable[[], Heal]]:
        """The n-th fault: its kind, target, the parts of the swarm it touches, and how to cause it."""
        kinds = ["partition", "sigterm", "deaf-radio", "garbage", "kill", "deaf-can", "liar", "unplug", "flood"]
        kind, turn = kinds[n % len(kinds)], n // len(kinds)
        g = turn % 3
        radio = RADIOS[(turn + n) % len(RADIOS)]
        if kind == "partition":
            pairs = [pair for pair in CABLES if g in pair]
            return kind, f"gateway {g}", frozenset(("zenoh", min(p), max(p)) for p in pairs), \
                lambda: self._partition(pairs)
        if kind in ("sigterm", "kill"):
            return kind, f"gateway {g}", frozenset({("gateway", g)}), lambda: self._restart(g, kind)
        if kind in ("deaf-radio", "deaf-can"):
            robot = radio if kind == "deaf-radio" else ADAPTER
            return kind, f"robot {robot}", frozenset({("to", robot)}), lambda: self._deaf(robot)
        if kind == "garbage":
            robot = ([*RADIOS, ADAPTER])[turn % (len(RADIOS) + 1)]
            return kind, f"robot {robot}", frozenset(), lambda: self._garbage(robot)
        if kind == "liar":
            return kind, f"radio of robot {radio}", frozenset(), lambda: self._liar(radio)
        if kind == "unplug":
            robot = ([*RADIOS, ADAPTER])[(turn + 1) % (len(RADIOS) + 1)]
            return kind, f"robot {robot}", frozenset({("from", robot), ("to", robot)}), lambda: self._unplug(robot)
        return kind, f"gateway {g}", frozenset(), lambda: self._flood(g)

    def _partition(self, pairs: list[tuple[int, int]]) -> Heal:
        for pair in pairs:
            self.cables[pair].pull()
        return lambda: [self.cables[pair].heal() for pair in pairs]

    def _restart(self, g: int, kind: str) -> Heal:
        gateway = self.gateways[g]
        took, status, counters = gateway.stop(signal.SIGTERM if kind == "sigterm" else signal.SIGKILL)
        if kind == "sigterm":
            self.stops.append((f"gateway {g} (fault)", took, status, counters))
            self.faults[-1].stop_s = took
        time.sleep(0.5 if kind == "sigterm" else 0.0)
        gateway.start(self.now())
        return lambda: None

    def _deaf(self, robot: int) -> Heal:
        self.tell("deafen", robot)
        return lambda: self.tell("hear", robot)

    def _garbage(self, robot: int) -> Heal:
        self.tell("garbage", robot, 4096)  # a burst every half second, until told otherwise
        return lambda: self.tell("garbage", robot, 0)

    def _liar(self, radio: int) -> Heal:
        self.tell("lie", radio)
        return lambda: self.tell("lie", None)

    def _unplug(self, robot: int) -> Heal:
        self.tell("unplug", robot)
        return lambda: self.tell("replug", robot)

    def _flood(self, g: int) -> Heal:
        gateway = self.gateways[g]
        before = rss_mb(gateway.process.pid) if gateway.process else None
        flood = subprocess.Popen([sys.executable, FLOOD, f"tcp/127.0.0.1:{self.ports[g]}", SWARM,
                                  str(self.args.active)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        fault = self.faults[-1]

        def heal() -> None:
            try:
                flood.wait(timeout=30)
            except subprocess.TimeoutExpired:
                flood.kill()
                flood.wait()
            time.sleep(2.0)  # what it sent has been handled
            after = rss_mb(gateway.process.pid) if gateway.process else None
            if before is not None and after is not None:
                fault.rss_delta = after - before

        return heal

    # -- the run ---------------------------------------------------------------------
    def run(self) -> int:
        args = self.args
        for gateway in self.gateways:
            gateway.start(self.now())
        self.tell("converge-within", max(3.0, args.fault_every - args.active - 2.0))
        next_fault = args.fault_every
        end = args.seconds
        last_fault_at = end - max(args.fault_every / 2, args.active + 8)
        print(f"chaos: {end:.0f} s, 3 gateways over Zenoh on 127.0.0.1, radios {RADIOS} and slcan robot {ADAPTER}, "
              f"{args.rate:.0f} PUTs/s, a fault every {args.fault_every:.0f} s", flush=True)
        next_sample = 0.0
        while (now := self.now()) < end:
            if now >= next_sample:
                next_sample = now + 2.0
                for gateway in self.gateways:
                    gateway.check(self.now())
                    gateway.sample(now)
            if now >= next_fault and now < last_fault_at:
                self._one_fault(len(self.faults))
                next_fault += args.fault_every
            time.sleep(0.05)
        self.tell("stop-writing")
        time.sleep(args.drain)
        for gateway in self.gateways:
            gateway.check(self.now())
            gateway.sample(self.now())
        swarm = self.tell("report")
        for gateway in self.gateways:
            if gateway.process is not None:
                took, status, counters = gateway.stop()
                self.stops.append((f"gateway {gateway.index} (end)", took, status, counters))
        for cable in self.cables.values():
            cable.close()
        self.child.join(timeout=10)
        return self.report(swarm)

    def _one_fault(self, n: int) -> None:
        kind, target, parts, cause = self.rotation(n)
        started = time.monotonic()
        fault = Fault(n, kind, target, self.now(), parts, lambda: None)
        self.faults.append(fault)
        self.tell("fault", n, parts, started)
        print(f"  {self.now():6.0f} s  fault {n}: {kind} ({target})", flush=True)
        heal = cause()
        fault.heal = heal
        until = time.monotonic() + (0.0 if kind in ("sigterm", "kill") else self.args.active)
        while time.monotonic() < until:
            for gateway in self.gateways:
                gateway.check(self.now())
            time.sleep(0.05)
        heal()
        fault.healed = True
        self.tell("healed", n, time.monotonic(), SETTLE_S)

    # -- the table -------------------------------------------------------------------
    def report(self, swarm: dict[str, Any]) -> int:
        args = self.args
        problems: list[str] = []
        for fault in self.faults:
            fault.converged_s = swarm["convergence"].get(fault.number)
        pairs = swarm["on_time"] + swarm["late"] + swarm["lost"]
        print(f"\nchaos table ({args.seconds:.0f} s, {swarm['writes']:,} writes, {len(self.faults)} faults, "
              f"{args.rate:.0f} PUTs/s offered)")
        print(f"  {'fault':<11} {'n':>3}  {'stop s (max)':>12}  {'converged s (max)':>17}  {'flood RSS MB':>12}")
        for kind in dict.fromkeys(f.kind for f in self.faults):
            of = [f for f in self.faults if f.kind == kind]
            stops = [f.stop_s for f in of if f.stop_s is not None]
            conv = [f.converged_s for f in of]
            rss = [f.rss_delta for f in of if f.rss_delta is not None]
            conv_text = "-" if not conv else ("NOT" if None in conv else f"{max(c for c in conv if c is not None):.1f}")
            print(f"  {kind:<11} {len(of):>3}  {f'{max(stops):.2f}' if stops else '-':>12}  {conv_text:>17}  "
                  f"{' '.join(f'{d:+.0f}' for d in rss) if rss else '-':>12}")
            problems += [f"fault {f.number} ({kind}, {f.target}) did not converge within the time before the next"
                         for f in of if f.converged_s is None]
        print(f"  pairs judged {pairs:,}: on time {swarm['on_time']:,}, late (> {LATE_S:g} s) {swarm['late']:,}, "
              f"lost {swarm['lost']:,}; excused (a fault on the path) {swarm['excused']:,}")
        print(f"  delay p50 {swarm['p50'] * 1000:.0f} ms, p99 {swarm['p99'] * 1000:.0f} ms, "
              f"max {swarm['max']:.2f} s; lies told {swarm['lies']}, noise {swarm['garbage_bytes']:,} bytes")
        for example in swarm["late_examples"]:
            print(f"    late: {example}")
        if swarm["lost"]:
            problems.append(f"{swarm['lost']} pairs lost on healthy paths")
        worst = max((took for _, took, _, _ in self.stops), default=0.0)
        print(f"  stops {len(self.stops)}: max {worst:.2f} s, all clean (status 0, counters, STOPPING=1): "
              f"{all(status == 0 and clean for _, _, status, clean in self.stops)}")
        for which, took, status, clean in self.stops:
            if took > STOP_S or status != 0 or not clean:
                problems.append(f"{which}: stop took {took:.2f} s, status {status}, "
                                f"counters printed and STOPPING=1 said: {clean}")
        growth = 0.0
        for gateway in self.gateways:
            for life in gateway.lives:
                warm = [(t, mb) for t, mb in life.rss if t - life.started >= args.warmup]
                if len(warm) >= 2:
                    grown = warm[-1][1] - warm[0][1]
                    growth = max(growth, grown)
                    print(f"  gateway {gateway.index} from {life.started:5.0f} s: RSS {warm[0][1]:.1f} -> "
                          f"{warm[-1][1]:.1f} MB ({grown:+.1f}) over {warm[-1][0] - warm[0][0]:.0f} s")
            watched = [life.manager for life in gateway.lives]
            gaps = [m.longest_gap for m in watched]
            print(f"  gateway {gateway.index} supervised: {len(watched)} lives, READY=1 in each, "
                  f"{sum(len(m.pings) for m in watched):,} watchdog pings, longest gap {max(gaps, default=0):.2f} s "
                  f"(WatchdogSec {args.watchdog:g}), watchdog fired {sum(m.fired.is_set() for m in watched)}")
            problems += [f"gateway {gateway.index}: the watchdog fired (no ping for {args.watchdog:g} s)"
                         for m in watched if m.fired.is_set()]
            problems += gateway.deaths
            problems += [f"gateway {gateway.index}: {line.strip()}" for line in gateway.log if "Traceback" in line]
        if growth > args.max_growth:
            problems.append(f"resident memory grew {growth:.1f} MB (more than {args.max_growth:g})")
        summary = {"seconds": args.seconds, "writes": swarm["writes"], "pairs": pairs, "lost": swarm["lost"],
                   "late": swarm["late"], "excused": swarm["excused"], "faults": [f.kind for f in self.faults],
                   "converged": [f.converged_s for f in self.faults],
                   "stops": [took for _, took, _, _ in self.stops],
                   "stops_clean": all(s == 0 and c for _, _, s, c in self.stops), "rss_growth_mb": growth,
                   "watchdog_longest_gap_s": max((life.manager.longest_gap for g in self.gateways for life in g.lives),
                                                 default=0.0),
                   "watchdog_fired": sum(life.manager.fired.is_set() for g in self.gateways for life in g.lives),
                   "problems": problems}
        if args.summary:
            Path(args.summary).write_text(json.dumps(summary, indent=1))
        if problems:
            print("chaos FAILED:\n  " + "\n  ".join(problems))
            return 1
        print("chaos ok: 0 lost on healthy paths, every stop clean within 2 s, every heal converged")
        return 0

    def close(self) -> None:
        for gateway in self.gateways:
            if gateway.process is not None and gateway.process.poll() is None:
                gateway.process.kill()
                gateway.process.wait()
        for cable in self.cables.values():
            cable.close()
        if self.child.is_alive():
            self.child.kill()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=float(os.environ.get("CHAOS_SECONDS", 1800)))
    parser.add_argument("--fault-every", type=float, default=30.0)
    parser.add_argument("--active", type=float, default=None, help="seconds a fault lasts (default: 1/3 of the "
                        "interval, at most 10)")
    parser.add_argument("--rate", type=float, default=800.0, help="PUTs a second, all robots together")
    parser.add_argument("--drain", type=float, default=5.0, help="seconds of quiet before the judge's last look")
    parser.add_argument("--warmup", type=float, default=20.0, help="seconds of a gateway's life before RSS counts")
    parser.add_argument("--max-growth", type=float, default=30.0, help="MB of resident growth that fails the run")
    parser.add_argument("--watchdog", type=float, default=5.0, help="WatchdogSec of the systemd played for each "
                        "gateway (a notify socket; a gateway whose pings stop this long is ended with SIGABRT)")
    parser.add_argument("--summary", help="write the figures as JSON here")
    parser.add_argument("--record", metavar="FOLDER", help="each gateway's life records its links into FOLDER "
                        "(bridge --record, .mcap), for `vstig why`")
    args = parser.parse_args()
    if args.active is None:
        args.active = min(10.0, args.fault_every / 3)
    folder = tempfile.mkdtemp(prefix="vstig-chaos-")
    chaos = None
    try:
        chaos = Chaos(args, folder)
        return chaos.run()
    finally:
        if chaos is not None:
            chaos.close()
        with contextlib.suppress(OSError):
            shutil.rmtree(folder)


if __name__ == "__main__":
    sys.exit(main())
