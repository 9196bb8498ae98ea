"""The live view's spread of each write (`LiveSpread`) against `analyze`'s measure of the same traffic."""

from __future__ import annotations

from vstig_hw.analysis import DEFAULT_WINDOW, Analyzer
from vstig_hw.links.link import Heard
from vstig_hw.live.spread import DEFAULT_WINDOW as LIVE_WINDOW
from vstig_hw.live.spread import LiveSpread
from vstig_hw.wire import Message, Op

T0 = 1_700_000_000.0
# Robot 3 writes key 1; 4 relays it, 5 asks with it; 6 only asks about key 2 (active, never shows key 1);
# a cobs8 radio (no sender) hears the relay too.
TRAFFIC = [
    Heard(Message(Op.GET, 2, 0, 0, 6), "can0", T0 + 0.0, 6),
    Heard(Message(Op.PUT, 1, 500, 1, 3), "can0", T0 + 0.1, 3),
    Heard(Message(Op.PUT, 1, 500, 1, 3), "can0", T0 + 0.6, 4),
    Heard(Message(Op.PUT, 1, 500, 1, 3), "radio", T0 + 0.7, None),
    Heard(Message(Op.GET, 1, 0, 0, 5), "can0", T0 + 0.8, 5),  # an empty GET: 5 is active, not caught up
    Heard(Message(Op.GET, 1, 500, 1, 3), "can0", T0 + 1.3, 5),  # a GET carries the entry it holds
    Heard(Message(Op.GET, 2, 0, 0, 6), "can0", T0 + 1.5, 6),
]


def _analyzed() -> dict[tuple[int, int, int], tuple[int, tuple[float, ...], tuple[int, ...]]]:
    analyzer = Analyzer()
    analyzer.add_messages((h.t, analyzer.link(h.link), -1 if h.sender is None else h.sender, h.message)
                          for h in TRAFFIC)
    return {(w.key, w.timestamp, w.robot): (w.senders_total, w.caught_up_after, w.behind)
            for w in analyzer.report().writes}


def test_the_windows_agree() -> None:
    assert LIVE_WINDOW == DEFAULT_WINDOW


def test_a_write_spreads_as_analyze_measures_it() -> None:
    live = LiveSpread()
    for heard in TRAFFIC:
        live.add(heard)
    rows = {(r["key"], r["timestamp"], r["robot"]): r for r in live.updates(T0 + 2.0, 50)}
    row = rows[(1, 1, 3)]
    total, caught, behind = _analyzed()[(1, 1, 3)]
    assert (row["senders_total"], row["senders_caught_up"], row["behind"]) == (total, len(caught), list(behind))
    assert (total, behind) == (4, (6,))  # 3, 4, 5 caught up; 6 never showed key 1
    assert row["converged_after"] is None and row["time_so_far"] == 1.9
    assert row["link"] == "can0" and row["value"] == 500 and not row["superseded"]
    assert live.updates(T0 + 2.1, 50)[0]["time_so_far"] == 2.0  # still spreading: shown again, time grows


def test_it_converges_when_the_last_active_sender_shows_it_or_newer() -> None:
    live = LiveSpread()
    for heard in TRAFFIC:
        live.add(heard)
    live.add(Heard(Message(Op.GET, 1, 500, 1, 3), "can0", T0 + 2.1, 6))
    (row,) = [r for r in live.updates(T0 + 3.0, 50) if r["key"] == 1]
    assert row["behind"] == [] and row["converged_after"] == 2.0  # 6 showed it 2.0 s after it appeared
    live.add(Heard(Message(Op.PUT, 1, 7, 2, 5), "can0", T0 + 3.5, 5))  # a newer write: the old row is final
    rows = {(r["timestamp"], r["robot"]): r for r in live.updates(T0 + 4.0, 50)}
    assert rows[(1, 3)]["superseded"] and rows[(2, 5)]["senders_caught_up"] == 1


def test_it_forgets_the_oldest_keys_beyond_keep() -> None:
    live = LiveSpread(keep=2)
    for key in range(1, 5):
        live.add(Heard(Message(Op.PUT, key, 1, 1, 3), "can0", T0 + key, 3))
    assert live.forgotten == 2
    assert sorted(r["key"] for r in live.updates(T0 + 5, 50)) == [3, 4]
