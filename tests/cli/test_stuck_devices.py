"""A device that stops taking data neither holds a stop nor counts as gone (issue 38, items 2 and 3).

The adapter is our slcan adapter on a pty (peers.SlcanAdapter) made deaf as a hung USB
adapter is: it reads nothing and its line is full, so every write the command makes
would wait for ever. Before, python-can's slcan driver wrote with no timeout: a command
opening such an adapter ignored SIGTERM for good, one closing it (record never sends, so
its last write had no timeout either) too; and one write that timed out counted the
adapter as lost, tore the bus down and reopened it inside the same stuck write.
"""

from __future__ import annotations

import signal
import subprocess
import threading
import time
from pathlib import Path

import can
import pytest
from peers import PtyPeer, SlcanAdapter, fill, start_vstig, wait_for

from vstig_hw import Message, Op
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.can import CanFraming, CanIdScheme

STOP_S = 2.0  # what a stop may take, whatever the devices do (docs/how-to/bridge.md)


class Run:
    """A vstig command, its stderr collected as it comes."""

    def __init__(self, *args: str) -> None:
        self.process = start_vstig(*args)
        self.lines: list[str] = []
        assert self.process.stderr is not None
        self._pump = threading.Thread(target=lambda: self.lines.extend(self.process.stderr or ()), daemon=True)
        self._pump.start()

    def said(self, words: str) -> bool:
        return any(words in line for line in self.lines)

    def stop(self, sig: int = signal.SIGTERM) -> tuple[int, float]:
        """Signal it; its exit status and how long it took to end. One alive 10 s later is killed and fails."""
        started = time.monotonic()
        self.process.send_signal(sig)
        try:
            code = self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            raise AssertionError(f"{self.process.args} still ran 10 s after SIGTERM: {''.join(self.lines)}") from None
        took = time.monotonic() - started
        self._pump.join(timeout=5)
        return code, took

    @property
    def text(self) -> str:
        return "".join(self.lines)


@pytest.fixture
def adapter() -> SlcanAdapter:
    made = SlcanAdapter()
    yield made  # type: ignore[misc]
    made.close()


@pytest.mark.parametrize("command", [["record", "-o", "{tmp}/lab.log"], ["bridge", "--robot-id", "9"],
                                     ["sniff", "--jsonl"]], ids=["record", "bridge", "sniff"])
def test_a_hung_adapter_at_open_is_one_line_not_a_command_that_ignores_sigterm(
        adapter: SlcanAdapter, command: list[str], tmp_path: Path) -> None:
    adapter.deafen()
    args = [arg.replace("{tmp}", str(tmp_path)) for arg in command]
    run = Run(args[0], f"can:slcan:{adapter.path}", *args[1:])
    wait_for(lambda: run.process.poll() is not None, 5 + STOP_S)  # the open gives up on its own
    run.stop()
    assert run.process.returncode == 1, run.text
    assert run.said(f"cannot open CAN slcan channel {adapter.path}: the adapter took no command within"), run.text
    assert "Traceback" not in run.text and len(run.lines) == 1, run.text
    assert not (tmp_path / "lab.log").exists()  # nothing was recorded: no file


@pytest.mark.parametrize("command", [["record", "-o", "{tmp}/lab.mcap"], ["bridge", "--robot-id", "9"]],
                         ids=["record", "bridge"])
def test_a_stop_while_the_adapter_is_hung_ends_in_two_seconds_with_the_counters(
        adapter: SlcanAdapter, command: list[str], tmp_path: Path) -> None:
    radio = PtyPeer()
    try:
        args = [arg.replace("{tmp}", str(tmp_path)) for arg in command]
        run = Run(args[0], f"can:slcan:{adapter.path}", f"serial:{radio.path}?framing=cobs8", *args[1:])
        wait_for(lambda: run.said("Ctrl-C stops"), 30)
        adapter.deafen()
        time.sleep(1.0)  # the bridge's writes meet the full line
        code, took = run.stop()
        assert code == 0 and took <= STOP_S, (code, took, run.text)
        name = adapter.path.replace("/", "_").lstrip("_")
        assert any(line.startswith(f"{name}: ") for line in run.lines), run.text  # the counters
        assert "Traceback" not in run.text and not run.said("lost"), run.text
    finally:
        radio.close()


