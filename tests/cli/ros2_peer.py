"""A plain ROS 2 node for the ros2: link tests: rclpy and the vstig_msgs types, none of vstig-hw's code.

Run as `python ros2_peer.py NAMESPACE [WAIT]`; once the gateway's services are found and its changes
matched (within WAIT seconds, default 20) it prints {"ready": true}, else {"error": ...} and ends. It
answers commands read from stdin, one a line, with one JSON line each on stdout, and prints every
change it hears (`{"change": ...}`) as it comes, stamped with the wall-clock time it arrived:

    put KEY VALUE        the put service's answer
    get KEY              the get service's answer
    table                the table service's entries
    puts N KEY VALUE     N put calls at once (values VALUE, VALUE+1, ...), and a get of KEY half a second later:
                         {"puts": {"answers": [[seconds to the answer, taken, reason], ...], "get": seconds}}
    tables N             N table calls at once: {"tables": [[seconds to the answer, entries], ...]}
    write KEY VALUE ROBOT   one sample on the write topic (timestamp 0: the gateway stamps it)
    write_tagged OP KEY VALUE TIMESTAMP ROBOT EPOCH TAG   one TaggedMessage on write_tagged (TAG: 16 hex digits)
    listen_tagged        prints every TaggedMessage on broadcast_tagged as {"tagged": [op, key, value, timestamp,
                         robot, sender, epoch, tag hex]}, after {"listening": "broadcast_tagged"}
    listen TOPIC         subscribes to TOPIC under the namespace (vstig_msgs/Message), then {"listening": TOPIC}
    flood SECONDS [TOPIC [mixed]]   writes as fast as rclpy publishes (on TOPIC under the namespace: default
                         write; mixed: valid, out of range and garbage), then {"flooded": {kind: N}}
    quit

It subscribes to `changes` as a late joiner would (reliable, transient-local,
depth 1 a key), so what it prints first is the table the gateway already held.
"""

from __future__ import annotations

import json
import random
import sys
import threading
import time
from typing import Any

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from vstig_msgs.msg import Change, Message, TaggedMessage
from vstig_msgs.srv import Get, Put, Table

CALL_TIMEOUT = 20.0


_SAYING = threading.Lock()  # the main thread answers while the executor's prints changes: one line at a time


def say(record: dict[str, object]) -> None:
    line = json.dumps(record) + "\n"
    with _SAYING:
        sys.stdout.write(line)
        sys.stdout.flush()


def entry(e: object) -> list[int]:
    return [e.key, e.value, e.timestamp, e.robot]  # type: ignore[attr-defined]


def timed(call: Any, start: float) -> list[float]:
    """[seconds from `start` to the answer of `call`], filled as the executor's thread completes it."""
    when: list[float] = []
    call.add_done_callback(lambda _: when.append(time.monotonic() - start))
    return when


def answered(when: list[float]) -> float:
    end = time.monotonic() + CALL_TIMEOUT
    while not when:
        assert time.monotonic() < end, "no answer in time"
        time.sleep(0.001)
    return when[0]


def concurrent_calls(client: Any, requests: list[Any], then: Any = None) -> tuple[list[tuple[float, Any]], float]:
    """`requests` called at once; `then` (a request to the get service) half a second later. Each answer with the
    seconds it took, and the seconds `then` took."""
    start = time.monotonic()
    calls = [client.call_async(request) for request in requests]
    times = [timed(call, start) for call in calls]
    got = 0.0
    if then is not None:
        time.sleep(0.5)
        asked = time.monotonic()
        got = answered(timed(then[0].call_async(then[1]), asked))
    return [(answered(when), call.result()) for when, call in zip(times, calls, strict=True)], got


def flood(target: Any, seconds: float, mixed: bool) -> dict[str, int]:
    """Publish on `target` as fast as rclpy does for `seconds`: PUTs of one key, or `mixed`, in every 10 samples 7
    PUTs and GETs of keys from 1000 up, 2 out of range (a key above 32767, an op that is neither PUT nor GET) and
    one payload of random bytes. How many of each were sent."""
    rng = random.Random(45)
    sample, bad = (Message(op=Message.PUT, key=9, value=1, timestamp=0, robot=999, sender=-1) for _ in range(2))
    sent = {"valid": 0, "out_of_range": 0, "garbage": 0}
    end = time.monotonic() + seconds
    n = 0
    while time.monotonic() < end:
        n += 1
        turn = n % 10 if mixed else 0
        if turn < 7:
            sample.value = n & 0xFFFF
            if mixed:  # PUTs and GETs of keys from 1000 up, stamped or not, from many robots
                sample.op, sample.key = n & 1, n * 7919 % 31768 + 1000
                sample.timestamp, sample.robot = n & 0xFFFF, n & 0x3FF
            target.publish(sample)
            sent["valid"] += 1
        elif turn < 9:
            bad.key, bad.op = (40000, Message.PUT) if turn == 7 else (9, 7)
            target.publish(bad)
            sent["out_of_range"] += 1
        else:
            target.publish(rng.randbytes(rng.randrange(0, 25)))  # Fast DDS sends no more than the type can be
            sent["garbage"] += 1
    return sent


