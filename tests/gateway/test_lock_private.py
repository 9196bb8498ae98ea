"""The Node's lock is its own: no module outside vstig_hw/gateway/ takes it (a contract, like the layers').

Read from the source (every module of the library, the CLI and the examples: nobody reaches for a `_lock`
or a `lock` that is not its own), and watched at run time (a program using every call of the Python API
on a real python-can bus: every acquire of the Node's lock comes from a module of the gateway).
"""

from __future__ import annotations

import ast
import sys
import threading
import time
from pathlib import Path
from typing import Any

import can

import vstig_hw
from vstig_hw import Entry, Message, Op, Stigmergy
from vstig_hw.framing.can import can_framing_for

ROOT = Path(__file__).parents[2]
GATEWAY = ROOT / "vstig_hw" / "gateway"
CHECKED = [ROOT / "vstig_hw", ROOT / "cli", ROOT / "examples"]


def _reaches_for_a_lock(path: Path) -> list[str]:
    """`x._lock` or `x.lock` where x is not `self`, and getattr(x, "_lock"...): where a module takes another's lock."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Attribute) and node.attr in ("_lock", "lock"):
            if not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")):
                found.append(f"{path.relative_to(ROOT)}:{node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "getattr" \
                and any(isinstance(arg, ast.Constant) and arg.value in ("_lock", "lock") for arg in node.args):
            found.append(f"{path.relative_to(ROOT)}:{node.lineno}: {ast.unparse(node)}")
    return found


def test_no_module_outside_the_gateway_reaches_for_the_nodes_lock() -> None:
    modules = [path for folder in CHECKED for path in folder.rglob("*.py") if GATEWAY not in path.parents]
    assert len(modules) > 100
    found = [line for path in modules for line in _reaches_for_a_lock(path)]
    assert found == []


def test_the_reading_above_finds_a_module_that_takes_the_lock() -> None:
    source = "def f(swarm):\n    with swarm._node._lock:\n        pass\n    getattr(node, 'lock')\n"
    path = ROOT / "tests" / "gateway" / "lock_taker.py"
    path.write_text(source)
    try:
        assert len(_reaches_for_a_lock(path)) == 2
    finally:
        path.unlink()


class _Watched:
    """The Node's RLock, noting the file of every frame that takes it."""

    def __init__(self, lock: Any, takers: set[str]) -> None:
        self._inner, self._takers = lock, takers

    def acquire(self, *args: Any, **kwargs: Any) -> bool:
        self._takers.add(sys._getframe(1).f_code.co_filename)
        return bool(self._inner.acquire(*args, **kwargs))

    def release(self) -> None:
        self._inner.release()

    def __enter__(self) -> bool:
        self._takers.add(sys._getframe(1).f_code.co_filename)
        return bool(self._inner.__enter__())

    def __exit__(self, *exc: object) -> None:
        self._inner.__exit__(*exc)


def test_a_program_using_the_whole_api_takes_the_lock_only_through_the_gateway(tmp_path: Path) -> None:
    channel = f"lock-{time.monotonic_ns()}"
    robot_bus = can.Bus(interface="virtual", channel=channel)
    robot, codec = Stigmergy(7), can_framing_for(7)
    running = True

    def robot_runs() -> None:  # hears, re-broadcasts, answers: confirms our writes
        while running:
            frame = robot_bus.recv(0.01)
            if frame is not None:
                for msg in codec.feed(frame):
                    robot.receive(msg)
            for msg in robot.drain():
                robot_bus.send(codec.encode(msg)[0])

    thread = threading.Thread(target=robot_runs, daemon=True)
    thread.start()
    takers: set[str] = set()
    swarm = vstig_hw.join(f"can:virtual:{channel}", robot_id=50, period=0.02)
    node = swarm._node
    node._lock = _Watched(node._lock, takers)  # type: ignore[assignment]
    try:
        changes = swarm.watch()
        called: list[object] = []
        handle = swarm.on_change(called.append)
        recording = swarm.record(tmp_path / "lock.log")
        assert swarm.put(1, 10) == Entry(10, 1, 50)
        assert swarm.put(2, 20, confirm=True, timeout=2.0) == Entry(20, 1, 50)
        assert swarm.get(1) == 10 and swarm.entry(2) == Entry(20, 1, 50) and sorted(swarm.keys()) == [1, 2]
        assert swarm.submit(lambda: 5).result(2) == 5
        robot.put(3, 30)
        deadline = time.monotonic() + 5
        while swarm.entry(3) is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert swarm.stats()["engine"]["stored"] >= 1 and changes.get(1.0) is not None
        handle.cancel()
        recording.stop()
        robot_bus.send(codec.encode(Message(Op.PUT, 4, 4, 1, 7))[0])
    finally:
        swarm.close()
        running = False
        thread.join(2)
        robot_bus.shutdown()
    assert recording.records > 0 and called
    outside = {taker for taker in takers if Path(taker).parent != GATEWAY}
    assert takers and outside == set()
