"""The confirmed write's state machine (gateway/confirm.py), as data: what is heard and when -> what it sends
and its verdict.

Each case is a sequence of events fed to a `ConfirmedWrite` beside a real engine (`Stigmergy`) that stands
for our table, as the driver on a Node does: a heard message goes to the machine first, then into the
engine, and the entry it leaves is told (`changed`) when it moved; a WRITE the machine asks for is the
engine's `put`, told back (`wrote`). The patterns are those a radio, a CAN bus and Buzz robots make:
re-broadcasts, answers, GETs carrying our entry, a write on top of ours, echoes, relayed empty GETs.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from vstig_hw import Entry, Message, Op, Stigmergy
from vstig_hw.gateway.confirm import ConfirmedWrite, Send, State, Verdict

ME, KEY, VALUE = 33, 23, 9
ROBOT, OTHER = 4, 1  # neighbours


def put(value: int, timestamp: int, robot: int, key: int = KEY) -> Message:
    return Message(Op.PUT, key, value, timestamp, robot)


def get(value: int, timestamp: int, robot: int, key: int = KEY) -> Message:
    return Message(Op.GET, key, value, timestamp, robot)


PROBE_BACK = get(0, 0, ME)  # our own empty GET, as an echo brings it back

# name: (options, events, sends, verdict, extra checks). An event: (t, "start") | (t, "tick") |
# (t, "hear", message, link, sender) | (t, "hold", key, value, timestamp, robot) (what our table held before).
CASES: dict[str, tuple[dict[str, Any], list[tuple[Any, ...]], list[str], Verdict | None, dict[str, Any]]] = {
    "a neighbour re-broadcasts our PUT: taken at once": (
        {}, [(0.0, "start"), (0.004, "hear", put(VALUE, 1, ME), "radio", None)],
        ["probe", "write", "probe"], Verdict.TAKEN, {"shown": Entry(VALUE, 1, ME), "tries": 1}),
    "a neighbour answers the probe after the write with our entry (a gateway that does not echo)": (
        {}, [(0.0, "start"), (0.002, "hear", put(VALUE, 1, ME), "zenoh-lab", 200)],
        ["probe", "write", "probe"], Verdict.TAKEN, {"shown": Entry(VALUE, 1, ME)}),
    "a neighbour's GET carries our entry (Buzz's get() each step)": (
        {}, [(0.0, "start"), (0.05, "hear", get(VALUE, 1, ME), "blabbermouth", ROBOT)],
        ["probe", "write", "probe"], Verdict.TAKEN, {"shown": Entry(VALUE, 1, ME)}),
    "an echoing radio brings the probe back before our PUT: hears itself, the PUT's copy is not a neighbour": (
        {}, [(0.0, "start"), (0.001, "hear", PROBE_BACK, "loop", None),
             (0.001, "hear", put(VALUE, 1, ME), "loop", None)],
        ["probe", "write", "probe"], Verdict.HEARS_ITSELF, {"echoed_on": "loop"}),
    "an echoing radio found while learning: nothing is written": (
        {"learn": 0.5}, [(0.0, "start"), (0.001, "hear", PROBE_BACK, "loop", None), (0.1, "tick"), (0.6, "tick")],
        ["probe"], Verdict.HEARS_ITSELF, {"written": None}),
    "our own frames named as ours (CAN IDs, receive_own_messages) are skipped, a neighbour's copy counts": (
        {}, [(0.0, "start"), (0.001, "hear", PROBE_BACK, "can0", ME), (0.001, "hear", put(VALUE, 1, ME), "can0", ME),
             (0.003, "hear", put(VALUE, 1, ME), "can0", ROBOT)],
        ["probe", "write", "probe"], Verdict.TAKEN, {"shown": Entry(VALUE, 1, ME)}),
    "Buzz relays our empty GET for a key it lacks: named by its relay, not an echo": (
        {"learn": 0.3}, [(0.0, "start"), (0.05, "hear", PROBE_BACK, "blabbermouth", ROBOT), (0.1, "tick"),
                         (0.2, "tick"), (0.31, "tick"), (0.36, "hear", put(VALUE, 1, ME), "blabbermouth", ROBOT)],
        ["probe", "probe", "ask", "write", "probe"], Verdict.TAKEN, {"shown": Entry(VALUE, 1, ME)}),
    "a robot stores ours and writes on top of it at once (its out-queue sends only its own): taken": (
        {"learn": 0.2}, [(0.0, "hold", KEY, 1, 5, ROBOT), (0.0, "start"), (0.21, "tick"),
                         (0.25, "hear", put(1, 7, ROBOT), "radio", None)],
        ["probe", "write", "probe"], Verdict.TAKEN, {"shown": Entry(1, 7, ROBOT), "holds": Entry(VALUE, 6, ME),
                                                    "written": Entry(VALUE, 6, ME)}),
    "re-broadcast, then a robot writes ts + 1 during the drain: taken, fixed when shown (issue 32)": (
        {}, [(0.0, "hold", KEY, 5, 10, OTHER), (0.0, "start"), (0.01, "hear", put(VALUE, 11, ME), "kh4", ROBOT),
             (0.2, "hear", put(7, 12, OTHER), "kh4", OTHER), (0.3, "tick"), (3.0, "tick")],
        ["probe", "write", "probe"], Verdict.TAKEN, {"shown": Entry(VALUE, 11, ME), "holds": Entry(VALUE, 11, ME)}),
    "a write two past ours is not shown to be built on ours: written again, then taken": (
        {}, [(0.0, "start"), (0.01, "hear", put(1, 3, ROBOT), "radio", None),
             (0.02, "hear", put(VALUE, 4, ME), "radio", None)],
        ["probe", "write", "probe", "write", "probe"], Verdict.TAKEN, {"tries": 2, "written": Entry(VALUE, 4, ME)}),
    "superseded on every try: not taken, naming what the swarm holds": (
        {"tries": 2}, [(0.0, "start"), (0.01, "hear", put(1, 3, ROBOT), "radio", None),
                       (0.02, "hear", put(1, 6, ROBOT), "radio", None)],
        ["probe", "write", "probe", "write", "probe"], Verdict.SUPERSEDED,
        {"tries": 2, "holds": Entry(1, 6, ROBOT), "written": Entry(VALUE, 4, ME)}),
    "a conflict our write loses (same timestamp, higher id), then a write one past it: not built on ours": (
        {"tries": 1}, [(0.0, "start"), (0.01, "hear", put(1, 1, 200), "radio", None),
                       (0.02, "hear", put(2, 2, 200), "radio", None)],
        ["probe", "write", "probe"], Verdict.SUPERSEDED, {"holds": Entry(1, 1, 200)}),
    "a conflict our write wins: the neighbour then re-broadcasts ours": (
        {}, [(0.0, "start"), (0.01, "hear", put(1, 1, OTHER), "radio", None),
             (0.02, "hear", put(VALUE, 1, ME), "radio", None)],
        ["probe", "write", "probe"], Verdict.TAKEN, {"tries": 1}),
    "a copy of a superseded write heard later does not count": (
        {"tries": 1}, [(0.0, "start"), (0.01, "hear", put(1, 3, ROBOT), "radio", None),
                       (0.02, "hear", put(VALUE, 1, ME), "radio", None)],
        ["probe", "write", "probe"], Verdict.SUPERSEDED, {"holds": Entry(1, 3, ROBOT)}),
    "nobody answers: unanswered at the first step past the wait, asking meanwhile (probe, view, probe...)": (
        {"wait": 0.35}, [(0.0, "start"), (0.1, "tick"), (0.2, "tick"), (0.3, "tick"), (0.4, "tick"), (0.5, "tick")],
        ["probe", "write", "probe", "probe", "ask", "probe"], Verdict.UNANSWERED,
        {"holds": Entry(VALUE, 1, ME), "heard": None}),
    "what other keys carry is not ours": (
        {"wait": 0.1}, [(0.0, "start"), (0.01, "hear", put(VALUE, 1, ME, key=KEY + 1), "radio", None), (0.2, "tick")],
        ["probe", "write", "probe"], Verdict.UNANSWERED, {}),
    "learning asks every step, then writes newer than anything heard": (
        {"learn": 0.25}, [(0.0, "start"), (0.05, "hear", put(3, 40, ROBOT), "radio", None), (0.1, "tick"),
                          (0.2, "tick"), (0.3, "tick"), (0.31, "hear", put(VALUE, 41, ME), "radio", None)],
        ["probe", "probe", "ask", "write", "probe"], Verdict.TAKEN, {"written": Entry(VALUE, 41, ME)}),
    "without confirm: written once, nothing asked after": (
        {"confirm": False}, [(0.0, "start"), (0.1, "tick"), (0.01, "hear", PROBE_BACK, "loop", None)],
        ["write"], Verdict.UNCONFIRMED, {}),
    "without confirm, learning still comes first": (
        {"confirm": False, "learn": 0.15}, [(0.0, "start"), (0.1, "tick"), (0.2, "tick")],
        ["probe", "probe", "write"], Verdict.UNCONFIRMED, {}),
    "still waiting: no verdict": (
        {}, [(0.0, "start"), (0.1, "tick"), (0.01, "hear", put(2, 1, ROBOT, key=KEY + 1), "radio", None)],
        ["probe", "write", "probe", "probe"], None, {}),
}


def play(options: dict[str, Any], events: list[tuple[Any, ...]]) -> tuple[ConfirmedWrite, list[str]]:
    """Feed `events` to a machine beside a real engine, as the Node's driver does; what it sent, by name."""
    engine = Stigmergy(ME)
    machine = ConfirmedWrite(KEY, ME, **options)
    sent: list[str] = []

    def do(sends: list[Send], now: float) -> None:
        for send in sends:
            if machine.done:
                return
            sent.append(send.value)
            if send is Send.WRITE:
                engine.put(KEY, VALUE)
                written = engine.entry(KEY)
                assert written is not None
                do(machine.wrote(written, now), now)

    for event in events:
        now, kind = event[0], event[1]
        if kind == "hold":
            engine.receive(put(*event[3:], key=event[2]))
        elif kind == "start":
            do(machine.start(now), now)
        elif kind == "tick":
            do(machine.tick(now), now)
        else:
            msg, link, sender = event[2:]
            before = engine.entry(msg.key)
            do(machine.heard(msg, link, sender, now), now)
            engine.receive(msg)
            after = engine.entry(msg.key)
            if msg.key == KEY and after != before:
                do(machine.changed(after, now), now)
    return machine, sent


