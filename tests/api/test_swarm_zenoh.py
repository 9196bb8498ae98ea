"""Two programs' swarms meet over zenoh sessions on loopback: confirmed puts both ways, a watched change."""

from __future__ import annotations

import os
import re
import time

import pytest

import vstig_hw
from vstig_hw import Entry

pytest.importorskip("zenoh", reason="the zenoh extra is not installed")


def test_two_swarms_over_zenoh_confirm_and_watch() -> None:
    lab = f"api-{os.getpid()}-{time.monotonic_ns() % 100000}"
    with vstig_hw.join(f"zenoh:{lab}", robot_id=1) as first:
        [about] = first.reachable.values()
        endpoint = re.search(r"listening on (\S+)", about)
        assert endpoint is not None, about
        with vstig_hw.join(f"zenoh:{lab}?connect={endpoint.group(1)}", robot_id=2) as second:
            watch = second.watch(keys=[5])
            assert first.put(5, 55, confirm=True, timeout=5.0) == Entry(55, 1, 1)
            change = watch.get(5.0)
            assert change is not None and change.new == Entry(55, 1, 1) and change.link == f"zenoh-{lab}"
            assert second.put(6, 66, confirm=True, timeout=5.0) == Entry(66, 1, 2)
            assert first.entry(6) == Entry(66, 1, 2)


def test_a_second_table_over_zenoh_meets_the_other_programs_and_keeps_apart() -> None:
    lab = f"api-tables-{os.getpid()}-{time.monotonic_ns() % 100000}"
    with vstig_hw.join(f"zenoh:{lab}", robot_id=1) as first:
        endpoint = re.search(r"listening on (\S+)", next(iter(first.reachable.values())))
        assert endpoint is not None
        with vstig_hw.join(f"zenoh:{lab}?connect={endpoint.group(1)}", robot_id=2) as second:
            first_2, second_2 = first.stigmergy(2), second.stigmergy(2)
            assert first_2.put(1, 7, confirm=True, timeout=5.0) == Entry(7, 1, 1)
            deadline = time.monotonic() + 5
            while second_2.entry(1) is None and time.monotonic() < deadline:
                time.sleep(0.01)
            assert second_2.entry(1) == Entry(7, 1, 1)
            assert second.put(1, 9, confirm=True, timeout=5.0) == Entry(9, 1, 2)  # table 0: its own key 1
            time.sleep(0.2)
            assert first.entry(1) == Entry(9, 1, 2) and first_2.entry(1) == Entry(7, 1, 1)
            assert second_2.entry(1) == Entry(7, 1, 1)
