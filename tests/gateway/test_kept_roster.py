"""A Node keeps a roster on real links: a python-can virtual bus (senders named) and a cobs8 pty (writer ids),
on the compiled delivery and the pure one."""

from __future__ import annotations

import itertools
import os
import time
import tty

import can
import pytest

from vstig_hw import Message, Op
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.can import can_framing_for
from vstig_hw.gateway import Mode, Node
from vstig_hw.gateway.kept_roster import keep_roster
from vstig_hw.gateway.roster import RobotState, Roster, StateChange
from vstig_hw.links import parse

_ids = itertools.count()


@pytest.mark.parametrize("mode", [Mode.ENGINE, Mode.RAW])
def test_a_relaying_node_keeps_who_it_heard_where_and_who_went_quiet(mode: Mode) -> None:
    channel = f"roster-{os.getpid()}-{next(_ids)}"
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    bus_robot = can.Bus(interface="virtual", channel=channel)
    links = [parse(f"can:virtual:{channel}").build("bus", robot_id=200),
             parse(f"serial:{os.ttyname(slave)}?framing=cobs8").build("radio", robot_id=200)]
    cobs8 = make_serial_framing("cobs8")
    changes: list[StateChange] = []
    try:
        with Node(links, 200, mode=mode, period=0.05) as node:
            kept = keep_roster(node, Roster(0.05, gone_after=5.0))
            kept.on_change(changes.append)
            for ts in range(1, 6):
                for frame in can_framing_for(7).encode(Message(Op.PUT, 5, 1, ts, 7)):
                    bus_robot.send(frame)
                os.write(master, cobs8.encode(Message(Op.PUT, 6, 1, ts, 40))[0])
                os.write(master, cobs8.encode(Message(Op.PUT, 6, 1, 1, 41))[0])  # 41 keeps sending an old write
                time.sleep(0.05)
            time.sleep(0.4)  # both silent: quiet after three periods
            views = {view.robot: view for view in kept.snapshot()}
    finally:
        os.close(master)
        os.close(slave)
        bus_robot.shutdown()
    assert set(views) == {7, 40, 41}
    assert (views[7].named_by, views[7].links, views[7].writes) == ("sender", ("bus",), 5)
    assert (views[40].named_by, views[40].links, views[40].writes) == ("writer", ("radio",), 5)
    assert views[41].behind == (6,) and views[40].behind == ()
    assert {view.state for view in views.values()} == {RobotState.QUIET}
    assert sorted((c.robot, c.new) for c in changes) == [(7, RobotState.QUIET), (40, RobotState.QUIET),
                                                          (41, RobotState.QUIET)]
