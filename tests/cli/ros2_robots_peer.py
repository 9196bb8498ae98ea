"""A plain ROS 2 node that watches a gateway's roster: rclpy and the vstig_msgs types, none of vstig-hw's code.

Run as `python ros2_robots_peer.py NAMESPACE`; it subscribes to NAMESPACE/robots as a late joiner would
(reliable, transient-local, depth 1), prints {"ready": true} once matched with the gateway's publisher, then
one JSON line per message, stamped with the wall-clock time it arrived: {"robots": {...}, "t": ...}.
It ends when its stdin closes.
"""

from __future__ import annotations

import json
import sys
import threading
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from vstig_msgs.msg import Robots

_SAYING = threading.Lock()


def say(record: dict[str, object]) -> None:
    with _SAYING:
        sys.stdout.write(json.dumps(record) + "\n")
        sys.stdout.flush()


def shown(message: Robots) -> dict[str, object]:
    return {"t": message.t, "robots_total": message.robots_total, "alive": message.alive, "quiet": message.quiet,
            "gone": message.gone, "untracked": message.untracked,
            "rows": [{"robot": r.robot, "named_by": r.named_by, "links": list(r.links), "state": r.state,
                      "last_heard_s": r.last_heard_s, "rate": r.rate, "messages": r.messages, "writes": r.writes,
                      "gets": r.gets, "behind": [int(k) for k in r.behind], "refused": r.refused,
                      "quality": r.quality} for r in message.robots]}


def main(namespace: str) -> None:
    rclpy.init()
    node = rclpy.create_node("ros2_robots_peer")
    latched = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    robots = node.create_subscription(Robots, f"{namespace}/robots",
                                      lambda m: say({"robots": shown(m), "t": time.time()}), latched)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()
    end = time.monotonic() + 60
    while robots.get_publisher_count() == 0 and time.monotonic() < end:
        time.sleep(0.01)
    say({"ready": robots.get_publisher_count() > 0})
    sys.stdin.read()
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main(sys.argv[1])
