"""The confirmed write's transition table (gateway/confirm.py) as a table: its diagram, its reach, DONE absorbing,
an event it lacks refused, and a property over any inputs a driver can bring (test_confirm.py plays the cases)."""

from __future__ import annotations

import textwrap
from collections import deque
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vstig_hw import Entry, Message, Op, Stigmergy
from vstig_hw.gateway import confirm
from vstig_hw.gateway.confirm import TRANSITIONS, ConfirmedWrite, Event, Send, State, UnexpectedEvent, Verdict

ME, KEY, VALUE, ROBOT = 33, 23, 9, 4


def test_the_docstring_diagram_is_the_table_rendered() -> None:
    drawn = textwrap.indent(confirm.diagram(), "    ")
    assert drawn in (confirm.__doc__ or ""), "regenerate it: python -m vstig_hw.gateway.confirm"
    for state in State:
        assert f"\n    {state.name}\n" in confirm.__doc__ + "\n"  # every state has its paragraph


def test_every_state_and_verdict_is_reachable_from_idle() -> None:
    seen, verdicts, todo = {State.IDLE}, set(), deque([State.IDLE])
    while todo:
        for step in TRANSITIONS[todo.popleft()].values():
            if step.verdict is not None:
                verdicts.add(step.verdict)
            if step.to not in seen:
                seen.add(step.to)
                todo.append(step.to)
    assert seen == set(State) and verdicts == set(Verdict)


def test_done_absorbs_every_event_and_only_a_move_into_done_names_a_verdict() -> None:
    assert set(TRANSITIONS) == set(State)
    done = TRANSITIONS[State.DONE]
    assert set(done) == set(Event)
    assert all(step.to is State.DONE and step.sends == () and step.verdict is None for step in done.values())
    for state, events in TRANSITIONS.items():
        if state is not State.DONE:
            for event, step in events.items():
                assert (step.verdict is not None) is (step.to is State.DONE), (state, event)


def test_an_event_the_table_lacks_is_an_error_naming_it() -> None:
    machine = ConfirmedWrite(KEY, ME)
    with pytest.raises(UnexpectedEvent, match="cannot take 'time limit' while idle"):
        machine.tick(0.0)  # a control step before start
    assert machine.start(0.0) == [Send.PROBE, Send.WRITE]
    with pytest.raises(UnexpectedEvent, match="cannot take 'time limit' while writing"):
        machine.tick(0.1)  # the driver did not tell `wrote` what it stored


def test_the_driver_feeds_everything_heard_and_the_machine_picks_what_concerns_the_write() -> None:
    machine = ConfirmedWrite(KEY, ME)
    machine.start(0.0)
    machine.wrote(Entry(VALUE, 1, ME), 0.0)
    other_key, own_frame = Message(Op.PUT, KEY + 1, VALUE, 1, ME), Message(Op.PUT, KEY, VALUE, 1, ME)
    assert machine.heard_on("can0", ME, [own_frame], 0.01) == [] and machine.last_heard is None
    assert machine.table_changed(KEY, Entry(VALUE, 1, ME), None, 0.01) == []  # our own write, told by `wrote`
    assert machine.table_changed(KEY + 1, Entry(1, 9, ROBOT), "radio", 0.01) == [] and machine.holds == Entry(
        VALUE, 1, ME)
    assert machine.heard_on("radio", None, [other_key], 0.02) == [] and not machine.done
    machine.heard_on("radio", ROBOT, [other_key, own_frame], 0.03)
    assert machine.verdict is Verdict.TAKEN and machine.shown == Entry(VALUE, 1, ME)


# What a neighbour may say, relative to what the machine wrote last (drawn before it is known).
SAYS = st.sampled_from(["ours", "one past", "two past", "rival", "winning rival", "older", "probe back",
                        "relayed probe", "other key"])
INPUTS = st.lists(st.one_of(st.tuples(st.just("tick"), st.floats(0.0, 0.4)),
                            st.tuples(st.just("hear"), SAYS, st.sampled_from([None, ME, ROBOT, 200]))),
                  max_size=40)


def said(what: str, written: Entry | None, robot: int) -> Message:
    ts = written.timestamp if written is not None else 5
    return {"ours": Message(Op.PUT, KEY, VALUE, ts, ME), "one past": Message(Op.PUT, KEY, 1, ts + 1, robot),
            "two past": Message(Op.PUT, KEY, 1, ts + 2, robot), "rival": Message(Op.PUT, KEY, 2, ts, 1),
            "winning rival": Message(Op.PUT, KEY, 2, ts, 200),
            "older": Message(Op.GET, KEY, 3, max(1, ts - 1), robot), "probe back": Message(Op.GET, KEY, 0, 0, ME),
            "relayed probe": Message(Op.GET, KEY, 0, 0, ME), "other key": Message(Op.PUT, KEY + 1, 1, ts, ME)}[what]


@settings(max_examples=300, deadline=None)
@given(learn=st.sampled_from([0.0, 0.3]), confirm_it=st.booleans(), tries=st.integers(1, 3), inputs=INPUTS)
def test_any_inputs_a_driver_brings_are_in_the_table_and_never_leave_done(
        learn: float, confirm_it: bool, tries: int, inputs: list[tuple[Any, ...]]) -> None:
    """Driven as the Node's driver does (a WRITE is stored and told at once), no input meets an event the table
    lacks; once DONE nothing is sent and the verdict and the result never change."""
    engine, machine = Stigmergy(ME), ConfirmedWrite(KEY, ME, learn=learn, wait=0.5, tries=tries, confirm=confirm_it)
    fixed: list[Any] = []

    def do(sends: list[Send], now: float) -> None:
        if fixed:
            assert sends == [] and machine.state is State.DONE
            assert (machine.verdict, machine.written, machine.holds, machine.last_heard) == fixed[0]
        elif machine.done:
            fixed.append((machine.verdict, machine.written, machine.holds, machine.last_heard))
        for send in sends:
            if send is Send.WRITE and not machine.done:
                engine.put(KEY, VALUE)
                stored = engine.entry(KEY)
                assert stored is not None
                do(machine.wrote(stored, now), now)

    now = 0.0
    do(machine.start(now), now)
    for kind, *args in inputs:
        if kind == "tick":
            now += args[0]
            do(machine.tick(now), now)
            continue
        what, sender = args
        message = said(what, machine.written, ROBOT)
        if what == "relayed probe":
            sender = ROBOT  # Buzz relays an empty GET for a key it lacks, named by the relay
        before = engine.entry(KEY)
        do(machine.heard_on("radio", sender, [message], now), now)
        engine.receive(message)
        if engine.entry(KEY) != before:
            do(machine.table_changed(message.key, engine.entry(KEY), "radio", now), now)
    do([], now)
    assert machine.done is (machine.verdict is not None)
