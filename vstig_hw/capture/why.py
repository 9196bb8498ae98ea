"""Why a sender holds the entry it holds for a key at a time: the newest write's path and one verdict per sender.

Read from a `Trace` (capture.trace): the newest write that existed at T (one the guard refused does not
count), where it was first heard and each link and sender that showed it next, what the recording gateway
did with it (its sends and decision notes), and for each sender what it last showed and why it is not the
newest, as a `cause` a program can test and a line a person reads (docs/how-to/why.md lists them).
"""

from __future__ import annotations

import bisect
from collections.abc import Callable
from dataclasses import dataclass, field

from .decision_notes import ENGINE_NOTES, QUEUED, Decision
from .trace import Shown, Trace, newer_entry

__all__ = ["CAUSES", "Answer", "Hop", "Verdict", "explain"]

# What a verdict's `cause` may be (None: the sender holds the newest write, no cause).
CAUSES = ("unheard", "never_asked", "refused", "conflict_lost", "never_sent", "deaf", "behind", "not_heard_since",
          "not_shown_since")
_NEAR = 1.0  # seconds around an event within which a decision note is taken as about it (a note is per tick)
_FULL_OUTLET = ("tx_overflow", QUEUED)


@dataclass(frozen=True)
class Hop:
    t: float
    link: str
    sender: str  # who showed it; for a send, the link it went out on
    sent: bool
    delay: float  # seconds since the previous hop


@dataclass(frozen=True)
class Verdict:
    sender: str
    cause: str | None
    line: str
    last_heard: float | None
    shown: Shown | None  # the last entry it showed for the key, at or before T


@dataclass
class Answer:
    key: int
    at: float
    newest: Shown | None  # the first showing of the newest write at T
    path: list[Hop] = field(default_factory=list)
    did: list[str] = field(default_factory=list)  # what the gateway did with the newest write, in words
    verdicts: list[Verdict] = field(default_factory=list)


def explain(trace: Trace, key: int, robot: str | None = None, at: float | None = None) -> Answer:
    """The answer for `key` at `at` seconds after the capture's start (None: its end); `robot` limits the
    verdicts to one sender (a sender id, or a serial link's name), else every sender that showed the key."""
    at = trace.end if at is None else at
    everything = trace.of(key)
    shown = everything[:bisect.bisect_right(everything, at, key=lambda s: s.t)]
    refused = {entry for d in trace.decisions if (entry := d.entry) is not None and d.t <= at + _NEAR}
    newest = _newest(shown, key, refused)
    answer = Answer(key, at, newest)
    if newest is not None:
        answer.path = _path(shown, newest)
        answer.did = _did(trace, shown, newest, key, refused)
    asked = _Asked(trace, key, at, shown, newest, refused)
    senders = [robot] if robot is not None else sorted(asked.by_sender)
    answer.verdicts = [_verdict(asked, sender) for sender in senders]
    return answer


class _Asked:
    """One question's key, time and newest write, with its messages grouped once: each sender's, and the
    gateway's sends of the newest write (or a newer entry) per link."""

    def __init__(self, trace: Trace, key: int, at: float, shown: list[Shown], newest: Shown | None,
                 refused: set[tuple[int, int, int]]) -> None:
        self.trace, self.key, self.at, self.shown, self.newest, self.refused = trace, key, at, shown, newest, refused
        self.by_sender: dict[str, list[Shown]] = {}
        self.sends: dict[str, list[Shown]] = {}
        for s in shown:
            if not s.sent:
                self.by_sender.setdefault(s.sender, []).append(s)
            elif newest is not None and s.t >= newest.t and (s.entry == newest.entry
                                                             or newer_entry(s.entry, newest.entry)):
                self.sends.setdefault(s.link, []).append(s)
        self.last_heard = trace.last_heard(at)

    def sends_to(self, sender: str) -> list[Shown]:
        """The gateway's sends of the newest write (or newer) on the links `sender` is heard on, in time order."""
        lists = [self.sends.get(link, []) for link in sorted(self.trace.links_of(sender))]
        return sorted((s for sends in lists for s in sends), key=lambda s: s.t) if len(lists) > 1 else \
            (lists[0] if lists else [])


def _newest(shown: list[Shown], key: int, refused: set[tuple[int, int, int]]) -> Shown | None:
    best: Shown | None = None
    for s in shown:
        if s.holds and (key, s.ts, s.robot) not in refused and (best is None or newer_entry(s.entry, best.entry)):
            best = s
    return best


def _path(shown: list[Shown], newest: Shown) -> list[Hop]:
    """The first showing of the write per (link, sender), in time order, each with its delay after the last."""
    hops: list[Hop] = []
    seen: set[tuple[str, str, bool]] = set()
    for s in shown:
        if s.t < newest.t or s.entry != newest.entry:
            continue
        where = (s.link, s.sender, s.sent)
        if where in seen:
            continue
        seen.add(where)
        hops.append(Hop(s.t, s.link, s.sender, s.sent, s.t - hops[-1].t if hops else 0.0))
    return hops


