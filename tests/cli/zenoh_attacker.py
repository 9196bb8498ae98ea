"""A stock zenoh-python peer (Zenoh's own defaults: shared memory on, 1 GiB messages) that a test points at a
gateway: `python zenoh_attacker.py huge ENDPOINT BYTES` publishes one sample of BYTES, `flood ENDPOINT BYTES
SECONDS` publishes BYTES-byte samples of valid vstig messages as fast as it can; each then leaves. It prints
`sent N` when done."""

from __future__ import annotations

import json
import sys
import time

import zenoh

KEY = "vstig/lab/0/66"
MESSAGE = bytes.fromhex("1100050001000000")  # a PUT, the same each time: the gateway decodes and judges it


def main(mode: str, endpoint: str, size: int, seconds: float = 0.0) -> None:
    config = zenoh.Config()
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("listen/endpoints", "[]")
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)
    end = time.monotonic() + 10
    while not session.info.peers_zid() and time.monotonic() < end:
        time.sleep(0.02)
    time.sleep(0.3)  # the gateway's subscription arrives just after the session opens
    sent = 0
    if mode == "huge":
        session.put(KEY, b"\x01" * size, congestion_control=zenoh.CongestionControl.BLOCK)
        sent = 1
        time.sleep(1.0)  # Zenoh pushes the last fragments after put returns
    else:
        payload = MESSAGE * (size // len(MESSAGE))
        publisher = session.declare_publisher(KEY)
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for _ in range(64):
                publisher.put(payload)
            sent += 64
    session.close()  # type: ignore[no-untyped-call]
    print(f"sent {sent}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4]) if len(sys.argv) > 4 else 0.0)
