"""Hostile WebSocket viewers of a live view, in a process of their own (`python ws_attacker.py MODE HOST PORT N`).

    many    open N connections with foxglove.sdk.v1, each subscribing to channels 1-4 and then never reading,
            print `opened N`, and hold them until stdin closes
    garbage open one connection and send N invalid messages quoting newlines, ANSI and OSC escape sequences
            (as text frames and as binary ones), reading what the server answers, print `sent N`

Frames are written by hand (a client masks each frame, RFC 6455 5.3), so N connections cost one socket each.
"""

from __future__ import annotations

import base64
import contextlib
import json
import os
import resource
import socket
import struct
import sys
import threading
import time

EVIL = "\n\x1b[31mRED\x1b]0;pwned\x07\r\nfake: line\x1b[2J"


def _frame(payload: bytes, opcode: int = 1) -> bytes:
    mask = os.urandom(4)
    size = len(payload)
    head = struct.pack("!BB", 0x80 | opcode, 0x80 | size) if size < 126 else \
        struct.pack("!BBH", 0x80 | opcode, 0x80 | 126, size)
    return head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload))


def _connect(host: str, port: int) -> socket.socket:
    sock = socket.create_connection((host, port))
    sock.settimeout(30)
    sock.sendall((f"GET / HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                  f"Sec-WebSocket-Key: {base64.b64encode(os.urandom(16)).decode()}\r\nSec-WebSocket-Version: 13\r\n"
                  "Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n").encode())
    answer = b""
    while b"\r\n\r\n" not in answer:  # frames sent before the 101 answer break the handshake
        chunk = sock.recv(4096)
        if not chunk:
            break
        answer += chunk
    return sock


def many(host: str, port: int, count: int) -> None:
    _, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    subscribe = _frame(json.dumps({"op": "subscribe", "subscriptions": [{"id": i, "channelId": i}
                                                                        for i in range(1, 5)]}).encode())
    held = []
    for _ in range(count):
        sock = _connect(host, port)
        with contextlib.suppress(OSError):  # closed on us already
            sock.sendall(subscribe)
        held.append(sock)
    print(f"opened {count}", flush=True)
    sys.stdin.read()


def _read_all(sock: socket.socket) -> None:
    with contextlib.suppress(OSError):
        while sock.recv(65536):
            pass


def garbage(host: str, port: int, count: int) -> None:
    sock = _connect(host, port)
    # it reads the server's answers (a status for each invalid message), as a viewer does: one that never reads
    # is `many`'s attack, and the server lets it go once its answers pile up (a reset here, now and then)
    threading.Thread(target=_read_all, args=(sock,), daemon=True).start()
    sent = 0
    for i in range(count):
        message = [json.dumps({"op": EVIL + str(i)}).encode(), (EVIL + "not json").encode()][i % 2]
        sock.sendall(_frame(message) + _frame(b"\xff\x00" + EVIL.encode(), opcode=2))
        sent += 2
    time.sleep(0.5)
    sock.close()
    print(f"sent {sent}", flush=True)


if __name__ == "__main__":
    {"many": many, "garbage": garbage}[sys.argv[1]](sys.argv[2], int(sys.argv[3]), int(sys.argv[4]))
