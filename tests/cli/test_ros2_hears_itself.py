"""A put served to a ROS 2 node through a gateway whose other link echoes (pyserial's loop://) is refused with the
reason alone: the service has no way to write unconfirmed, so neither put(..., confirm=False) nor --no-confirm is
named (issue 44). A real ROS 2 node in another process, as tests/cli/test_ros2.py runs them."""

from __future__ import annotations

import pytest
from dds import Host
from peers import wait_for
from test_ros2 import host, joined_program_and_peer, ros2_env

pytestmark = pytest.mark.slow
__all__ = ["host", "ros2_env"]  # fixtures, used by name


def test_a_served_put_on_a_gateway_that_hears_itself_names_no_way_to_write_anyway(
        host: Host, ros2_env: dict[str, str]) -> None:
    with joined_program_and_peer(host, ros2_env, """
import sys
import vstig_hw
with vstig_hw.join("serial:loop://", "ros2:lab", robot_id=200):
    print("joined", flush=True)
    sys.stdin.read()
""") as peer:
        peer.send("put 4 1")
        wait_for(lambda: bool(peer.records("put")), 30)
        answer = peer.records("put")[-1]
    assert not answer["taken"] and "brings our own GETs back (robot id 200)" in answer["reason"], answer
    assert "confirm=False" not in answer["reason"] and "--no-confirm" not in answer["reason"], answer
