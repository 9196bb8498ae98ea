"""The hot counts the compiled path holds in C (`Counters.pending`, vstig_hw/_cext/pending.c) reach every reader.

A real compiled relay over ptys adds rx, rx_bytes, in, tx, tx_bytes and out as C integers; every way a program,
a capture or a metrics page reads a Counters (an item, get, iteration, items, dict(), json, ==, a copy, pickling,
the summary, stats()) must see them, and Python's own writes to the same dict must not lose any.
"""

from __future__ import annotations

import copy
import json
import os
import pickle
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import ModuleType
from typing import Any

import pytest
from test_native_pty_relay import COBS8, arrived, two_radios

from vstig_hw import Message, Op
from vstig_hw.counters import Counters
from vstig_hw.gateway import Mode, Node

HOT = ("rx", "rx_bytes", "tx", "tx_bytes", "in", "out", "not_echoed")  # the names pending.c keeps

# Each read sees the counts as one dict; a read that missed what is pending would see fewer.
READS: dict[str, Callable[[Counters], dict[str, int]]] = {
    "item": lambda c: {name: c[name] for name in HOT},
    "get": lambda c: {name: c.get(name, 0) for name in HOT},
    "items": lambda c: dict(c.items()),
    "keys and values": lambda c: dict(zip(list(c.keys()), list(c.values()), strict=True)),
    "iteration": lambda c: {name: dict.__getitem__(c, name) for name in list(c)},
    "dict()": lambda c: dict(c),
    "unpacked": lambda c: {**c},
    "json": lambda c: json.loads(json.dumps(c)),
    "copy": lambda c: dict.copy(c.copy()),
    "copy.copy": lambda c: dict(copy.copy(c)),
    "pickle": lambda c: dict(pickle.loads(pickle.dumps(c))),
    "Counters()": lambda c: dict.copy(Counters(c)),
    "summary": lambda c: {k: int(v) for k, v in (part.split("=") for part in c.summary().split())},
    "most_common": lambda c: dict(c.most_common()),
}


@contextmanager
def relay() -> Iterator[tuple[Callable[[int], None], Node]]:
    """A compiled raw relay between two ptys; send(n) relays n more messages (one a write) and waits for them."""
    with two_radios() as (a, b, links), Node(links, 200, mode=Mode.RAW, budget=None) as node:
        assert node.compiled
        sent = 0

        def send(n: int) -> None:
            nonlocal sent
            for key in range(sent, sent + n):
                os.write(a, COBS8.encode(Message(Op.PUT, key % 1000, 1, 1, 7))[0])
                assert [m.key for m in arrived(b, 1)] == [key % 1000]
            sent += n

        yield send, node


def pending_of(counters: Counters) -> dict[str, int]:
    pending: Any = counters.pending  # the attribute alone folds nothing
    assert pending is not None, "the compiled path keeps no counts of its own here"
    return dict(pending.counts)


def nonzero(counts: dict[str, int]) -> dict[str, int]:
    return {name: n for name, n in counts.items() if n}


@pytest.mark.parametrize("read", sorted(READS))
def test_every_read_sees_what_the_c_holds(compiled: ModuleType, read: str) -> None:
    with relay() as (send, node):
        send(3)
        for counters in (node.links[0].transport.counters, node.links[1].transport.counters):
            send(1)
            held = pending_of(counters)
            assert held, "a message relayed left nothing pending (the counts went to the dict)"
            expected = nonzero({name: dict.get(counters, name, 0) + held.get(name, 0)
                                for name in {*dict.keys(counters), *held}})
            assert nonzero(READS[read](counters)) == expected
            assert pending_of(counters) == {}, f"{read} read without folding in"


def test_the_counts_equal_what_crossed(compiled: ModuleType) -> None:
    """rx on A, tx on B and the links' in and out are the messages relayed, bytes the frames' sizes."""
    frame = len(COBS8.encode(Message(Op.PUT, 1, 1, 1, 7))[0])
    with relay() as (send, node):
        send(25)
        a, b = node.links
        assert (a.transport.counters["rx"], a.transport.counters["rx_bytes"]) == (25, 25 * frame)
        transport: Any = b.transport
        preamble = len(transport.preamble)  # a serial transport's, ahead of the first frame written
        assert (b.transport.counters["tx"], b.transport.counters["tx_bytes"]) == (25, 25 * frame + preamble)
        assert (a.counters["in"], b.counters["out"]) == (25, 25)
        send(5)
        assert {name: stats["out"] for name, stats in node.stats().items() if name in "ab"} == {"a": 0, "b": 30}


def test_pythons_own_adds_and_the_c_s_both_count(compiled: ModuleType) -> None:
    """A Python `+=` on a name the C holds pending (a read, then a set of what it read plus one) loses neither."""
    with relay() as (send, node):
        send(2)
        counters = node.links[0].transport.counters
        send(3)
        assert pending_of(counters).get("rx", 0) >= 3  # (the first count of a name goes into the dict)
        counters["rx"] += 10
        send(4)
        assert counters["rx"] == 2 + 3 + 10 + 4


def test_a_cleared_counters_counts_again_from_nothing(compiled: ModuleType) -> None:
    """clear() drops what is pending too, and the next count reaches a dict json sees as not empty."""
    with relay() as (send, node):
        send(2)
        counters = node.links[0].transport.counters
        send(1)
        counters.clear()
        assert pending_of(counters) == {} and dict(counters) == {}
        send(2)
        assert dict.__len__(counters) > 0  # the first count after a clear went into the dict
        assert json.loads(json.dumps(counters))["rx"] == 2
        assert counters.pop("rx") == 2 and "rx" not in counters
        send(1)
        assert counters["rx"] == 1
