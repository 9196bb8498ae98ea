"""`vstig bridge` between swarms that speak Buzz or BittyBuzz and our own radios, as subprocesses."""

from __future__ import annotations

import itertools
from pathlib import Path

import can
from bbz_swarm import KilobotSwarm
from peers import PtyPeer, SlcanAdapter, start_vstig, stop, wait_for

from vstig_hw import Message, Op, decode, encode

X = 41  # BittyBuzz's string id of "x" in every build


def test_bittybuzz_kilobots_and_can_converge_with_both_clocks(tmp_path: Path) -> None:
    deployment = tmp_path / "kilobots.toml"
    deployment.write_text('[keys]\nx = { key = 1, type = "int16" }\n', encoding="utf-8")
    adapter, radio = SlcanAdapter(), PtyPeer()
    swarm = KilobotSwarm(radio, [11, 12, 13], [X])
    for robot in swarm.robots:  # the paper's task: every robot puts its id; here the higher id wins
        robot.put(X, robot.rid)
    bridge = start_vstig("bridge", f"can:slcan:{adapter.path}",
                         f"serial:{radio.path}?framing=kilobot&dialect=bittybuzz&deployment={deployment}",
                         "--robot-id", "200")
    try:
        wait_for(lambda: "O" in adapter.commands, 30)
        swarm.start()
        # A CAN robot joins with a higher id at timestamp 1: the same version number the Kilobots started at.
        adapter.inject(can.Message(arbitration_id=0x600 | 40, data=encode(Message(Op.PUT, 1, 40, 1, 40)),
                                   is_extended_id=False))
        wait_for(lambda: all(e is not None and e.value == 40 for e in swarm.held(X)), 30)
        # A Kilobot writes: its next lamport becomes the next timestamp on CAN, writer kept.
        swarm.act(13, X, -7)

        def on_can(value: int) -> list[Message]:
            return [m for m in (decode(bytes(f.data)) for f in list(adapter.sent)) if m.key == 1 and m.value == value]

        wait_for(lambda: bool(on_can(0xFFF9)), 30)
        wait_for(lambda: all(e is not None and e.value == -7 for e in swarm.held(X)), 30)
    finally:
        _out, err = stop(bridge)
        swarm.stop()
        adapter.close()
        radio.close()
    assert bridge.returncode == 0, err
    kilobot_write = on_can(0xFFF9)[0]
    winner = next(e for e in swarm.held(X) if e is not None)
    assert (kilobot_write.op, kilobot_write.robot) == (Op.PUT, 13)
    assert kilobot_write.timestamp == 2 and winner.lamport == 3  # lamport 3 = one past the bridge's 2
    # What the bridge told the Kilobots: PUTs only, each lamport one step past the previous.
    sent = [m for m in swarm.from_bridge if m[2] == X]
    assert sent and all(m[0] == 1 for m in sent)
    lamports = [m[5] for m in sent]
    assert all(1 <= (b - a) & 0xFF <= 2 or b == a for a, b in itertools.pairwise(lamports)), lamports
    assert sent[0][1] == 40 and sent[0][4] == 40  # the CAN robot's version, under its own id
