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

__all__ = ["Links", "Radio", "links"]

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
    for start in range(0, len(positions), _CHUNK):
        block = positions[start:start + _CHUNK]
        dist_sq = np.sum((block[:, None, :] - positions[None, :, :]) ** 2, axis=2)
        a, b = np.nonzero(dist_sq <= reach_sq)
        keep = (a + start) != b
        rows.append(a[keep] + start)
        cols.append(b[keep])
    return np.concatenate(rows).astype(np.intp), np.concatenate(cols).astype(np.intp)


def _clear_pairs(positions: Positions, near_a: Index, near_c: Index, radio_range: float,
                 body_radius: float) -> tuple[Index, Index]:
    """Pairs a < b in range whose segment passes no closer than `body_radius` to a third robot.

    Robot by robot: any blocker of a->b lies within |ab| + body_radius of a, so
    the candidates are a's near robots, and the test is a |B| x |C| matrix of
    segment-to-centre distances (cheap even in a blob of hundreds).
    """
    bounds = np.searchsorted(near_a, np.arange(len(positions) + 1))
    out_a: list[Index] = []
    out_b: list[Index] = []
    range_sq, body_sq = radio_range**2, body_radius**2
    for a in range(len(positions)):
        near = near_c[bounds[a]:bounds[a + 1]]
        rel = positions[near] - positions[a]  # (C, 2)
        dist_sq = np.einsum("ij,ij->i", rel, rel)
        is_b = (near > a) & (dist_sq <= range_sq)
        if not is_b.any():
            continue
        rb, b_sq = rel[is_b], dist_sq[is_b]
        t = np.clip((rb @ rel.T) / b_sq[:, None], 0.0, 1.0)  # (B, C): where c projects on a->b
        gap_sq = dist_sq[None, :] - 2 * t * (rb @ rel.T) + t * t * b_sq[:, None]
        gap_sq[np.arange(len(rb)), np.flatnonzero(is_b)] = np.inf  # b does not block itself
        clear = ~(gap_sq < body_sq).any(axis=1)
        out_a.append(np.full(int(clear.sum()), a, dtype=np.intp))
        out_b.append(near[is_b][clear])
    if not out_a:
        return np.empty(0, dtype=np.intp), np.empty(0, dtype=np.intp)
    return np.concatenate(out_a), np.concatenate(out_b)


def links(
    positions: Positions, radio_range: float = RANGE, body_radius: float = BODY_RADIUS, occlusion: bool = True
) -> Links:
    """Who hears whom: in range, and (with `occlusion`) no other body on the line between."""
    near_a, near_c = _pairs_within(positions, radio_range + body_radius)
    if occlusion and body_radius > 0:
        a, b = _clear_pairs(positions, near_a, near_c, radio_range, body_radius)
        a, b = np.concatenate([a, b]), np.concatenate([b, a])  # line of sight is symmetric
    else:
        in_range = np.sum((positions[near_a] - positions[near_c]) ** 2, axis=1) <= radio_range**2
        a, b = near_a[in_range], near_c[in_range]
    order = np.lexsort((b, a))
    return Links(len(positions), a[order], b[order])


Receive = Callable[[Message], object]


class Radio:
    """Delivers one control step's broadcasts, each copy dropped independently with probability `drop`."""

    def __init__(self, hearing: Links, drop: float, rng: np.random.Generator) -> None:
        if not 0.0 <= drop <= 1.0:
            raise ValueError(f"drop probability must be in [0, 1], got {drop!r}")
        self.links = hearing
        self.drop = drop
        self._rng = rng
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
