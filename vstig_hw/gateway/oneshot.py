"""One write or one read through a Node, checked against what the swarm says (`vstig put`, `vstig get`, the API).

`confirm_write` drives a `confirm.ConfirmedWrite` (the pure state machine: its
docstring has the rules) on a Node, for the CLI and the Python API alike: the
machine hears everything the links heard (a `messages` listener, on the
reader's thread as it arrives: the machine picks what concerns the write), what
that did to our table (`change`), and each control step (`tick`); what it asks
to send goes out through the Node; its verdict completes a Future the moment it
is reached. The Node's own threads run it: nothing else schedules it.
"""

from __future__ import annotations

import concurrent.futures
import time
from collections.abc import Callable, Sequence
from typing import Any

from ..engine import Entry
from ..links.link import Link
from ..wire import Message
from ..wording import counted
from .confirm import ConfirmedWrite, PutResult, Send, Verdict
from .node import Listening, Node, SwarmClosed

__all__ = ["HearsItself", "PutResult", "confirm_write", "get_newest", "not_taken", "put_confirmed", "unreached"]


class HearsItself(RuntimeError):
    """A link brings our own messages back (it echoes what it is sent), so no neighbour's answer can be told
    from our echo: a confirmed write cannot be confirmed there. `reason` is the message without the way to write
    anyway, which the message names as Python code does it (`vstig put` names its --no-confirm instead)."""

    def __init__(self, reason: str) -> None:
        super().__init__(f"{reason} (put(key, value, confirm=False) writes anyway)")
        self.reason = reason


def confirm_write(node: Node, key: int, value: int, *, learn: float = 0.0, wait: float = 2.0, tries: int = 3,
                  confirm: bool = True, spent: float = 0.0) -> concurrent.futures.Future[PutResult]:
    """Write `value` under `key` through an ENGINE node, checked as `confirm` says; its PutResult as a Future.

    It starts on the Node's loop (`submit`), which runs once the Node is open.
    Each write waits up to `wait` seconds for a neighbour to show it; `learn` seconds of asking come first.
    `spent`: seconds already used opening the node, taken from `learn`, then from the first write's wait.
    The future raises HearsItself when a link brings our own probe back, SwarmClosed when the node closes first.
    """
    engine = node.engine
    if engine is None:
        raise RuntimeError(f"a {node.mode.value} node cannot write")
    first_wait = max(0.0, wait - max(0.0, spent - learn))
    machine = ConfirmedWrite(key, engine.robot_id, learn=max(0.0, learn - spent), wait=wait, tries=tries,
                             confirm=confirm, first_wait=first_wait)
    driver = _Driver(node, machine, value)
    started = node.submit(driver.start)
    started.add_done_callback(driver.failed_to_start)
    return driver.future


