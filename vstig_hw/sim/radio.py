"""The simulated broadcast radio: who hears whom, and which copies get dropped.

The model is the paper's range-and-bearing one (section 4): a broadcast reaches
every robot within range R *and in direct line of sight*; each robot drops each
message it could hear independently with probability P. Line of sight is what
ARGoS checks by casting a ray between the two devices: here a ray is blocked
when it passes within one body radius of a third robot's centre. That is why
the paper's line, robots sqrt(2) m apart with R = 3 m, gives "exactly two
neighbours" rather than four.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..wire import Message
from .topology import BODY_RADIUS, RANGE, Positions

__all__ = ["Discs", "Links", "Radio", "links", "near_pairs"]

Index = NDArray[np.intp]
_CHUNK = 512  # rows of the distance matrix computed at once: bounds memory for big swarms


@dataclass(frozen=True)
class Links:
    """Directed hearing links, sorted by sender then receiver (both directions of each pair)."""

    robots: int
    src: Index
    dst: Index

    def degrees(self) -> Index:
        return np.bincount(self.src, minlength=self.robots).astype(np.intp)

    def neighbours(self) -> list[list[int]]:
        out: list[list[int]] = [[] for _ in range(self.robots)]
        for s, d in zip(self.src.tolist(), self.dst.tolist(), strict=True):
            out[s].append(d)
        return out


def _pairs_within(positions: Positions, reach: float) -> tuple[Index, Index]:
    """All (a, b) with a != b and |ab| <= reach, a-major order."""
    rows: list[Index] = []
    cols: list[Index] = []
    reach_sq = reach * reach
    x, y = positions[:, 0], positions[:, 1]
    for start in range(0, len(positions), _CHUNK):
        dx = x[start:start + _CHUNK, None] - x[None, :]
        dy = y[start:start + _CHUNK, None] - y[None, :]
        a, b = np.nonzero(dx * dx + dy * dy <= reach_sq)
        keep = (a + start) != b
        rows.append(a[keep] + start)
        cols.append(b[keep])
    return np.concatenate(rows).astype(np.intp), np.concatenate(cols).astype(np.intp)


def _clear_pairs(positions: Positions, near_a: Index, near_c: Index, radio_range: float,
                 body_radius: float) -> tuple[Index, Index]:
    """Pairs a < b in range whose segment passes no closer than `body_radius` to a third robot.

    Any blocker of a->b lies within |ab| + body_radius of a, so the candidates
    for pair (a, b) are a's near robots: one flat array of (pair, candidate)
    rows, built in chunks of pairs so memory stays bounded in dense swarms.
    """
    rel = positions[near_c] - positions[near_a]
    rel_x, rel_y = rel[:, 0].copy(), rel[:, 1].copy()
    rel_sq = rel_x * rel_x + rel_y * rel_y
    pair_rows = np.flatnonzero((near_a < near_c) & (rel_sq <= radio_range**2))  # the pairs a < b in range
    starts = np.searchsorted(near_a, np.arange(len(positions) + 1))
    fan_out = np.diff(starts)[near_a[pair_rows]]  # candidates of each pair: a's near robots
    ends = np.cumsum(fan_out)
    body_sq = body_radius**2
    blocked = np.zeros(len(pair_rows), dtype=bool)
    first = 0
    while first < len(pair_rows):
        done = ends[first - 1] if first else 0
        last = max(first + 1, int(np.searchsorted(ends, done + _CHUNK * _CHUNK, side="right")))
        rows, counts = pair_rows[first:last], fan_out[first:last]
        pair = np.repeat(np.arange(len(rows)), counts)
        cand = np.arange(len(pair)) + np.repeat(starts[near_a[rows]] - (ends[first:last] - counts - done), counts)
        bx, by, b_sq = rel_x[rows][pair], rel_y[rows][pair], rel_sq[rows][pair]
        dot = bx * rel_x[cand] + by * rel_y[cand]
        t = np.clip(dot / b_sq, 0.0, 1.0)  # where c projects on a->b
        gap_sq = rel_sq[cand] - 2 * t * dot + t * t * b_sq
        hit = (gap_sq < body_sq) & (cand != rows[pair])  # b does not block itself
        blocked[first:last] = np.bincount(pair[hit], minlength=len(rows)) > 0
        first = last
    clear = pair_rows[~blocked]
    return near_a[clear], near_c[clear]


def _segments_clear_of_discs(start: Positions, end: Positions, centres: Positions, radius: float) -> NDArray[np.bool_]:
    """For each segment start->end, True when it keeps at least `radius` from every centre."""
    s, e, c = (np.ascontiguousarray(xy).view(np.complex128) for xy in (start, end, centres))  # x + iy: (P, 1), (K, 1)
    seg = e - s
    rel = c.T - s  # (P, K): each centre seen from each segment's start
    t = np.clip((rel * seg.conj()).real / np.maximum((seg * seg.conj()).real, 1e-300), 0.0, 1.0)
    clear: NDArray[np.bool_] = np.all(np.abs(rel - t * seg) >= radius, axis=1)
    return clear


@dataclass(frozen=True)
class Discs:
    """Round obstacles (the motion arena's columns): they block line of sight."""

    centres: Positions
    radius: float


def near_pairs(positions: Positions, reach: float) -> tuple[Index, Index]:
    """All (a, b) with a != b and |ab| <= reach, a-major order: the candidates every other test starts from."""
    return _pairs_within(positions, reach)


def links(
    positions: Positions, radio_range: float = RANGE, body_radius: float = BODY_RADIUS, occlusion: bool = True,
    obstacles: Discs | None = None, near: tuple[Index, Index] | None = None,
) -> Links:
    """Who hears whom: in range, and (with `occlusion`) no other body, nor any of `obstacles`, on the line between.

    `near` may pass `near_pairs(positions, reach)` for any reach >= radio_range + body_radius,
    when the caller needs those pairs too.
    """
    near_a, near_c = near if near is not None else _pairs_within(positions, radio_range + body_radius)
    if occlusion and body_radius > 0:
        a, b = _clear_pairs(positions, near_a, near_c, radio_range, body_radius)
    else:
        keep = (near_a < near_c) & (np.sum((positions[near_a] - positions[near_c]) ** 2, axis=1) <= radio_range**2)
        a, b = near_a[keep], near_c[keep]
    if occlusion and obstacles is not None and len(a):
        sight = _segments_clear_of_discs(positions[a], positions[b], obstacles.centres, obstacles.radius)
        a, b = a[sight], b[sight]
    a, b = np.concatenate([a, b]), np.concatenate([b, a])  # hearing is symmetric
    order = np.argsort(a * len(positions) + b)  # by sender, then receiver
    return Links(len(positions), a[order], b[order])


Receive = Callable[[Message], object]


class Radio:
    """Delivers one control step's broadcasts, each copy dropped independently with probability `drop`."""

    def __init__(self, hearing: Links, drop: float, rng: np.random.Generator) -> None:
        if not 0.0 <= drop <= 1.0:
            raise ValueError(f"drop probability must be in [0, 1], got {drop!r}")
        self.drop = drop
        self._rng = rng
        self.hear(hearing)

    def hear(self, hearing: Links) -> None:
        """From now on, deliver over `hearing` (robots that move change who hears whom)."""
        self.links = hearing
        self._src_list = hearing.src.tolist()
        self._dst_list = hearing.dst.tolist()

    def deliver(self, outgoing: Sequence[Sequence[Message]], receive: Sequence[Receive]) -> int:
        """Hand every surviving copy to its receiver; returns how many were delivered.

        `outgoing[s]` is what robot s broadcast. Copies go out slot by slot (every
        robot's first message, then every second one...), each receiver in sender
        order, so a run depends only on its seed.
        """
        src, dst = self.links.src, self.links.dst
        counts = np.fromiter(map(len, outgoing), dtype=np.intp, count=len(outgoing))
        delivered = 0
        for slot in range(int(counts.max(initial=0))):
            sending = counts > slot
            if sending.all():
                if self.drop == 0.0:
                    senders, receivers = self._src_list, self._dst_list
                else:
                    kept = self._rng.random(len(src)) >= self.drop
                    senders, receivers = src[kept].tolist(), dst[kept].tolist()
            else:
                candidates = np.flatnonzero(sending[src])
                if self.drop != 0.0:
                    candidates = candidates[self._rng.random(len(candidates)) >= self.drop]
                senders, receivers = src[candidates].tolist(), dst[candidates].tolist()
            for s, r in zip(senders, receivers, strict=True):
                receive[r](outgoing[s][slot])
            delivered += len(senders)
        return delivered
