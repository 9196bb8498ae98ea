"""Tags on a ros2: link (SPEC.md 10.5, 10.6): a `vstig bridge --swarm-key` whose ros2:lab link requires them, a
real ROS 2 node in another process (ros2_peer.py: rclpy only) writing on `write_tagged` and reading
`broadcast_tagged`, and a robot on a pty radio (cobs8, auth=require) that tags its own writes.

A ROS 2 program with its own robot key (robot 9) writes and is taken; a write tagged with robot 10's key under
robot 9's id, and an untagged write, are refused and counted on the ros2 link; the put service, which writes as
the gateway under its key, is refused on a link that checks tags. The pty robot's write reaches ROS 2 with its own
tag, so a ROS 2 consumer holding the master can check who wrote it.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from pathlib import Path

import test_ros2
from peers import wait_for
from robots import PtyRobot
from test_ros2 import Lab, counters

from vstig_hw.auth import SwarmKeys, Tagged, encode_record, entry_tag, robot_key
from vstig_hw.wire import Message, Op

MASTER = bytes(range(0x60, 0x80))
ros2_env, host, lab = test_ros2.ros2_env, test_ros2.host, test_ros2.lab  # its fixtures, here too


def tag(robot_key_of: int, msg: Message) -> str:
    """The hex tag of `msg` at epoch 0 under robot `robot_key_of`'s key."""
    return entry_tag(robot_key(MASTER, robot_key_of), 0, msg, 0).hex()


class SigningRobot(PtyRobot):
    """A pty robot holding its own key: it sends its own writes as records, everything else untagged."""

    def __init__(self, robot_id: int, watch: Iterable[int]) -> None:
        super().__init__(robot_id, watch)
        self.spec += "&auth=require"
        self.key = robot_key(MASTER, robot_id)

    def _send(self, messages: list[Message]) -> None:
        records = [Tagged(m, 0, entry_tag(self.key, 0, m, 0)) for m in messages if m.robot == self.engine.robot_id]
        plain = [m for m in messages if m.robot != self.engine.robot_id]
        data = b"".join(self.framing.encode_tagged(records)) + b"".join(self.framing.encode_batch(plain))
        if data:
            self.radio.write(data)


def test_a_ros2_writer_with_its_key_is_taken_forgeries_are_refused_and_entries_reach_ros2_with_their_tags(
        lab: Callable[..., Lab], tmp_path: Path) -> None:
    key_file = tmp_path / "swarm.key"
    key_file.write_text(MASTER.hex() + "\n", encoding="ascii")
    key_file.chmod(0o600)
    robot = SigningRobot(7, watch=(5, 6))
    run = lab([robot], "--swarm-key", str(key_file), ros2="ros2:lab?auth=require")
    peer = run.peer()
    peer.send("listen_tagged")
    wait_for(lambda: "broadcast_tagged" in peer.records("listening"))
    honest = Message(Op.PUT, 5, 55, 1, 9)

    def write(msg: Message, key_of: int) -> None:
        peer.send(f"write_tagged {int(msg.op)} {msg.key} {msg.value} {msg.timestamp} {msg.robot} 0 {tag(key_of, msg)}")

    wait_for(lambda: robot.value(5) == 55, 40, step=lambda: (write(honest, 9), run.step(), time.sleep(0.2)))
    write(Message(Op.PUT, 6, 66, 1, 9), 10)  # robot 10's key, robot 9's id
    peer.send("write 6 67 9")  # untagged: the gateway stamps it, then refuses it
    peer.send("put 4 44")
    run.run_until(lambda: bool(peer.records("put")))
    later = Message(Op.PUT, 6, 68, 1, 9)
    write(later, 9)
    robot.put(8, 88)  # the pty robot's own write, tagged with its key
    run.run_until(lambda: robot.value(6) == 68 and any(t[1] == 8 for t in peer.records("tagged")))
    for _ in range(5):
        run.step()
    answer = peer.records("put")[-1]
    stderr = run.close()
    assert not answer["taken"] and "auth=require" in answer["reason"], answer
    keys = SwarmKeys(MASTER)
    shown = [Tagged(Message(Op(t[0]), *t[1:5]), t[6], bytes.fromhex(t[7])) for t in peer.records("tagged")]
    assert shown and all(keys.verify(record) for record in shown), shown  # a consumer with the master checks each
    mine = [record for record in shown if record.message.key == 8]  # broadcast as PUTs and GETs that show it
    assert mine and {record.message[1:] for record in mine} == {tuple(robot.engine.entry(8) or ())}, mine
    assert all(encode_record(record)[12:].hex() == tag(7, record.message) for record in mine)  # robot 7's own tag
    assert {t[5] for t in peer.records("tagged")} == {200}  # sent by the gateway
    counted = counters(stderr, "ros2-lab")
    assert (counted.get("drop_bad_tag"), counted.get("drop_untagged")) == (1, 1), counted
    assert "refusing writes whose tag does not check out claiming robot 9" in stderr, stderr[-2000:]
    assert robot.value(6) == 68  # neither forgery was ever held: the honest later write is


def test_a_flood_on_write_leaves_signed_writes_on_write_tagged_their_share(lab: Callable[..., Lab],
                                                                         tmp_path: Path) -> None:
    """The node takes the two write topics in turn within write_rate: a peer flooding `write` (untagged, refused)
    does not hold a signed writer's writes back until the flood ends."""
    key_file = tmp_path / "swarm.key"
    key_file.write_text(MASTER.hex() + "\n", encoding="ascii")
    key_file.chmod(0o600)
    keys = range(20, 30)
    robot = SigningRobot(7, watch=keys)
    run = lab([robot], "--swarm-key", str(key_file), ros2="ros2:lab?auth=require&write_rate=100")
    flooder, writer = run.peer(), run.peer()

    def write(key: int) -> None:
        msg = Message(Op.PUT, key, key, 1, 9)
        writer.send(f"write_tagged 0 {key} {key} 1 9 0 {tag(9, msg)}")

    wait_for(lambda: robot.value(20) == 20, 40, step=lambda: (write(20), run.step(), time.sleep(0.2)))
    flooder.send("flood 8")
    time.sleep(1.0)  # the flood under way: its samples take every token the write topic is given
    for key in keys[1:]:
        write(key)
    run.run_until(lambda: all(robot.value(key) == key for key in keys) or bool(flooder.records("flooded")), 30)
    held = [key for key in keys if robot.value(key) == key]
    flooding = not flooder.records("flooded")
    run.run_until(lambda: bool(flooder.records("flooded")), 30)
    stderr = run.close()
    assert held == list(keys) and flooding, (held, flooder.records("flooded"))  # all in, while the flood went on
    assert counters(stderr, "ros2-lab")["drop_untagged"] > 100, stderr[-2000:]  # the flood, refused
