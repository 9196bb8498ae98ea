"""systemd's service notification protocol, spoken by us (sd_notify(3); no libsystemd): one datagram each to
$NOTIFY_SOCKET for READY=1 once every link is open, WATCHDOG=1 from the loop while it runs, STATUS= with the
counters, and STOPPING=1 when a stop begins.

The watchdog pings come from the Node's tick, on the loop's thread: a loop that stalls (a listener stuck, the lock
held) stops pinging, and systemd, after WatchdogSec, ends the process and restarts it (Restart=on-failure). A
datagram never waits: a service manager that does not read loses its own notifications (counted, said once),
the gateway goes on.
"""

from __future__ import annotations

import logging
import os
import socket
import time
from collections.abc import MutableMapping
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from vstig_hw.gateway import Node

__all__ = ["STATUS_EVERY_S", "ServiceNotifier"]

log = logging.getLogger(__name__)

STATUS_EVERY_S = 5.0  # how often STATUS= carries the counters (`systemctl status` shows the latest)
_STATUS_MAX = 1000  # characters of STATUS=: systemctl shows one line


class ServiceNotifier:
    """Notifications to the service manager at `address` (a path, or '@name' for an abstract socket)."""

    def __init__(self, address: str, watchdog_s: float | None = None) -> None:
        self.address = "\0" + address[1:] if address.startswith("@") else address
        self.ping_every = None if watchdog_s is None else watchdog_s / 2  # sd_watchdog_enabled(3): half the timeout
        self.pings = 0
        self.failed = 0  # datagrams the manager did not take
        self._socket = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
        self._next_ping = 0.0
        self._next_status = 0.0

    @classmethod
    def from_environment(cls, environ: MutableMapping[str, str] | None = None) -> ServiceNotifier | None:
        """The notifier systemd's environment asks for, or None (not run by a service manager).

        NOTIFY_SOCKET and the WATCHDOG_ variables are taken out of the environment, as sd_notify's
        unset_environment does: a child (the live view's server) must not speak for the service.
        """
        env = os.environ if environ is None else environ
        address = env.pop("NOTIFY_SOCKET", "")
        usec, pid = env.pop("WATCHDOG_USEC", ""), env.pop("WATCHDOG_PID", "")
        if not address.startswith(("/", "@")) or len(address) < 2:  # systemd's rule: absolute or abstract
            return None
        watchdog_s = None
        if usec.isdigit() and int(usec) > 0 and (not pid or pid == str(os.getpid())):  # the pings are ours to send
            watchdog_s = int(usec) / 1e6
        return cls(address, watchdog_s)

    def notify(self, *fields: str) -> bool:
        """Send one datagram of `fields` (KEY=value lines); False (counted, said once) if it could not go."""
        try:
            self._socket.sendto("\n".join(fields).encode(), socket.MSG_DONTWAIT, self.address)
        except OSError as error:
            self.failed += 1
            if self.failed == 1:
                log.warning("cannot notify the service manager at %s: %s (counting the others)",
                            self.address.replace("\0", "@"), error.strerror or error)
            return False
        return True

    def ready(self, status: str) -> None:
        self.notify("READY=1", f"STATUS={status[:_STATUS_MAX]}", f"MAINPID={os.getpid()}")
        self._next_status = time.monotonic() + STATUS_EVERY_S

    def stopping(self) -> None:
        self.notify("STOPPING=1", "STATUS=stopping")

    def tick(self, node: Node) -> None:
        """On the loop's thread, every tick: WATCHDOG=1 when one is due, STATUS= with the counters now and then."""
        now = time.monotonic()
        if self.ping_every is not None and now >= self._next_ping:
            self._next_ping = now + self.ping_every
            if self.notify("WATCHDOG=1"):
                self.pings += 1
        if now >= self._next_status:
            self._next_status = now + STATUS_EVERY_S
            self.notify(f"STATUS={node.summary()[:_STATUS_MAX]}")

    def close(self) -> None:
        self._socket.close()
