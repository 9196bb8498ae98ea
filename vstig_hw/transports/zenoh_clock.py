"""Clock round trips between Zenoh sessions, over the session a link already has (vstig_hw.clocks does the
arithmetic).

Every session answers queries on `vstig/<swarm>/clock/<CLOCK_ID>` with its wall clock (nanoseconds, decimal
text), and asks `vstig/<swarm>/clock/*` every PROBE_EVERY_S from the transport's read thread; replies are
measured on Zenoh's thread as they come. Nothing here touches the swarm's samples: the clock keys are outside
the stigmergies' `vstig/<swarm>/<n>/*` (firmware_spec/SPEC.md, "Zenoh").

Who answered: a reply names the session that sent it; where that session is connected to ours over links whose
TLS certificate names it (mutual TLS, or the TLS listener we connected to: a certificate our CA signed), the
round trip keeps that name as its proof. Any other answer (an open link, a session beyond a router) is
unproved: there any peer can answer under any clock id. Both are kept, marked (capture.clock_notes), and
`analyze` uses unproved ones only when told (DECISIONS.md, "Clocks by round trips over Zenoh").

Bounded whatever peers answer: an answer that is not a clock id of 16 hex digits and a time of at most 19
digits is counted (`clock_malformed`), so are a second answer for one clock in one round (`clock_repeated`) and
answers from clocks beyond the MAX_PEERS tracked (`clock_peers_over`): a capture gets at most MAX_PEERS offset
lines a round, the metrics page two series per tracked clock.
"""

from __future__ import annotations

import collections
import re
import threading
import time
from typing import Any
from urllib.parse import quote

import zenoh

from ..clocks import CLOCK_ID, CLOCK_ID_LENGTH, MAX_PROOF_CHARS, ClockOffset, OffsetFilter, measure
from ..counters import Counters

__all__ = ["PROBE_EVERY_S", "ZenohClock", "peer_time"]

PROBE_EVERY_S = 2.0  # a round trip to every peer this often: a few dozen bytes each
_REPLY_WAIT_S = 1.0  # a reply later than this bounds nothing useful
_KEPT = 256  # measurements waiting for `take` (a recorder takes them every tick)
_MAX_TIME_DIGITS = 19  # nanoseconds since 1970 fit 19 digits until the year 2286; more is no clock's answer
_CLOCK_ID = re.compile(f"[0-9a-f]{{{CLOCK_ID_LENGTH}}}")

_Heard = set[tuple[str, str | None]]  # the clocks (and proofs) one round has measured


def peer_time(payload: bytes) -> float | None:
    """The seconds a clock's answer says (decimal nanoseconds), or None if it is no clock's answer."""
    if not 0 < len(payload) <= _MAX_TIME_DIGITS or not payload.isdigit():
        return None
    return int(payload) / 1e9


def _proof_name(auth: str | None) -> str | None:
    """A certificate's name as captures and labels keep it: percent-encoded (no space or line break), bounded."""
    return None if not auth else quote(auth, safe="@:+")[:MAX_PROOF_CHARS]


class ZenohClock:
    def __init__(self, prefix: str) -> None:
        self.prefix = prefix  # vstig/<swarm>/clock
        self.filter = OffsetFilter()
        self.counters = Counters()  # the transport's, once attached
        self._queryable: Any = None
        self._link_events: Any = None
        self._next_probe = 0.0
        self._lock = threading.Lock()  # replies and link events come on Zenoh's threads
        self._new: collections.deque[ClockOffset] = collections.deque(maxlen=_KEPT)
        self._links: dict[str, dict[tuple[str, str], str | None]] = {}  # session id -> its links' certificate names

    def attach(self, session: zenoh.Session, counters: Counters) -> None:
        """Answer for this process's clock on `session`, and follow which sessions connected to it a certificate
        names; what is refused is counted in `counters`."""
        key = f"{self.prefix}/{CLOCK_ID}"
        self.counters = counters

        def answer(query: zenoh.Query) -> None:  # under our own key: the asker learns whose clock it read
            query.reply(key, str(time.time_ns()))

        with self._lock:
            self._links.clear()
        self._link_events = session.info.declare_link_events_listener(self._link_event, history=True)
        self._queryable = session.declare_queryable(key, answer)

    def _link_event(self, event: zenoh.LinkEvent) -> None:
        link = event.link
        zid, path = str(link.zid), (link.src, link.dst)
        with self._lock:
            links = self._links.setdefault(zid, {})
            if event.kind == zenoh.SampleKind.PUT:
                links[path] = _proof_name(link.auth_identifier)
            else:
                links.pop(path, None)
                if not links:
                    del self._links[zid]

    def _proof(self, replier: zenoh.EntityGlobalId | None) -> str | None:
        """The certificate name every link of the replying session carries, if it is connected to ours."""
        names = set(self._links.get(str(replier.zid), {}).values()) if replier is not None else set()
        return names.pop() if len(names) == 1 and None not in names else None

    def probe(self, session: zenoh.Session) -> None:
        """Ask every peer for its time, if a round is due; on the transport's read thread."""
        now = time.monotonic()
        if now < self._next_probe:
            return
        self._next_probe = now + PROBE_EVERY_S
        sent, heard = time.time(), _Heard()
        try:
            # Every reply, not Zenoh's latest per key: a forger's answer under a peer's id must not hide the peer's.
            session.get(f"{self.prefix}/*", lambda reply: self._reply(reply, sent, heard), timeout=_REPLY_WAIT_S,
                        consolidation=zenoh.ConsolidationMode.NONE)
        except zenoh.ZError:  # the session is closing: the next round asks again
            return

    def _reply(self, reply: zenoh.Reply, sent: float, heard: _Heard) -> None:
        received = time.time()
        sample = reply.ok
        peer = "" if sample is None else str(sample.key_expr).rsplit("/", 1)[-1]
        if peer == CLOCK_ID:  # our own answer (another link of this process)
            return
        said = None
        if sample is not None and len(sample.payload) <= _MAX_TIME_DIGITS and _CLOCK_ID.fullmatch(peer):
            said = peer_time(sample.payload.to_bytes())
        if said is None or received < sent:  # not a clock's answer, or our clock stepped back meanwhile
            self.counters["clock_malformed"] += 1
            return
        with self._lock:
            trip = measure(peer, sent, said, received, self._proof(reply.replier_id))
            if (peer, trip.proof) in heard:
                self.counters["clock_repeated"] += 1
            elif self.filter.add(trip) is None:
                self.counters["clock_peers_over"] += 1
            else:
                heard.add((peer, trip.proof))
                self._new.append(trip)

    def estimates(self) -> list[ClockOffset]:
        """Each peer's offset now (the tightest of its recent round trips), its proved and unproved apart."""
        with self._lock:
            return self.filter.estimates()

    def take(self) -> list[ClockOffset]:
        """The round trips measured since the last call."""
        with self._lock:
            new = list(self._new)
            self._new.clear()
        return new
