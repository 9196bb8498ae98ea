"""The fair share of an outlet, pure: data in, data out. Each rule by example, then a property against the
out-queue's rules (hypothesis): the share changes the order in which keys leave, never what is sent for a key."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vstig_hw import Message, Op
from vstig_hw.gateway.fairshare import LINES_PER_LINK, LOCAL, FairFifo, FairQueue
from vstig_hw.outqueue import OutQueue, replaces

PUT, GET = Op.PUT, Op.GET
A, B, H = 0, 1, 2  # link indexes: two honest robots' radios and a flooding one


def put(key: int, ts: int = 1, robot: int = 1, value: int = 7) -> Message:
    return Message(PUT, key, value, ts, robot)


def get(key: int, ts: int = 1, robot: int = 1, value: int = 7) -> Message:
    return Message(GET, key, value, ts, robot)


def flood(count: int, first_key: int = 1000) -> list[Message]:
    return [put(first_key + i, robot=66) for i in range(count)]


def keys(messages: list[Message]) -> list[int]:
    return [msg.key for msg in messages]


# -- the turns -------------------------------------------------------------------------
def test_a_message_waits_for_one_message_of_a_flooder_not_for_its_backlog() -> None:
    queue = FairQueue()
    queue.push(flood(5000), H)
    queue.push([put(1)], A)
    assert keys(queue.drain(2)) == [1000, 1]  # the flooder's turn, then A's: not 5,000 of the flooder's first
    assert len(queue) == 4999


def test_sources_take_turns_one_message_each_and_a_sparse_one_goes_first() -> None:
    queue = FairQueue()
    queue.push([put(10), put(11), put(12)], A)
    queue.push([put(20), put(21)], B)
    assert keys(queue.drain(2)) == [10, 20]
    queue.push([put(30)], LOCAL)  # its line was empty: ahead of A and B, once, then in its turn
    assert keys(queue.drain()) == [30, 11, 21, 12]
    assert not queue and queue.sources == 0


# -- sparse links (RFC 8290's new flows) --------------------------------------------------
def test_a_sparse_links_message_leaves_before_a_backlog() -> None:
    queue = FairQueue()
    queue.push(flood(5000), H)
    assert keys(queue.drain(3)) == [1000, 1001, 1002]
    queue.push([put(1)], A)
    assert len(queue.sparse) == 1
    assert keys(queue.drain(2)) == [1, 1003]  # A's first: not after the flood's turn


def test_a_link_served_within_the_round_is_sparse_again_only_once_its_turn_came_round() -> None:
    queue = FairQueue()
    queue.push(flood(100), H)
    queue.push(flood(100, 2000), B)
    queue.push([put(1)], A)
    assert keys(queue.drain(3)) == [1000, 2000, 1]  # all three sparse, in the order they came
    queue.push([put(2)], A)  # served within the round: it waits for its turn
    assert not queue.sparse and keys(queue.drain(3)) == [1001, 2001, 2]
    assert keys(queue.drain(1)) == [1002]
    queue.push([put(3)], A)  # its turn (its emptied place) has not come round yet
    assert not queue.sparse and keys(queue.drain(2)) == [2002, 3]
    assert keys(queue.drain(3)) == [1003, 2003, 1004]  # A's emptied place came round and passed
    queue.push([put(4)], A)
    assert len(queue.sparse) == 1 and keys(queue.drain(1)) == [4]


def test_a_source_refilling_its_line_each_time_it_empties_gets_one_message_a_round() -> None:
    """Becoming sparse at every chance gains nothing: against one backlog, half the messages, as in the round."""
    queue = FairQueue()
    queue.push(flood(1000), H)
    out: list[int] = []
    for i in range(200):
        if not queue._lines.get((A, None)):
            queue.push([put(i + 1)], A)
        out += keys(queue.drain(1))
    assert sum(key < 1000 for key in out) <= 101


def test_many_sub_sources_of_one_link_each_sending_one_message_share_that_links_turn() -> None:
    """A flooder opening a fresh session (a sub-source) for every message is not sparse for it: sub-sources split
    their link's turn, and only a link is sparse."""
    queue = FairQueue()
    queue.push([put(i + 1) for i in range(900)], A)
    out: list[int] = []
    for session in range(300):
        queue.push([put(1000 + session, robot=66)], H, f"session-{session}")
        queue.push([put(2000 + session, robot=66)], H, f"session-{session}-b")
        out += keys(queue.drain(2))
    a = [key < 1000 for key in out]
    assert all(a[1::2]) or all(a[0::2])  # every other message is A's, however many sessions H opens
    assert not queue.sparse