def test_a_slow_adapter_keeps_its_link_and_is_said_once(adapter: SlcanAdapter) -> None:
    """A deaf spell: what the gateway sends there is dropped and counted, what the adapter hears still crosses,
    and the link is never torn down; one line when it starts, one when the adapter reads again."""
    radio = PtyPeer()
    cobs = make_serial_framing("cobs8")
    robot = CanFraming(CanIdScheme(), sender=5)
    heard: list[Message] = []
    try:
        run = Run("bridge", f"can:slcan:{adapter.path}", f"serial:{radio.path}?framing=cobs8", "--robot-id", "9")
        wait_for(lambda: run.said("Ctrl-C stops"), 30)
        adapter.deafen()
        for value in range(1, 40):  # a CAN robot keeps writing while its adapter takes nothing from us
            for frame in robot.encode(Message(Op.PUT, 7, value, value, 5)):
                adapter.inject(frame)
            heard += cobs.feed(radio.read(0.05))
        wait_for(lambda: run.said("is not taking what we send in time"), 10)
        deadline = time.monotonic() + 10
        while not any(m.key == 7 and m.value == 39 for m in heard) and time.monotonic() < deadline:
            heard += cobs.feed(radio.read(0.05))
        assert any(m.key == 7 and m.value == 39 for m in heard), heard[-5:]  # its frames still cross

        sent_before = len(adapter.sent)
        adapter.listening.set()  # it reads again: the gateway's frames reach it again
        wait_for(lambda: run.said("CAN device takes what we send again"), 15)
        radio.write(b"".join(cobs.encode(Message(Op.PUT, 8, 88, 1, 40))))
        wait_for(lambda: any(isinstance(f, can.Message) and f.data[:2] == b"\x00\x08"
                             for f in adapter.sent[sent_before:]), 15)
        code, _took = run.stop()
        assert code == 0, run.text
        name = adapter.path.replace("/", "_").lstrip("_")
        (counters,) = [line for line in run.lines if line.startswith(f"{name}: ")]
        assert "tx_timeout=" in counters and "lost=" not in counters and "reconnects=" not in counters, counters
        assert not run.said("lost"), run.text
        assert sum("is not taking what we send in time" in line for line in run.lines) == 1, run.text
    finally:
        radio.close()


def test_a_full_line_at_open_is_refused_in_half_a_second(tmp_path: Path) -> None:
    """Straight from the transport: the open of a hung adapter gives up within its bound, port closed."""
    from vstig_hw.transports.base import TransportError
    from vstig_hw.transports.can import CanTransport

    peer = PtyPeer()
    try:
        fill(peer.path)
        transport = CanTransport("slcan", peer.path)
        started = time.monotonic()
        with pytest.raises(TransportError, match="took no command"):
            transport.open()
        assert time.monotonic() - started < 1.5
    finally:
        peer.close()


def test_closing_a_port_gives_a_reader_what_was_written_and_a_deaf_one_half_a_second() -> None:
    """A closing port waits for the kernel to hand its output to a device that reads, never for one that does not."""
    from vstig_hw.transports.serial import CLOSE_DRAIN, SerialTransport

    listening, deaf = PtyPeer(), PtyPeer()
    try:
        port = SerialTransport(listening.path)
        port.open()
        got = bytearray()
        reader = threading.Thread(target=lambda: [got.extend(listening.read(0.05)) for _ in range(40)], daemon=True)
        reader.start()
        port.write(b"x" * 3000)  # more than a pty takes at once is not needed: what is queued must reach it
        port.close()
        reader.join()
        assert bytes(got) == b"x" * 3000

        fill(deaf.path)  # the line to the far end is full, and nobody reads it
        port = SerialTransport(deaf.path)
        port.open()
        port.write(b"y" * 100)  # waits its write_timeout, then counted
        started = time.monotonic()
        port.close()
        assert time.monotonic() - started < CLOSE_DRAIN + 0.5
        assert port.counters["tx_timeout"] == 1 and port.counters["disconnects"] == 0
    finally:
        listening.close()
        deaf.close()


def test_noise_on_the_adapter_line_costs_only_its_own_lines(adapter: SlcanAdapter) -> None:
    """Bursts of any bytes between a CAN robot's frames: every frame crosses, the noise is counted (rx_garbage),
    and the adapter is never taken for lost (python-can's reader raised on such lines, and after one byte that is
    not ASCII on every line: the adapter was reopened again and again, 2 s each)."""
    import random

    radio = PtyPeer()
    cobs = make_serial_framing("cobs8")
    robot = CanFraming(CanIdScheme(), sender=5)
    heard: list[Message] = []
    try:
        run = Run("bridge", f"can:slcan:{adapter.path}", f"serial:{radio.path}?framing=cobs8", "--robot-id", "9")
        wait_for(lambda: run.said("Ctrl-C stops"), 30)
        for key in range(1, 51):
            adapter.write(random.randbytes(512).replace(b"\r", b"").replace(b"\x07", b"") + b"\r")  # one line
            for frame in robot.encode(Message(Op.PUT, key, key, 1, 5)):
                adapter.inject(frame)
            heard += cobs.feed(radio.read(0.01))
        deadline = time.monotonic() + 10
        while {m.key for m in heard if m.value == m.key} != set(range(1, 51)) and time.monotonic() < deadline:
            heard += cobs.feed(radio.read(0.05))
        assert {m.key for m in heard if m.value == m.key} == set(range(1, 51))
        code, _took = run.stop()
        assert code == 0, run.text
        name = adapter.path.replace("/", "_").lstrip("_")
        (counters,) = [line for line in run.lines if line.startswith(f"{name}: ")]
        assert "rx_garbage=50" in counters and "lost=" not in counters, counters
    finally:
        radio.close()
