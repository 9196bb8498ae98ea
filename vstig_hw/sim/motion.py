"""Robots that diffuse through the arena: a simplified potential-field dispersion.

The paper's robots follow "a simplified version" of Howard, Mataric and
Sukhatme (2002): every robot is pushed away from the robots it senses and from
obstacles, with a magnitude that grows as the inverse square of the gap. Their
dispersion alone comes to rest once the robots are spread out, but at D = 1 a
spread-out swarm is a set of islands and the paper needs motion to carry data
between them, so here each robot also drives forward along its heading:

    u = heading + sum over sensed robots, walls and columns of (repulsion / gap)^2 * (unit vector away)
    heading <- direction of u, plus a small random turn (`turn_noise`)
    speed   =  S * min(1, |u|)   (the forward speed cap S; a robot facing a push slows down)

Sensed robots are those the range-and-bearing device reports: in range and in
line of sight (the hearing graph). Walls and columns are sensed within the same
range. Every robot moves at once, once per control step; a move that would put
its body into a wall, a column or another body is not made, and that robot
turns to a random heading instead (a bump). So bodies never overlap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .arena import Arena
from .radio import Index, Links, links, near_pairs
from .topology import Positions

__all__ = ["Dispersion", "MovingSwarm"]

_MIN_GAP = 1e-3  # m: caps the push of a touching body
# Candidate pairs are listed within reach + _SKIN and re-listed only once some robot
# has moved _SKIN / 2 (a Verlet list): every pair that matters is then still listed.
_SKIN = 0.5  # m


@dataclass(frozen=True)
class Dispersion:
    """How robots move: the paper's forward speed cap and control step, and the field's two knobs."""

    speed: float = 0.1  # m/s, the cap S
    control_step: float = 0.1  # s
    repulsion: float = 0.5  # m: the gap at which a push equals the forward drive
    turn_noise: float = 0.05  # rad, standard deviation of the random turn per control step

    @property
    def stride(self) -> float:
        """The farthest a robot moves in one control step."""
        return self.speed * self.control_step


class MovingSwarm:
    """Positions and headings of N robots in an arena; `hearing` is who hears whom right now."""

    def __init__(self, arena: Arena, robots: int, rng: np.random.Generator, radio_range: float, body_radius: float,
                 occlusion: bool, dispersion: Dispersion) -> None:
        self.arena = arena
        self.radio_range = radio_range
        self.body_radius = body_radius
        self.occlusion = occlusion
        self.dispersion = dispersion
        self._rng = rng
        self._columns = arena.columns
        # Line of sight needs pairs within R + body radius, a bump check pairs that one stride each can join.
        self._reach = max(radio_range + body_radius, 2 * body_radius + 2 * dispersion.stride) + _SKIN
        self.positions = arena.place(robots, rng, body_radius)
        self.headings = rng.uniform(0.0, 2 * math.pi, robots)
        self._listed_at = self.positions
        self._near = near_pairs(self.positions, self._reach)
        self._sense()

    def _sense(self) -> None:
        drift = self.positions - self._listed_at
        if np.max(np.einsum("ij,ij->i", drift, drift), initial=0.0) > (_SKIN / 2) ** 2:
            self._listed_at = self.positions
            self._near = near_pairs(self.positions, self._reach)
        self.hearing: Links = links(self.positions, self.radio_range, self.body_radius, self.occlusion,
                                    self._columns, self._near)

    def step(self) -> None:
        """One control step of motion for every robot, then the new hearing graph."""
        drive = np.column_stack([np.cos(self.headings), np.sin(self.headings)]) + self._push()
        pace = np.minimum(1.0, np.hypot(drive[:, 0], drive[:, 1]))
        turn = self._rng.normal(0.0, self.dispersion.turn_noise, len(self.headings))
        headings = np.arctan2(drive[:, 1], drive[:, 0]) + turn
        stride = self.dispersion.stride * pace
        wanted = self.positions + stride[:, None] * np.column_stack([np.cos(headings), np.sin(headings)])
        moved = self._allowed(wanted)
        bumped = ~moved
        headings[bumped] = self._rng.uniform(0.0, 2 * math.pi, int(bumped.sum()))
        self.headings = np.mod(headings, 2 * math.pi)
        self.positions = np.where(moved[:, None], wanted, self.positions)
        self._sense()

    def _push(self) -> NDArray[np.float64]:
        """The repulsive field on every robot, from the robots it senses, the walls and the columns."""
        p, rho, reach = self.positions, self.body_radius, self.radio_range
        scale = self.dispersion.repulsion**2
        push = np.zeros_like(p)
        src, dst = self.hearing.src, self.hearing.dst
        if len(src):
            away = p[src] - p[dst]
            dist = np.hypot(away[:, 0], away[:, 1])
            gap = np.maximum(dist - 2 * rho, _MIN_GAP)
            magnitude = scale / (gap * gap * dist)
            push[:, 0] += np.bincount(src, away[:, 0] * magnitude, len(p))
            push[:, 1] += np.bincount(src, away[:, 1] * magnitude, len(p))
        half = self.arena.side / 2 - rho
        for axis in (0, 1):  # the wall behind pushes forward, the wall ahead pushes back
            low = np.maximum(p[:, axis] + half, _MIN_GAP)
            high = np.maximum(half - p[:, axis], _MIN_GAP)
            push[:, axis] += np.where(low < reach, scale / (low * low), 0.0)
            push[:, axis] -= np.where(high < reach, scale / (high * high), 0.0)
        columns = self._columns
        rel = p[:, None, :] - columns.centres[None, :, :]
        dist = np.hypot(rel[:, :, 0], rel[:, :, 1])
        gap = np.maximum(dist - columns.radius - rho, _MIN_GAP)
        magnitude = np.where(gap < reach, scale / (gap * gap * dist), 0.0)
        push += np.einsum("nk,nkj->nj", magnitude, rel)
        return push

    def _allowed(self, wanted: Positions) -> NDArray[np.bool_]:
        """Which robots may make their move: into free space, and not into another body, moved or not.

        A refused move leaves its robot where it was, which may refuse a move
        beside it in turn; the loop ends because refusing every move gives back
        the current, overlap-free layout.
        """
        moved = self.arena.fits(wanted, self.body_radius)
        a, b = self._near
        ordered = a < b
        a, b = a[ordered], b[ordered]
        if not len(a):
            return moved
        contact_sq = (2 * self.body_radius) ** 2
        while True:
            where = np.where(moved[:, None], wanted, self.positions)
            gap = where[a] - where[b]
            clash = np.einsum("ij,ij->i", gap, gap) < contact_sq
            if not clash.any():
                return moved
            stop: Index = np.concatenate([a[clash], b[clash]])
            if not moved[stop].any():  # two bodies that did not move overlap: the layout was broken before
                raise RuntimeError("bodies overlap in the current layout")
            moved[stop] = False