def _did(trace: Trace, shown: list[Shown], newest: Shown, key: int, refused: set[tuple[int, int, int]]) -> list[str]:
    """What the recording gateway did with the newest write: from its sends and its decision notes."""
    did: list[str] = []
    sends: dict[str, int] = {}
    for s in shown:
        if s.sent and s.entry == newest.entry:
            sends[s.link] = sends.get(s.link, 0) + 1
    if sends:
        did.append("the gateway stored it and sent it on "
                   + ", ".join(f"{link} ({n}x)" for link, n in sorted(sends.items())))
    lost = {s.entry for s in shown if s.ts == newest.ts and s.robot != newest.robot}
    for ts, robot in sorted(lost):
        note = _note_near(trace, newest.t, lambda d: d.link == ENGINE_NOTES and d.reason == "conflict")
        counted = f" (the gateway counted a conflict at {note.t:.2f} s)" if note else ""
        did.append(f"robot {robot}'s write of the same timestamp {ts} lost the conflict to it{counted}")
    refusals: dict[tuple[int | None, int | None, str, str], list[float]] = {}
    for d in trace.decisions:
        if d.key == key and d.t >= newest.t - _NEAR and d.entry in refused:
            refusals.setdefault((d.robot, d.ts, d.link, d.reason), []).append(d.t)
    for (writer, stamp, link, reason), times in sorted(refusals.items(), key=lambda item: item[1][0]):
        did.append(f"the gateway refused robot {writer}'s ts {stamp} on {link} {len(times)}x from {times[0]:.2f} s "
                   f"({reason})")
    heard_on = newest.link
    intake = _note_near(trace, newest.t, lambda d: d.link == heard_on and d.reason == "drop_intake")
    if intake is not None:
        did.append(f"the fair share dropped {intake.count} messages heard on {heard_on} at {intake.t:.2f} s "
                   "(drop_intake)")
    return did


def _note_near(trace: Trace, t: float, wanted: Callable[[Decision], bool]) -> Decision | None:
    return next((d for d in trace.decisions if abs(d.t - t) <= _NEAR and wanted(d)), None)


def _verdict(asked: _Asked, sender: str) -> Verdict:
    trace, key, at, newest = asked.trace, asked.key, asked.at, asked.newest
    last_heard = asked.last_heard.get(sender)
    mine = asked.by_sender.get(sender, [])
    last = mine[-1] if mine else None
    if last_heard is None:
        return Verdict(sender, "unheard", f"{sender} was never heard before {at:.2f} s", None, None)
    if last is None:
        line = f"{sender} never asked for key {key}: it showed no entry for it (last heard at {last_heard:.2f} s)"
        sends = asked.sends_to(sender)
        told = f"; ts {sends[0].ts} was sent to it at {sends[0].t:.2f} s" if sends else ""
        return Verdict(sender, "never_asked", line + told, last_heard, None)
    if last.holds and (key, last.ts, last.robot) in asked.refused:
        reasons = sorted({d.reason for d in trace.decisions if d.entry == (key, last.ts, last.robot)})
        return Verdict(sender, "refused", f"{sender} was refused by the guard ({', '.join(reasons)}): it shows ts "
                       f"{last.ts}, which the gateway never took", last_heard, last)
    if newest is None or (last.holds and last.entry == newest.entry):
        line = f"{sender} holds the newest write" + (f" (ts {newest.ts} by robot {newest.robot})" if newest else "")
        return Verdict(sender, None, line + f", shown at {last.t:.2f} s: no cause", last_heard, last)
    if last.holds and last.ts == newest.ts:
        return Verdict(sender, "conflict_lost", f"{sender} lost the conflict to robot {newest.robot}'s write (same "
                       f"timestamp {newest.ts}, higher id)", last_heard, last)
    return _not_reached(asked, newest, sender, mine, last_heard)


def _not_reached(asked: _Asked, newest: Shown, sender: str, mine: list[Shown], last_heard: float) -> Verdict:
    trace, last = asked.trace, mine[-1]
    held = f"ts {last.ts}" if last.holds else "no entry"
    sends = asked.sends_to(sender)
    links = sorted(trace.links_of(sender))
    if not sends:
        where = ", ".join(links)
        full = [d for d in trace.decisions if d.link in links and d.reason in _FULL_OUTLET and d.count
                and newest.t - _NEAR <= d.t <= asked.at]
        if full:
            why = "tx_overflow" if any(d.reason == "tx_overflow" for d in full) else \
                f"up to {max(d.count for d in full)} messages waiting, the device taking none"
            line = f"never sent on {where} (the gateway's queue for it was full: {why})"
        elif not any(s.sent for s in asked.shown) and not any(d.link in links for d in trace.decisions):
            line = f"never sent on {where} (the capture holds nothing the gateway sent there: bridge --record)"
        else:
            line = f"never sent on {where}"
        return Verdict(sender, "never_sent", f"{line}; {sender} shows {held}", last_heard, last)
    first = sends[0]
    if last_heard < first.t:
        return Verdict(sender, "not_heard_since", f"sent {len(sends)} times from {first.t:.2f} s; {sender} not heard "
                       f"since {last_heard:.2f} s", last_heard, last)
    before = [s for s in mine if s.t < first.t]
    after = [s for s in mine if s.t >= first.t]
    if not after:  # heard since, but not about this key: nothing says whether it took the write yet
        return Verdict(sender, "not_shown_since", f"sent {len(sends)} times from {first.t:.2f} s; {sender} has not "
                       f"shown key {asked.key} since (it showed {held} at {last.t:.2f} s)", last_heard, last)
    moved = before and any(s.holds and (not before[-1].holds or newer_entry(s.entry, before[-1].entry))
                           for s in after)
    if moved:
        return Verdict(sender, "behind", f"{sender} is behind: it shows {held} while ts {newest.ts} was sent to it "
                       f"at {first.t:.2f} s", last_heard, last)
    return Verdict(sender, "deaf", f"sent {len(sends)} times, never shown back ({sender}'s radio deaf since "
                   f"{first.t:.2f} s: it still shows {held})", last_heard, last)
