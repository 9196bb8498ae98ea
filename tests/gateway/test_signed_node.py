"""A gateway with the swarm key on real python-can virtual CAN FD buses (SPEC.md 10.6): honest tagged writes stored
and relayed with their writer's own tag; an outsider's untagged write, a robot writing under another's id with
its own key and a relayed entry whose value was changed refused and counted by writer; a replayed old write loses;
an untagged write heard on an `auth=off` link kept but never carried onto a link that requires tags."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import can
import pytest

import vstig_hw
from vstig_hw.auth import SwarmKeys, Tagged, entry_tag, robot_key
from vstig_hw.engine import Entry
from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.gateway import Node
from vstig_hw.gateway.kept_roster import keep_roster
from vstig_hw.links import Heard, examples, parse
from vstig_hw.links.assemble import LinkBuildError, assemble_links
from vstig_hw.tagged import AuthPolicy
from vstig_hw.wire import Message, Op

MASTER = bytes(range(0xA0, 0xC0))
GATEWAY = 200


def _own_tag(robot: int, msg: Message, epoch: int = 0) -> Tagged:
    """`msg` tagged as robot `robot` tags it, holding only its own key."""
    return Tagged(msg, epoch, entry_tag(robot_key(MASTER, robot), 0, msg, epoch))


class Robot:
    """A node on a virtual CAN FD bus, sending what it is given as robot `robot` (its CAN sender id)."""

    def __init__(self, channel: str, robot: int) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel, fd=True)
        self.framing = CanFraming(CanIdScheme(), robot, fd=True)

    def send_records(self, records: list[Tagged]) -> None:
        for frame in self.framing.encode_tagged(records):
            self.bus.send(frame)

    def send(self, messages: list[Message]) -> None:
        for frame in self.framing.encode_batch(messages):
            self.bus.send(frame)

    def heard(self) -> list[tuple[Message, Tagged | None]]:
        return [pair for frame in iter(lambda: self.bus.recv(0.05), None) for pair in self.framing.feed_tagged(frame)]


@pytest.fixture
def channels() -> Iterator[tuple[str, str, str]]:
    yield tuple(f"signed-{name}-{os.getpid()}-{time.monotonic_ns()}" for name in "abc")  # type: ignore[misc]


def _node(channels: tuple[str, str, str], policies: tuple[str, str, str]) -> Node:
    links = assemble_links([f"can:virtual:{channel}?fd=1&auth={policy}" for channel, policy in
                            zip(channels, policies, strict=True)], GATEWAY)
    return Node(links, GATEWAY, period=0.02, swarm_keys=SwarmKeys(MASTER))


def _run(node: Node, seconds: float = 0.3) -> None:
    time.sleep(seconds)


def test_attacks_on_a_require_link_are_refused_and_honest_writes_relayed_with_their_tags(
        channels: tuple[str, str, str]) -> None:
    node = _node(channels, ("require", "require", "off"))
    refused: list[tuple[Heard, str]] = []
    node.listen(refused=lambda heard, reason: refused.append((heard, reason)))
    kept = keep_roster(node)
    robot5, robot6, outsider = Robot(channels[0], 5), Robot(channels[0], 6), Robot(channels[0], 99)
    listener = Robot(channels[1], 7)
    honest = _own_tag(5, Message(Op.PUT, 1, 1000, 3, 5))
    with node:
        robot5.send_records([honest])
        outsider.send([Message(Op.PUT, 2, 666, 9, 99)])  # no key at all: untagged
        robot6.send_records([_own_tag(6, Message(Op.PUT, 3, 666, 9, 5))])  # robot 5's id, robot 6's key
        changed = Tagged(Message(Op.PUT, 1, 1001, 4, 5), 0, honest.tag)  # its value altered on the way
        robot6.send_records([changed])
        _run(node)
        relayed = listener.heard()
        robot5.send_records([_own_tag(5, Message(Op.PUT, 1, 1002, 5, 5))])
        _run(node)
        robot6.send_records([honest])  # the old write again, tag and all
        _run(node)
    for robot in (robot5, robot6, outsider, listener):
        robot.bus.shutdown()
    engine = node.engine
    assert engine is not None
    assert engine.entry(1) == Entry(1002, 5, 5) and engine.entry(2) is None and engine.entry(3) is None
    assert [(msg, record) for msg, record in relayed if msg.key == 1] == [(honest.message, honest)]
    stats = node.stats()[node.links[0].name]
    assert (stats["drop_untagged"], stats["drop_bad_tag"]) == (1, 2)
    assert node.signing is not None and node.signing.refused == {("drop_untagged", 99): 1, ("drop_bad_tag", 5): 2}
    assert sorted((heard.message.robot, reason) for heard, reason in refused) == \
        [(5, "drop_bad_tag"), (5, "drop_bad_tag"), (99, "drop_untagged")]
    assert len([w for w in node.signing.warnings if "claiming robot 5" in w]) == 1  # once per writer and episode
    roster = {view.robot: view.refused for view in kept.snapshot()}
    # The roster counts a refusal to the node the medium names as its sender (CAN IDs): robot 6 sent both forgeries
    assert (roster[5], roster[6], roster[99]) == (0, 2, 1), roster
    assert node.signing.engine is not None and node.signing.engine.replays == 1  # the replay lost, counted


def test_an_untagged_write_on_an_off_link_never_reaches_a_require_link(channels: tuple[str, str, str]) -> None:
    node = _node(channels, ("require", "prefer", "off"))
    on_off, on_require, on_prefer = Robot(channels[2], 8), Robot(channels[0], 9), Robot(channels[1], 10)
    with node:
        on_off.send([Message(Op.PUT, 4, 40, 1, 8)])
        _run(node)
    require_heard, prefer_heard = on_require.heard(), on_prefer.heard()
    for robot in (on_off, on_require, on_prefer):
        robot.bus.shutdown()
    assert node.engine is not None and node.engine.entry(4) == Entry(40, 1, 8)  # kept: the off link's robots
    assert [msg.key for msg, _ in require_heard] == []
    assert [(msg.key, record) for msg, record in prefer_heard] == [(4, None)]  # prefer: carried, untagged
    assert node.stats()[node.links[0].name]["held_unverified"] >= 1


def test_the_gateways_own_writes_carry_its_tag(channels: tuple[str, str, str]) -> None:
    node = _node(channels, ("require", "off", "off"))
    listener = Robot(channels[0], 11)
    with node:
        node.put(6, 60)
        _run(node, 0.1)
    heard = [(msg, record) for msg, record in listener.heard() if msg.key == 6]
    listener.bus.shutdown()
    assert heard and all(record == _own_tag(GATEWAY, msg) for msg, record in heard)


def test_a_key_without_a_link_that_checks_tags_changes_nothing(channels: tuple[str, str, str]) -> None:
    node = _node(channels, ("off", "off", "off"))
    assert node.signing is None and all(link.record_of is None for link in node.links)


def test_policies_need_a_key_and_room_for_tags(channels: tuple[str, str, str]) -> None:
    links = assemble_links([f"can:virtual:{channels[0]}?fd=1&auth=prefer"], GATEWAY)
    with pytest.raises(ValueError, match=r"auth=prefer: checking tags needs the swarm key \(--swarm-key FILE"):
        Node(links, GATEWAY)
    with pytest.raises(LinkBuildError, match="auth=require, but can frames have no room for tags"):
        assemble_links([f"can:virtual:{channels[0]}?auth=require"], GATEWAY)


@pytest.mark.parametrize("spec", [specs[0] for specs in examples().values()], ids=list(examples()))
def test_every_kind_takes_a_policy(spec: str) -> None:
    joined = "&" if "?" in spec else "?"
    assert parse(f"{spec}{joined}auth=prefer").auth is AuthPolicy.PREFER
    assert parse(f"{spec}{joined}auth=prefer") == replace(parse(spec), auth=AuthPolicy.PREFER)  # type: ignore[type-var]
    with pytest.raises(ValueError, match=r"auth='maybe': must be one of require, prefer, off"):
        parse(f"{spec}{joined}auth=maybe")
    with pytest.raises(ValueError, match="parameter 'auth' given twice"):
        parse(f"{spec}{joined}auth=off&auth=require")


def test_join_takes_the_swarm_key_file(channels: tuple[str, str, str], tmp_path: Path) -> None:
    key_file = tmp_path / "swarm.key"
    key_file.write_text(MASTER.hex() + "\n", encoding="ascii")
    spec = f"can:virtual:{channels[0]}?fd=1&auth=require"
    with pytest.raises(ValueError, match=r"swarm_key: link '.*' has auth=require: checking tags needs the swarm key"):
        vstig_hw.join(spec, robot_id=GATEWAY)
    key_file.chmod(0o644)
    with pytest.raises(ValueError, match=f"{key_file}"):  # group and others may read it: refused, named
        vstig_hw.join(spec, robot_id=GATEWAY, swarm_key=key_file)
    key_file.chmod(0o600)
    listener = Robot(channels[0], 12)
    with vstig_hw.join(spec, robot_id=GATEWAY, swarm_key=key_file) as swarm:
        swarm.put(7, 70)
        time.sleep(0.2)
    heard = [(msg, record) for msg, record in listener.heard() if msg.key == 7]
    listener.bus.shutdown()
    assert heard and all(record == _own_tag(GATEWAY, msg) for msg, record in heard)  # the program's write, tagged
