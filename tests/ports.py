"""A TCP port on loopback that nothing listens on (for a peer that is not there, or one a test starts)."""

from __future__ import annotations

import socket


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])