class _Driver:
    """Runs one ConfirmedWrite on a Node: feeds it, sends what it asks, completes `future` with its verdict.

    Everything here runs under the Node's lock: `start` and `tick` on the loop's thread,
    `heard` and `changed` on a reader's, as the batch is handled (a write again after a
    superseding entry goes out from there, as a conflict hook's put does).
    """

    def __init__(self, node: Node, machine: ConfirmedWrite, value: int) -> None:
        self.node, self.machine, self.value = node, machine, value
        self.future: concurrent.futures.Future[PutResult] = concurrent.futures.Future()
        self._listening: Listening | None = None

    def start(self) -> None:
        self._listening = self.node.listen(messages=self._heard, change=self._changed, tick=self._tick,
                                           closed=self._closed)
        self._do(self.machine.start(time.monotonic()))

    def failed_to_start(self, started: concurrent.futures.Future[None]) -> None:
        error = started.exception()
        if error is not None:
            self._finish(error)

    # -- what the Node tells ---------------------------------------------------------
    def _heard(self, link: str, t: float, sender: int | None, messages: list[Message]) -> None:
        self._do(self.machine.heard_on(link, sender, messages, time.monotonic()))

    def _changed(self, key: int, old: Entry | None, new: Entry, link: str | None, sender: int | None) -> None:
        self._do(self.machine.table_changed(key, new, link, time.monotonic()))

    def _tick(self, node: Node) -> None:
        self._do(self.machine.tick(time.monotonic()))

    def _closed(self) -> None:
        try:
            self.node.check_open()
        except SwarmClosed as closed:
            self._finish(closed)

    # -- what the machine asks -------------------------------------------------------------
    def _do(self, sends: list[Send]) -> None:
        node, machine = self.node, self.machine
        try:
            for send in sends:
                if machine.done:
                    break
                if send is Send.PROBE:
                    node.probe(machine.key)
                elif send is Send.ASK:
                    node.get(machine.key)
                else:
                    entry = node.put(machine.key, self.value)
                    self._do(machine.wrote(entry, time.monotonic()))
        except SwarmClosed as closed:  # the node began closing (what it read is handed over then): no verdict
            self._finish(closed)
            return
        self._settle()

    def _settle(self) -> None:
        machine = self.machine
        if not machine.done or self.future.done():
            return
        if machine.verdict is Verdict.HEARS_ITSELF:
            self._finish(HearsItself(
                f"{machine.echoed_on} brings our own GETs back (robot id {machine.robot_id}): the radio echoes "
                "what we send, or another robot uses that id; no neighbour's answer can be told from our echo"))
        else:
            self._finish(machine.result())

    def _finish(self, outcome: PutResult | BaseException) -> None:
        if self._listening is not None:
            self._listening.cancel()
        if self.future.done():
            return
        if isinstance(outcome, BaseException):
            self.future.set_exception(outcome)
        else:
            self.future.set_result(outcome)


def put_confirmed(node: Node, key: int, value: int, *, learn: float, wait: float, tries: int = 3,
                  confirm: bool = True, spent: float = 0.0) -> PutResult:
    """`confirm_write` on an open node, waiting for its verdict (the Node closing first raises SwarmClosed)."""
    future = confirm_write(node, key, value, learn=learn, wait=wait, tries=tries, confirm=confirm, spent=spent)
    return future.result()


def not_taken(result: PutResult, key: int, where: str, wait: float, show: Callable[[Entry], str] = str, *,
              confirm: bool = True) -> str | None:
    """Why the write was not taken, in one line naming what the swarm holds; None when it was.

    Superseded is always a failure; unanswered only when a confirmation was asked for.
    """
    ours = show(result.written)
    if result.superseded:
        assert result.holds is not None
        return (f"key {key}: the swarm holds {show(result.holds)} on {where}, not our write ({ours}), "
                f"after {counted(result.tries, 'write')}")
    if confirm and not result.confirmed:
        said = f"the last entry heard was {show(result.heard)}" if result.heard else "nothing was heard for the key"
        return f"key {key}: no neighbour on {where} took our write ({ours}) within {wait:g} s; {said}"
    return None


def unreached(links: Sequence[Link[Any]]) -> str:
    """"; <link> reached nobody at connect=..." for each link told to connect that reaches nobody now ("" if
    none): why nothing answered, for the end of a failed put's or get's line. Read it while the links are open."""
    return "".join(f"; {link.name} {why}" for link in links if (why := link.unreached))


class _Asker:
    """A tick listener: each control step one GET for the key, an empty GET and a view GET in turn."""

    def __init__(self, key: int) -> None:
        self.key = key
        self.steps = 0

    def __call__(self, node: Node) -> None:
        self.steps += 1
        if self.steps % 2:
            node.ask(self.key)
        else:
            node.get(self.key)


def get_newest(node: Node, key: int, wait: float) -> Entry | None:
    """Ask every control step for `wait` seconds; the newest entry heard (conflicts resolved), or None."""
    engine = node.engine
    if engine is None:
        raise RuntimeError(f"a {node.mode.value} node cannot ask")
    asker = _Asker(key)
    with node.listen(tick=asker):
        asker(node)
        node.wait_closed(wait)  # the loop asks at every tick meanwhile; a Node that closes ends the wait
    return engine.entry(key)
