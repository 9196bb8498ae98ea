"""A Zenoh peer that floods a gateway and leaves: `python flood.py ENDPOINT SWARM SECONDS`.

It connects straight to the gateway's listener, publishes 64 KiB samples of PUTs (keys
FLOOD_KEYS, each one climbing by one, so the gateway stores and passes them on) as fast
as Zenoh takes them for SECONDS, then closes its session. Prints the samples it sent.
"""

from __future__ import annotations

import json
import struct
import sys
import time

import zenoh

FLOOD_KEYS = range(30_000, 32_000)
FLOOD_ROBOT = 77
SAMPLE_MESSAGES = 8192  # 64 KiB: the largest sample a gateway takes by default


def main() -> int:
    endpoint, swarm, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("listen/endpoints", "[]")
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("scouting/gossip/enabled", "false")
    session = zenoh.open(config)
    publisher = session.declare_publisher(f"vstig/{swarm}/0/{FLOOD_ROBOT}",
                                          congestion_control=zenoh.CongestionControl.DROP)
    pack = struct.Struct(">HHHH").pack
    sent, ts, end = 0, 0, time.monotonic() + seconds
    while time.monotonic() < end:
        ts = ts % 0xFFFF + 1
        keys = FLOOD_KEYS
        payload = b"".join(pack(keys[i % len(keys)], ts, ts, FLOOD_ROBOT) for i in range(SAMPLE_MESSAGES))
        publisher.put(payload)
        sent += 1
    session.close()  # type: ignore[no-untyped-call]
    print(sent)
    return 0


if __name__ == "__main__":
    sys.exit(main())
