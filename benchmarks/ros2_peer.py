"""The ROS 2 ends of the ros2 benchmarks, each a plain rclpy process (`python -m benchmarks.ros2_peer ...`).

    receive TOPIC COUNT SECONDS      subscribe (vstig_msgs/Message, reliable, depth 1000), stamp every
                                     message's arrival (perf_counter is system-wide), print {value: time}
                                     as JSON once COUNT arrived or SECONDS passed
    publish TOPIC COUNT RATE         wait for a subscriber, publish COUNT messages (value = index) at RATE
                                     a second, print their send times as JSON
    subscribe NAMESPACE SECONDS      subscribe to every heard/<link> topic and to changes under NAMESPACE
                                     (a ROS 2 system watching the gateway), counting what arrives

Every one runs in a network namespace with only lo (benchmarks/bench_ros2.py starts them).
"""

from __future__ import annotations

import json
import sys
import threading
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from vstig_msgs.msg import Change, Message

STREAM = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
TABLE = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def receive(node: object, topic: str, count: int, seconds: float) -> None:
    arrived: dict[int, float] = {}
    done = threading.Event()

    def heard(message: Message) -> None:
        arrived.setdefault(message.value, time.perf_counter())
        if len(arrived) >= count:
            done.set()

    subscription = node.create_subscription(Message, topic, heard, STREAM)  # type: ignore[attr-defined]
    while subscription.get_publisher_count() == 0:  # matched: nothing sent from now on is missed
        time.sleep(0.01)
    time.sleep(0.5)
    print("ready", flush=True)
    done.wait(seconds)
    print(json.dumps(arrived), flush=True)


def publish(node: object, topic: str, count: int, rate: float) -> None:
    publisher = node.create_publisher(Message, topic, STREAM)  # type: ignore[attr-defined]
    while publisher.get_subscription_count() == 0:
        time.sleep(0.01)
    time.sleep(0.5)  # the subscriber's side of the match settles
    sent, start = [], time.perf_counter() + 0.05
    for i in range(count):
        remaining = start + i / rate - time.perf_counter()
        if remaining > 0:
            time.sleep(remaining)
        sent.append(time.perf_counter())
        publisher.publish(Message(op=Message.PUT, key=i & 0x7FFF, value=i, timestamp=1, robot=7, sender=-1))
    print(json.dumps(sent), flush=True)


def subscribe(node: object, namespace: str, seconds: float) -> None:
    counted = [0]

    def heard(_: object) -> None:
        counted[0] += 1

    topics = [name for name, _ in node.get_topic_names_and_types()]  # type: ignore[attr-defined]
    for topic in topics:
        if topic.startswith(f"{namespace}/heard/"):
            node.create_subscription(Message, topic, heard, STREAM)  # type: ignore[attr-defined]
    node.create_subscription(Change, f"{namespace}/changes", heard, TABLE)  # type: ignore[attr-defined]
    print("ready", flush=True)
    time.sleep(seconds)
    print(json.dumps({"received": counted[0]}), flush=True)


def main(argv: list[str]) -> None:
    rclpy.init()
    node = rclpy.create_node("bench_peer")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()
    mode, *args = argv
    if mode == "receive":
        receive(node, args[0], int(args[1]), float(args[2]))
    elif mode == "publish":
        publish(node, args[0], int(args[1]), float(args[2]))
    elif mode == "subscribe":
        time.sleep(2.0)  # discovery: the gateway's topics become known
        subscribe(node, args[0], float(args[1]))
    executor.shutdown()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main(sys.argv[1:])
