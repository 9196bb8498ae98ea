"""The state a Node's two deliveries share with its loop: declared once, read by both.

C twin: vstig_hw/_cext/path.c (`Path` reads and writes these slots; the names it uses are the ones
`vstig_hw._vstig.DECLARED` lists under this class, and tests/native/test_native_declared.py checks each is a slot
here). The Python delivery is `delivery.Delivery.deliver`; the loop is `loop.Loop` (its `_step`). It is the Node's
one object of wake-ups: nothing else carries when the loop must look.
"""

from __future__ import annotations

from ..wakeup import Wakeup

__all__ = ["DeliveryState"]


class DeliveryState:
    """What a delivery (on a reader thread) and the Node's loop tell each other, and nothing else.

    * `wake`: the loop's one wake-up token (a call, a window reopening, a failure).
    * `reader_thread`: ident of the reader thread handling a batch that may run the user's Python (0: none), so
      that `Node.on_node_thread` is true there.
    * `failure`: what a listener or rule raised on a reader thread; the loop raises it on its thread (the Node
      then closes, naming it).
    * `retry_at`: when a budget window next lets held-back messages out (None: nothing held back).
    * `sleep_until`: when the waiting loop looks again by itself (0.0: it is not waiting). The loop sets it
      before reading `retry_at`, a delivery reads it after setting `retry_at`: no wake-up is lost between.
    * `wake_on_arrival`: the loop has a predicate to check after every batch (a drain, `Loop.wait_until`).
    """

    __slots__ = ("failure", "reader_thread", "retry_at", "sleep_until", "wake", "wake_on_arrival")

    wake: Wakeup
    reader_thread: int
    failure: BaseException | None
    retry_at: float | None
    sleep_until: float
    wake_on_arrival: bool

    def __init__(self) -> None:
        self.wake = Wakeup()
        self.reader_thread = 0
        self.failure = None
        self.retry_at = None
        self.sleep_until = 0.0
        self.wake_on_arrival = False
