"""A Node's loop, on a thread of its own: ticks every period, runs `submit`'s calls, sends what a window held back.

The links' frames are not handled here: each reader thread handles its own
(`delivery`). The loop sleeps on the DeliveryState's one wake-up token until the
next tick, a call, a budget window reopening (`retry_at`), a slow device's room, a
failure on a reader thread, or a stop; whichever comes first. How the loop and a
delivery agree on when to wake it is the DeliveryState's (`sleep_until` is set
before `retry_at` is read, a delivery reads it after setting `retry_at`).

A failure (a listener or rule that raised on a reader thread, or on the loop)
ends the loop; `start`'s `ended` is then told what broke it, and the Node closes.
"""

from __future__ import annotations

import collections
import concurrent.futures
import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar

from .delivery_state import DeliveryState

__all__ = ["MAX_WAIT", "Loop", "settle"]

MAX_WAIT = 0.25  # seconds the loop waits at most before it looks again by itself

T = TypeVar("T")
Call = tuple[concurrent.futures.Future[Any], Callable[[], Any]]


class Loop:
    """The loop of one Node: `tick(now)` every `period` (unless `paused`), `spread(now)` at every step."""

    def __init__(self, lock: threading.RLock, state: DeliveryState, period: float,
                 tick: Callable[[], None], spread: Callable[[float], None]) -> None:
        self._lock, self._state, self.period = lock, state, period
        self._tick, self._spread = tick, spread
        self.ticks = 0
        self.paused = False  # no ticks: draining before a stop
        self._next_tick = 0.0
        self._calls: collections.deque[Call] = collections.deque()  # submit's: run under the lock, on the loop
        self._stop = threading.Event()  # `request_stop` asked the running loop to return
        self._waiters: list[tuple[Callable[[], bool], threading.Event]] = []  # `wait_until`'s, told at each step
        self._thread: threading.Thread | None = None
        self._ident = 0  # the loop thread's ident while it lives (0: none)

    @property
    def started(self) -> bool:
        return self._thread is not None

    @property
    def thread(self) -> threading.Thread:
        """The loop's thread (once started)."""
        assert self._thread is not None, "the loop was not started"
        return self._thread

    @property
    def running(self) -> bool:
        """Whether the loop's thread lives (it is looping, or closing the Node)."""
        return self._ident != 0

    def start(self, name: str, ended: Callable[[BaseException | None], None]) -> None:
        """Loop on a new thread until `request_stop`; then `ended(what broke the loop, or None)` on that thread."""
        self._next_tick = time.monotonic() + self.period
        self._thread = threading.Thread(target=self._serve, args=(ended,), name=name, daemon=True)
        self._thread.start()

    def _serve(self, ended: Callable[[BaseException | None], None]) -> None:
        self._ident = threading.get_ident()
        try:
            failure: BaseException | None = None
            try:
                self.run()
            except BaseException as error:  # a link or a listener broke the loop: `ended` says why
                failure = error
            ended(failure)
        finally:
            with self._lock:
                self._ident = 0
                for _until, told in self._waiters:  # nobody will look for them any more
                    told.set()

    def on_thread(self) -> bool:
        return threading.get_ident() == self._ident

    def request_stop(self) -> None:
        """Ask the loop to return at its next look (from any thread)."""
        self._stop.set()
        self._state.wake.set()

    def join(self) -> None:
        """Wait until the loop's thread ended (not from that thread)."""
        thread = self._thread
        if thread is not None and not self.on_thread():
            thread.join()

    def call_soon(self, future: concurrent.futures.Future[T], call: Callable[[], T]) -> None:
        """Run `call` for `future` at the loop's next step, waking a loop that waits."""
        self._calls.append((future, call))  # deque.append is atomic: no lock shared with the loop
        self._state.wake.set()

    def fail_calls(self, error: Callable[[], BaseException]) -> None:
        """Fail every call nobody will run now with `error()`."""
        calls = self._calls
        while calls:
            try:
                future, _call = calls.popleft()
            except IndexError:  # another thread took the last one
                return
            if future.set_running_or_notify_cancel():
                future.set_exception(error())

    def run(self, until: Callable[[], bool] | None = None, deadline: float | None = None, *,
            stoppable: bool = True) -> None:
        """On the loop's thread: step until `request_stop` (if `stoppable`), `until()` is true (checked under the
        lock after every batch a link delivers, and at every step) or the monotonic `deadline` passes."""
        state = self._state
        stopping = self._stop
        state.wake_on_arrival = until is not None or bool(self._waiters)
        try:
            while not (stoppable and stopping.is_set()) and not (until is not None and self._holds(until)):
                now = time.monotonic()
                if deadline is not None and now >= deadline:
                    return
                wait = self._next_tick - now
                if deadline is not None:
                    wait = min(wait, deadline - now)
                self._step(max(0.0, min(wait, MAX_WAIT)))
        finally:
            state.wake_on_arrival = bool(self._waiters)

    def wait_until(self, until: Callable[[], bool], timeout: float) -> bool:
        """From another thread while the loop runs: wait until `until()` holds (looked at under the lock after
        every batch and every step, as `run`'s) or `timeout` seconds pass, or the loop ends; whether it holds."""
        waiter = (until, threading.Event())
        with self._lock:
            self._waiters.append(waiter)
            self._state.wake_on_arrival = True
            if not self.running:  # ended meanwhile: nobody will look
                waiter[1].set()
        self._state.wake.set()
        try:
            waiter[1].wait(timeout)
        finally:
            with self._lock:
                self._waiters.remove(waiter)
                self._state.wake_on_arrival = bool(self._waiters)
        return self._holds(until)

    def run_paused(self, until: Callable[[], bool], deadline: float, *, stoppable: bool = True) -> bool:
        """`run` with the ticks paused (a drain); whether `until()` holds at its end."""
        was, self.paused = self.paused, True
        try:
            self.run(until, deadline, stoppable=stoppable)
            return self._holds(until)
        finally:
            self.paused = was

    def _holds(self, until: Callable[[], bool]) -> bool:
        with self._lock:
            return until()

    def _step(self, timeout: float) -> None:
        """Wait up to `timeout` seconds for a wake-up, then: raise a reader's failure, run the calls, tick if due,
        and send what the windows let out."""
        state = self._state
        state.sleep_until = time.monotonic() + timeout  # set before reading retry_at: see `Delivery.deliver`
        retry = state.retry_at
        if retry is not None:
            timeout = min(timeout, retry - time.monotonic())
        state.wake.wait(timeout)  # wake-ups that came together are one
        state.sleep_until = 0.0
        with self._lock:  # held while working, never while waiting: other threads may call in between
            failure, state.failure = state.failure, None
            if failure is not None:
                raise failure
            calls = self._calls
            while calls:
                future, call = calls.popleft()
                settle(future, call)
            now = time.monotonic()
            if now >= self._next_tick and not self.paused:
                self.ticks += 1
                self._next_tick = max(self._next_tick + self.period, now)  # no catch-up burst after a stall
                self._tick()
            self._spread(now)
            for until, told in self._waiters:
                if until():
                    told.set()


def settle(future: concurrent.futures.Future[T], call: Callable[[], T]) -> None:
    """Run `call` for `future` unless it was cancelled; its result or exception goes to the future."""
    if not future.set_running_or_notify_cancel():
        return
    try:
        result = call()
    except BaseException as error:  # handed to whoever waits for the future, raised there
        future.set_exception(error)
    else:
        future.set_result(result)
