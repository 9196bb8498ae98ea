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
from .jit import compiled
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


@compiled
def _gap_sq(dx: float, dy: float, length_sq: float, px: float, py: float) -> float:
    """Squared distance from point p to the segment from the origin to d (all relative to one end)."""
    t = (px * dx + py * dy) / length_sq if length_sq > 0.0 else 0.0
    t = min(max(t, 0.0), 1.0)  # where p projects on the segment
    ex, ey = px - t * dx, py - t * dy
    return ex * ex + ey * ey


@compiled
def _hearing(x: NDArray[np.float64], y: NDArray[np.float64], near_a: Index, near_c: Index, radio_range: float,
             block_radius: float, column_x: NDArray[np.float64], column_y: NDArray[np.float64],
             column_radius: float) -> tuple[Index, Index]:
    """Directed hearing links (src, dst), sorted by sender then receiver.

    A pair a < b of `near` hears each other when |ab| <= radio_range and the
    segment ab passes no closer than `block_radius` (0: no blocking) to a third
    robot, nor closer than `column_radius` to a column's centre. Any robot that
    blocks a->b lies within |ab| + block_radius of a, so a's near robots are the
    only candidates (`near` is a-major).
    """
    robots = len(x)
    starts = np.searchsorted(near_a, np.arange(robots + 1))
    range_sq, block_sq, column_sq = radio_range * radio_range, block_radius * block_radius, column_radius**2
    pair_a = np.empty(len(near_a), np.intp)
    pair_b = np.empty(len(near_a), np.intp)
    degree = np.zeros(robots, np.intp)
    pairs = 0
    for row in range(len(near_a)):
        a, b = near_a[row], near_c[row]
        if b <= a:
            continue
        dx, dy = x[b] - x[a], y[b] - y[a]
        length_sq = dx * dx + dy * dy
        if length_sq > range_sq:
            continue
        clear = True
        if block_sq > 0.0:
            for candidate in range(starts[a], starts[a + 1]):
                c = near_c[candidate]
                if c != b and _gap_sq(dx, dy, length_sq, x[c] - x[a], y[c] - y[a]) < block_sq:
                    clear = False
                    break
        for column in range(len(column_x)):
            if clear and _gap_sq(dx, dy, length_sq, column_x[column] - x[a], column_y[column] - y[a]) < column_sq:
                clear = False
        if clear:
            pair_a[pairs], pair_b[pairs] = a, b
            degree[a] += 1
            degree[b] += 1
            pairs += 1
    # Both directions of each pair, as rows per sender. The pairs come sorted by a, then b,
    # so a row fills with its lower receivers (as b) before its higher ones (as a): sorted.
    fill = np.zeros(robots + 1, np.intp)
    fill[1:] = np.cumsum(degree)
    src = np.empty(2 * pairs, np.intp)
    dst = np.empty(2 * pairs, np.intp)
    for pair in range(pairs):
        a, b = pair_a[pair], pair_b[pair]
        src[fill[a]], dst[fill[a]] = a, b
        fill[a] += 1
        src[fill[b]], dst[fill[b]] = b, a
        fill[b] += 1
    return src, dst


@dataclass(frozen=True)
class Discs:
    """Round obstacles (the motion arena's columns): they block line of sight."""

    centres: Positions
    radius: float

    @property
    def x(self) -> NDArray[np.float64]:
        return np.ascontiguousarray(self.centres[:, 0])

    @property
    def y(self) -> NDArray[np.float64]:
        return np.ascontiguousarray(self.centres[:, 1])


_NO_DISCS = Discs(np.zeros((0, 2)), 0.0)


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
    x, y = (np.ascontiguousarray(positions[:, axis]) for axis in (0, 1))
    block_radius = body_radius if occlusion else 0.0
    columns = obstacles if occlusion and obstacles is not None else _NO_DISCS
    src, dst = _hearing(x, y, near_a, near_c, radio_range, block_radius, columns.x, columns.y, columns.radius)
    return Links(len(positions), src, dst)


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