@st.composite
def link_steps(draw: st.DrawFn) -> list[tuple[int, int, int] | int]:
    """Steps: (link, sub, how many distinct keys) pushed, or a drain budget."""
    step = st.one_of(st.tuples(st.integers(-1, 3), st.integers(0, 3), st.integers(1, 4)), st.integers(1, 5))
    return draw(st.lists(step, max_size=80))


@settings(max_examples=300, deadline=None)
@given(link_steps())
def test_a_waiting_link_waits_for_at_most_one_message_of_every_other_link(steps: list[tuple[int, int, int] | int]
                                                                           ) -> None:
    """Sparse links first does not weaken the round: between two messages of a link that had messages waiting
    all along, every other link sends at most one; and a sparse link waits only for the sparse links ahead."""
    queue = FairQueue()
    waiting = dict.fromkeys(range(-1, 4), 0)
    since: dict[int, dict[int, int]] = {}  # link waiting all along -> messages of each other link since its last
    fresh = 0
    for step in steps:
        if isinstance(step, int):
            sparse = list(queue.sparse)
            out = queue.drain(step)
            assert [msg.key // 1000 - 2 for msg in out[:len(sparse)]] == sparse[:len(out)]
            for msg in out:
                link = msg.key // 1000 - 2
                waiting[link] -= 1
                since[link] = {}
                for other, counts in since.items():
                    if other != link:
                        counts[link] = counts.get(link, 0) + 1
                        assert counts[link] <= 1, (other, link, out)
                if not waiting[link]:
                    del since[link]
        else:
            link, sub, count = step
            queue.push([put((link + 2) * 1000 + fresh + i) for i in range(count)], link, sub)  # keys never repeat
            fresh += count
            waiting[link] += count
            since.setdefault(link, {})



def test_a_links_peers_share_that_links_turn() -> None:
    """Zenoh peers (sub-sources of one link) split their link's share: many claimed sessions gain no more."""
    queue = FairQueue()
    for session in range(10):
        queue.push([put(1000 + 10 * session + i) for i in range(3)], H, f"session-{session}")
    queue.push([put(1), put(2), put(3)], A)
    out = keys(queue.drain(6))
    assert out[1::2] == [1, 2, 3]  # every other message is A's, however many sessions H's link claims
    assert out[0::2] == [1000, 1010, 1020]  # and H's sessions take turns within H's share


def test_sub_sources_beyond_the_cap_share_the_links_common_line() -> None:
    queue = FairQueue()
    for session in range(LINES_PER_LINK + 5):
        queue.push([put(1000 + session)], H, session)
    assert queue.sources == LINES_PER_LINK + 1  # the cap, plus the line None the others share
    assert len(queue) == LINES_PER_LINK + 5


def test_each_line_keeps_puts_before_gets_and_a_replaced_message_keeps_its_place() -> None:
    queue = FairQueue()
    queue.push([get(1), put(2), put(3)], A)
    queue.push([put(2, ts=2, value=9)], A)  # replaces 2 in its place, ahead of 3
    assert queue.drain() == [put(2, ts=2, value=9), put(3), get(1)]


# -- one pending message per key, across sources -------------------------------------------
def test_a_newer_message_from_another_source_replaces_the_pending_one_and_waits_in_its_own_line() -> None:
    queue = FairQueue()
    queue.push(flood(100), H)
    queue.push([put(1050, ts=2, robot=5)], A)  # robot 5 wrote key 1050 again: H's pending copy is outdated
    assert queue.drain(2) == [put(1000, robot=66), put(1050, ts=2, robot=5)]
    assert 1050 not in keys(queue.drain())  # it left once, from A's line


def test_a_conflicts_winner_from_another_source_replaces_the_loser() -> None:
    queue = FairQueue()
    queue.push([put(4, ts=3, robot=2, value=9)], A)
    queue.push([put(4, ts=3, robot=5, value=1)], B)  # same timestamp, another entry: the loser is never sent
    assert queue.drain() == [put(4, ts=3, robot=5, value=1)]


def test_an_older_message_from_another_source_is_not_queued() -> None:
    queue = FairQueue()
    queue.push([put(4, ts=3)], A)
    assert queue.push([put(4, ts=2), get(4, ts=1)], B) == 2
    assert queue.drain() == [put(4, ts=3)] and queue.sources == 0


def test_an_entry_two_sources_asked_for_leaves_from_the_first_line_that_reaches_it_and_only_once() -> None:
    queue = FairQueue()
    queue.push(flood(100), H)  # H's stale GETs were answered: the engine's entries wait in H's line
    assert queue.push([put(1099, robot=66)], B) == 1  # B's stale GET for the last of them: the same answer
    out = queue.drain(2)
    assert out == [put(1000, robot=66), put(1099, robot=66)]  # from B's line, not behind H's 98 others
    assert put(1099, robot=66) not in queue.drain()  # and gone from H's line too


def test_a_flooder_asking_for_an_entry_cannot_pull_it_into_its_own_line() -> None:
    queue = FairQueue()
    queue.push(flood(100), H)
    queue.push([put(1, robot=5)], A)  # robot 5's write, re-broadcast
    queue.push([put(1, robot=5)], H)  # H's stale GET for key 1 is answered with that same entry
    assert queue.drain(2) == [put(1000, robot=66), put(1, robot=5)]  # it keeps its place in A's line


def test_a_get_of_a_pending_put_keeps_the_put() -> None:
    queue = FairQueue()
    queue.push([put(4, ts=3)], A)
    queue.push([get(4, ts=3)], LOCAL)  # the gateway's own refresh GET of the same entry
    assert queue.drain() == [put(4, ts=3)]


def test_draining_one_source_alone_clears_every_place() -> None:
    queue = FairQueue()
    queue.push([put(1), put(2)], A)
    assert queue.drain() == [put(1), put(2)] and not queue
    queue.push([put(1, ts=2)], B)
    assert queue.drain() == [put(1, ts=2)]


@st.composite
def pushes_and_drains(draw: st.DrawFn) -> list[tuple[int, int, list[Message]] | int]:
    """Steps: (link, sub, messages) pushed, or a drain budget."""
    message = st.builds(Message, st.sampled_from([PUT, GET]), st.integers(0, 5), st.integers(0, 3),
                        st.integers(1, 4), st.integers(1, 3))
    step = st.one_of(st.tuples(st.integers(-1, 2), st.integers(0, 2), st.lists(message, max_size=4)),
                     st.integers(1, 4))
    return draw(st.lists(step, max_size=40))


@settings(max_examples=300, deadline=None)
@given(pushes_and_drains())
def test_what_leaves_for_each_key_is_what_the_out_queue_would_send(steps: list[tuple[int, int, list[Message]] | int]
                                                                    ) -> None:
    queue = FairQueue()
    pending: dict[int, Message] = {}  # the out-queue's rules on one queue: what is due for each key
    for step in steps:
        if isinstance(step, int):
            out = queue.drain(step)
            assert len(out) == min(step, len(pending))
            assert len({msg.key for msg in out}) == len(out)  # no key twice in one drain
            for msg in out:
                assert pending.pop(msg.key) == msg
        else:
            link, sub, messages = step
            queue.push(messages, link, sub)
            for msg in messages:
                due = pending.get(msg.key)
                if due is None or replaces(msg, due):
                    pending[msg.key] = msg
        assert len(queue) == len(pending)
    assert {msg.key: msg for msg in queue.drain()} == pending


def test_one_source_alone_drains_as_the_out_queue_does() -> None:
    messages = [put(3), get(1), put(2), put(3, ts=2), get(1, ts=2), put(5)]
    queue, reference = FairQueue(), OutQueue()
    queue.push(messages, A)
    for msg in messages:
        reference.push(msg)
    assert queue.drain(3) == reference.drain(3) and queue.drain() == reference.drain()


# -- raw bridges -------------------------------------------------------------------------
def test_a_raw_queue_serves_sources_in_turn_and_keeps_every_message_in_order() -> None:
    fifo = FairFifo(limit=100)
    fifo.push([put(1), put(1, ts=2)], A)
    fifo.push(flood(3), H)
    assert keys(fifo.drain()) == [1, 1000, 1, 1001, 1002]
    assert not fifo


def test_a_raw_queue_serves_a_sparse_link_first_too() -> None:
    fifo = FairFifo(limit=100)
    fifo.push(flood(50), H)
    assert keys(fifo.drain(2)) == [1000, 1001]
    fifo.push([put(1), put(1, ts=2)], A)
    assert keys(fifo.drain(4)) == [1, 1002, 1, 1003]  # its first message ahead of the backlog, then in turn


def test_a_full_raw_queue_drops_the_flooders_oldest_not_another_sources() -> None:
    fifo = FairFifo(limit=10)
    fifo.push([put(1), put(2)], A)
    assert fifo.push(flood(12), H) == 4  # 14 waiting, room for 10: four of H's oldest go
    assert len(fifo) == 10
    out = keys(fifo.drain())
    assert out[:4] == [1, 1004, 2, 1005] and out[4:] == list(range(1006, 1012))


def test_a_raw_queue_refuses_a_limit_below_one() -> None:
    with pytest.raises(ValueError, match="at least 1"):
        FairFifo(limit=0)
