"""The ros2 link's table snapshots (gateway/ros2.py): what a burst of `table` calls costs the Node."""

from __future__ import annotations

import threading
import time

from vstig_hw.engine import Entry
from vstig_hw.gateway.ros2 import TABLE_SPACING, TableSnapshots
from vstig_hw.transports.ros2 import TABLE_RECORD


class Table:
    """A Node's `entries()`, counting its walks (each holds the Node's lock in a gateway)."""

    def __init__(self, keys: int) -> None:
        self.entries = {key: Entry(key * 2, 1, 9) for key in reversed(range(keys))}
        self.walks: list[float] = []

    def take(self) -> list[tuple[int, Entry]]:
        self.walks.append(time.monotonic())
        time.sleep(0.01)  # a walk of a big table
        return list(self.entries.items())


def test_fifty_calls_at_once_share_one_or_two_snapshots_of_the_table_by_key() -> None:
    table = Table(18_000)
    snapshots = TableSnapshots(table.take)
    got = []
    threads = [threading.Thread(target=lambda: got.append(snapshots.snapshot())) for _ in range(50)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(got) == 50 and len(table.walks) <= 2, len(table.walks)
    records = list(TABLE_RECORD.iter_unpack(got[-1].records))
    assert records == [(key, key * 2, 1, 9) for key in range(18_000)]


def test_an_unchanged_table_is_not_walked_again_and_a_changing_one_at_most_once_a_spacing() -> None:
    table = Table(10)
    snapshots = TableSnapshots(table.take)
    first = snapshots.snapshot()
    assert snapshots.snapshot() is first and len(table.walks) == 1
    for n in range(4):
        table.entries[3] = Entry(100 + n, 2 + n, 9)
        snapshots.changed()
        taken = snapshots.snapshot()  # asked after the change: it holds the change
        assert (3, 100 + n, 2 + n, 9) in TABLE_RECORD.iter_unpack(taken.records)
        assert taken.serial == first.serial + n + 1
    gaps = [later - earlier for earlier, later in zip(table.walks, table.walks[1:], strict=False)]
    assert len(table.walks) == 5 and min(gaps) >= TABLE_SPACING * 0.99, gaps