def main(namespace: str, wait: float) -> None:
    rclpy.init()
    node = rclpy.create_node("ros2_peer")
    table_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)

    def changed(change: Change) -> None:
        say({"change": {"key": change.key, "new": entry(change.new_entry),
                        "old": entry(change.old_entry) if change.has_old else None,
                        "link": change.link, "sender": change.sender}, "t": time.time()})

    changes = node.create_subscription(Change, f"{namespace}/changes", changed, table_qos)
    writes = node.create_publisher(Message, f"{namespace}/write", 100)
    tagged_writes = node.create_publisher(TaggedMessage, f"{namespace}/write_tagged", 100)
    burst = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE)
    clients = {name: node.create_client(kind, f"{namespace}/{name}", qos_profile=burst)  # 50 calls at once
               for name, kind in (("put", Put), ("get", Get), ("table", Table))}
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()
    for client in clients.values():
        if not client.wait_for_service(timeout_sec=wait):
            say({"error": f"no service {client.srv_name}"})
            return
    end = time.monotonic() + wait
    while changes.get_publisher_count() == 0 and time.monotonic() < end:  # matched: no change is missed
        time.sleep(0.01)
    say({"ready": True})
    for line in sys.stdin:
        words = line.split()
        if not words:
            continue
        command, args = words[0], [int(w) if w.lstrip("-").isdigit() else w for w in words[1:]]
        if command == "quit":
            break
        if command == "put":
            answer = clients["put"].call(Put.Request(key=args[0], value=args[1]), timeout_sec=CALL_TIMEOUT)
            say({"put": {"taken": answer.taken, "entry": entry(answer.entry), "reason": answer.reason}})
        elif command == "get":
            answer = clients["get"].call(Get.Request(key=args[0]), timeout_sec=CALL_TIMEOUT)
            say({"get": {"found": answer.found, "entry": entry(answer.entry)}})
        elif command == "puts":
            puts, got = concurrent_calls(clients["put"], [Put.Request(key=args[1], value=args[2] + n)
                                                          for n in range(args[0])],
                                         (clients["get"], Get.Request(key=args[1])))
            say({"puts": {"answers": [[t, answer.taken, answer.reason] for t, answer in puts], "get": got}})
        elif command == "tables":
            tables, _ = concurrent_calls(clients["table"], [Table.Request() for _ in range(args[0])])
            say({"tables": [[t, len(answer.entries)] for t, answer in tables]})
        elif command == "table":
            answer = clients["table"].call(Table.Request(), timeout_sec=CALL_TIMEOUT)
            say({"table": [entry(e) for e in answer.entries]})
        elif command == "write":
            writes.publish(Message(op=Message.PUT, key=args[0], value=args[1], timestamp=0, robot=args[2],
                                   sender=-1))
            say({"written": args[:2]})
        elif command == "write_tagged":
            tagged_writes.publish(TaggedMessage(op=args[0], key=args[1], value=args[2], timestamp=args[3],
                                                robot=args[4], sender=-1, epoch=args[5],
                                                tag=list(bytes.fromhex(words[7]))))  # as written: hex may be all digits
            say({"written_tagged": args[1:3]})
        elif command == "listen_tagged":
            def tagged(m: TaggedMessage) -> None:
                say({"tagged": [m.op, m.key, m.value, m.timestamp, m.robot, m.sender, m.epoch, bytes(m.tag).hex()]})
            node.create_subscription(TaggedMessage, f"{namespace}/broadcast_tagged", tagged, 100)
            say({"listening": "broadcast_tagged"})
        elif command == "listen":
            node.create_subscription(Message, f"{namespace}/{args[0]}", lambda _: None, 10)
            say({"listening": args[0]})
        elif command == "flood":
            target = writes if len(args) < 2 else node.create_publisher(Message, f"{namespace}/{args[1]}", 100)
            say({"flooded": flood(target, float(args[0]), len(args) > 2 and args[2] == "mixed")})
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main(sys.argv[1], float(sys.argv[2]) if len(sys.argv) > 2 else CALL_TIMEOUT)
