"""ROS 2 (issue 35): a ros2: link's latency and cost, each beside an anchor measured in the same run.

* Radio -> ROS 2 subscriber: a PUT written on a cobs8 pty radio, read by a plain rclpy
  subscriber of the gateway's `heard/<link>` topic, beside a bare rclpy publisher ->
  subscriber of the same message type at the same rate (goal: p50 <= 2x).
* Gateway CPU per relayed message, pty -> pty in engine mode, with a ros2: link that a
  ROS 2 node subscribes to (every heard topic and changes) beside the same bridge
  without it (goal: <= 1.3x); context switches beside them. The subscriber's own CPU
  is its process's, not the gateway's.

Every DDS process runs in a network namespace with only lo, on a domain of this
run's own (tests/dds.py), so nothing leaves the machine; that needs root.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

from .bench_datapath import COUNT, VSTIG, _frames, _paced, _quantiles, _relaying, _usage
from .registry import Result, benchmark

_REPO = Path(__file__).resolve().parents[1]
LATENCY_COUNT = 2000
LATENCY_RATE = 500  # messages a second: a busy swarm, well under what either path carries


class _Dds:
    """A namespace with only lo for this benchmark's ROS 2 processes, and the environment they run with."""

    def __enter__(self) -> _Dds:
        sys.path.insert(0, str(_REPO / "tests"))
        import dds

        reason = dds.unavailable()
        if reason:
            raise RuntimeError(f"the ros2 benchmarks need {reason}")
        self.host = dds.Host("bench")
        self.env = {**os.environ, **dds.environment()}
        self.gateway_env = dds.vstig_environment()  # the gateways `_relaying` starts: as a user's
        return self

    def __exit__(self, *exc: object) -> None:
        self.host.close()

    def start(self, *argv: str) -> subprocess.Popen[str]:
        return subprocess.Popen([*self.host.command(), *argv], env=self.env, text=True, cwd=_REPO,
                                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)

    def peer(self, *args: str) -> subprocess.Popen[str]:
        peer = self.start(sys.executable, "-m", "benchmarks.ros2_peer", *args)
        if args[0] != "publish":
            assert peer.stdout is not None and peer.stdout.readline().strip() == "ready"
        return peer


def _result(process: subprocess.Popen[str]) -> object:
    out, _ = process.communicate(timeout=120)
    return json.loads(out.strip().splitlines()[-1])


def _radio_to_ros2(ros: _Dds) -> tuple[float, ...]:
    """(p50, p90, p99) seconds from a PUT written on a pty radio to a ROS 2 subscriber of heard/<that radio>."""
    argv = lambda a, b: [VSTIG, "bridge", f"serial:{a}?framing=cobs8", f"serial:{b}?framing=cobs8",  # noqa: E731
                         "ros2:lab", "--robot-id", "200", "--budget", "2000", "--no-refresh"]
    with _relaying(argv, True, ros.gateway_env, tuple(ros.host.command())) as (_, a, _out):
        from vstig_hw.framing.ros2 import ros_name
        from vstig_hw.links import parse

        subscriber = ros.peer("receive", f"/vstig/lab/heard/{ros_name(parse(f'serial:{a.path}').name)}",
                              str(LATENCY_COUNT), "60")
        frames = _frames(LATENCY_COUNT)
        sent = _paced(lambda f: os.write(a.master, f), frames, LATENCY_RATE)
        arrived = _result(subscriber)
    assert isinstance(arrived, dict)
    return _quantiles([arrived[str(i)] - t for i, t in enumerate(sent) if str(i) in arrived])


def _bare(ros: _Dds) -> tuple[float, ...]:
    """(p50, p90, p99) seconds from a bare rclpy publisher to a subscriber, same type, rate and count."""
    publisher = ros.peer("publish", "/bench/bare", str(LATENCY_COUNT), str(LATENCY_RATE))  # waits for it:
    subscriber = ros.peer("receive", "/bench/bare", str(LATENCY_COUNT), "60")  # ready once they match
    sent = _result(publisher)
    arrived = _result(subscriber)
    assert isinstance(sent, list) and isinstance(arrived, dict)
    return _quantiles([arrived[str(i)] - t for i, t in enumerate(sent) if str(i) in arrived])


@benchmark("ros2")
def radio_to_ros2_latency() -> Iterator[Result]:
    with _Dds() as ros:
        bare = _bare(ros)
        ours = _radio_to_ros2(ros)
    for (label, _), value, anchor in zip((("p50", 0), ("p90", 0), ("p99", 0)), ours, bare, strict=True):
        yield Result(f"ros2.radio_to_subscriber_{label}", value * 1e3, "ms", f"bare rclpy pub -> sub {label}",
                     anchor * 1e3)


def _relay_cpu(ros: _Dds, with_ros2: bool, pure: bool = False) -> tuple[float, float, float, int]:
    """(CPU s per message, switches per message, p50 delay s, delivered) of an engine bridge relaying pty -> pty
    (`pure`: the whole Node in Python, VSTIG_PURE=1; with a ros2: link, whose listeners want every message, the
    Node delivers in Python and its engine and outlets stay compiled)."""
    extra = ["ros2:lab"] if with_ros2 else []
    argv = lambda a, b: [VSTIG, "bridge", f"serial:{a}?framing=cobs8", f"serial:{b}?framing=cobs8",  # noqa: E731
                         *extra, "--robot-id", "200", "--budget", "2000", "--no-refresh"]
    env = {**ros.gateway_env, "VSTIG_PURE": "1"} if pure else ros.gateway_env
    with _relaying(argv, True, env, tuple(ros.host.command())) as (pid, a, out):
        watcher = ros.peer("subscribe", "/vstig/lab", "30") if with_ros2 else None
        frames = _frames(COUNT)
        cpu0, sw0 = _usage(pid)
        sent = _paced(lambda f: os.write(a.master, f), frames)
        out.wait(COUNT + 1)
        cpu1, sw1 = _usage(pid)
        if watcher is not None:
            watcher.terminate()
            watcher.wait(timeout=30)
    delays = [out.arrived[i] - sent[i] for i in range(len(sent)) if i in out.arrived]
    return (cpu1 - cpu0) / COUNT, (sw1 - sw0) / COUNT, _quantiles(delays)[0], len(delays)


@benchmark("ros2")
def gateway_cost() -> Iterator[Result]:
    with _Dds() as ros:
        without = _relay_cpu(ros, False)
        pure = _relay_cpu(ros, False, pure=True)
        with_ros2 = _relay_cpu(ros, True)
    yield Result("ros2.gateway_cpu_per_msg", with_ros2[0] * 1e6, "us", "the same bridge without ros2 CPU/msg",
                 without[0] * 1e6)
    yield Result("ros2.gateway_cpu_per_msg_vs_pure", with_ros2[0] * 1e6, "us",
                 "the same bridge without ros2, pure path, CPU/msg", pure[0] * 1e6)
    yield Result("ros2.gateway_switches_per_msg", with_ros2[1], "/msg", "the same bridge without ros2",
                 without[1])
    yield Result("ros2.gateway_relay_p50", with_ros2[2] * 1e3, "ms", "the same bridge without ros2 p50",
                 without[2] * 1e3)