@pytest.mark.parametrize("name", list(CASES))
def test_a_confirmed_write_as_data(name: str) -> None:
    options, events, sends, verdict, checks = CASES[name]
    machine, sent = play(options, events)
    assert sent == sends
    assert machine.verdict is verdict
    assert machine.done is (verdict is not None)
    if verdict is None or (verdict is Verdict.HEARS_ITSELF and machine.written is None):
        assert "written" not in checks or machine.written == checks["written"]
        if "echoed_on" in checks:
            assert machine.echoed_on == checks["echoed_on"]
        return
    result = machine.result()
    assert result.verdict is verdict and result.confirmed is (verdict is Verdict.TAKEN)
    for field, expected in checks.items():
        got = machine.echoed_on if field == "echoed_on" else getattr(result, field)
        assert got == expected, field


def test_the_verdict_once_reached_never_changes() -> None:
    machine, _ = play({}, [(0.0, "start"), (0.01, "hear", put(VALUE, 1, ME), "radio", None)])
    fixed = machine.result()
    for later in (put(1, 9, ROBOT), PROBE_BACK, put(1, 2, ROBOT)):
        assert machine.heard(later, "radio", None, 0.5) == []
    assert machine.changed(Entry(1, 9, ROBOT), 0.6) == [] and machine.tick(99.0) == []
    assert machine.result() == fixed and machine.state is State.DONE


def test_no_result_before_a_verdict_and_a_clear_error_for_bad_tries() -> None:
    machine = ConfirmedWrite(KEY, ME)
    with pytest.raises(RuntimeError, match="no result yet"):
        machine.result()
    with pytest.raises(ValueError, match="tries must be at least 1"):
        ConfirmedWrite(KEY, ME, tries=0)


def test_the_machine_is_pure() -> None:
    """No I/O, thread or clock: the time comes in with every event (as the engine's rules)."""
    from module_imports import imports_of

    source = Path(__file__).parents[2] / "vstig_hw" / "gateway" / "confirm.py"
    assert imports_of(source, "vstig_hw.gateway") <= {"__future__", "enum", "dataclasses", "vstig_hw.engine",
                                                         "vstig_hw.timestamps", "vstig_hw.wire"}
