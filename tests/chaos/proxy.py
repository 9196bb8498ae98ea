"""The cables between the chaos soak's gateways: TCP relays on 127.0.0.1 that can be cut and healed.

Each gateway reaches another only through one of these (Zenoh's gossip is off, so
no gateway learns another's own address). A cut is a cable pulled out: bytes stop
flowing both ways on the connections there were, and new connections are taken but
lead nowhere, so each side notices only when its Zenoh lease runs out, as on a real
network. A heal resets what the cut left hanging, so both sides dial again at once.
One thread per direction of each connection: a gateway slow to read holds its own
connection only.
"""

from __future__ import annotations

import contextlib
import socket
import struct
import threading

_RESET = struct.pack("ii", 1, 0)  # SO_LINGER on, 0 s: close() sends a reset


def _reset(sock: socket.socket) -> None:
    with contextlib.suppress(OSError):
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, _RESET)
    with contextlib.suppress(OSError):
        sock.shutdown(socket.SHUT_RDWR)
    sock.close()


class Cable:
    """Listen on a free loopback port and relay every connection to `target` (a port) while not cut."""

    def __init__(self, target: int) -> None:
        self.target = target
        self.cut = False
        self._server = socket.socket()
        self._server.bind(("127.0.0.1", 0))
        self._server.listen(64)
        self.port = int(self._server.getsockname()[1])
        self._lock = threading.Lock()
        self._open: set[socket.socket] = set()
        self._closed = False
        threading.Thread(target=self._accept, name=f"cable-{self.port}", daemon=True).start()

    def pull(self) -> None:
        """Cut it: nothing crosses until `heal`."""
        self.cut = True

    def heal(self) -> None:
        with self._lock:
            self.cut = False
            hanging, self._open = self._open, set()
        for sock in hanging:
            _reset(sock)

    def close(self) -> None:
        self._closed = True
        self.heal()
        with contextlib.suppress(OSError):
            self._server.shutdown(socket.SHUT_RDWR)
        self._server.close()

    def _accept(self) -> None:
        while not self._closed:
            try:
                near, _ = self._server.accept()
            except OSError:
                return
            far = None
            if not self.cut:
                try:
                    far = socket.create_connection(("127.0.0.1", self.target), timeout=1)
                    far.settimeout(None)
                except OSError:  # nobody listens there now (a gateway restarting): the dialler sees a reset
                    _reset(near)
                    continue
            with self._lock:
                self._open.add(near)
                if far is not None:
                    self._open.add(far)
            threading.Thread(target=self._pump, args=(near, far), daemon=True).start()
            if far is not None:
                threading.Thread(target=self._pump, args=(far, near), daemon=True).start()

    def _pump(self, source: socket.socket, sink: socket.socket | None) -> None:
        while True:
            try:
                data = source.recv(65536)
            except OSError:
                data = b""
            if not data:
                break
            if self.cut or sink is None:
                continue  # the cable is out: the bytes go nowhere
            try:
                sink.sendall(data)
            except OSError:
                break
        with self._lock:
            mine = [sock for sock in (source, sink) if sock is not None and sock in self._open]
            self._open.difference_update(mine)
        for sock in mine:
            _reset(sock)
