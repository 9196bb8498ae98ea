"""Robots that diffuse through the arena: a simplified potential-field dispersion.

The paper's robots follow "a simplified version" of Howard, Mataric and
Sukhatme (2002): every robot is pushed away from the robots it senses and from
obstacles, with a magnitude that grows as the inverse square of the gap. Their
dispersion alone comes to rest once the robots are spread out, but at D = 1 a
spread-out swarm is a set of islands and the paper needs motion to carry data
between them, so here each robot also drives forward along its heading:

    u = heading + sum over pushes of (repulsion / gap)^2 * (unit vector away)
    heading <- direction of u, plus a small random turn (`turn_noise`)
    speed   =  S * min(1, |u|)   (the forward speed cap S; a robot facing a push slows down)

A push comes from each wall, column and sensed robot (in range and in line of
sight: what the range-and-bearing device reports) whose gap is at most twice
`repulsion`. The cut-off matters: weak pushes from far away, added to the
heading step after step, would steer every robot into a loop inside the region
it started in (each region is a basin of the field), and nothing would diffuse.
Every robot moves at once, once per control step; a move that would put its
body into a wall, a column or another body is not made, and that robot turns
to a random heading instead (a bump). So bodies never overlap.
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
    repulsion: float = 0.5  # m: the gap at which a push equals the forward drive; none beyond twice this
    turn_noise: float = 0.05  # rad, standard deviation of the random turn per control step

    @property
    def stride(self) -> float:
        """The farthest a robot moves in one control step."""
        return self.speed * self.control_step


class MovingSwarm:
    """Positions and headings of N robots in an arena; `hearing` is who hears whom right now.

    Inside, a position is a complex number x + iy and a heading a unit complex
    number: one numpy call per operation instead of one per axis, which is most
    of the cost of a step for a hundred robots.
    """

    def __init__(self, arena: Arena, robots: int, rng: np.random.Generator, radio_range: float, body_radius: float,
                 occlusion: bool, dispersion: Dispersion) -> None:
        self.arena = arena
        self.radio_range = radio_range
        self.body_radius = body_radius
        self.occlusion = occlusion
        self.dispersion = dispersion
        self._rng = rng
        self._columns = arena.columns
        self._column_centres = _complex(self._columns.centres)
        # Line of sight needs pairs within R + body radius, a bump check pairs that one stride each can join.
        self._reach = max(radio_range + body_radius, 2 * body_radius + 2 * dispersion.stride) + _SKIN
        self._z = _complex(arena.place(robots, rng, body_radius))
        self._heading = np.exp(1j * rng.uniform(0.0, 2 * math.pi, robots))
        self._list_pairs()
        self._sense()

    @property
    def positions(self) -> Positions:
        """(N, 2) metres: a read-only view of the current positions."""
        view: Positions = self._z.view(np.float64).reshape(-1, 2)
        view.flags.writeable = False
        return view

    @property
    def headings(self) -> NDArray[np.float64]:
        """Radians."""
        angles: NDArray[np.float64] = np.angle(self._heading)
        return angles

    def _list_pairs(self) -> None:
        self._listed_at = self._z
        self._near = near_pairs(self.positions, self._reach)
        a, b = self._near
        ordered = a < b
        self._pairs = (a[ordered], b[ordered])

    def _sense(self) -> None:
        if np.max(np.abs(self._z - self._listed_at), initial=0.0) > _SKIN / 2:
            self._list_pairs()
        self.hearing: Links = links(self.positions, self.radio_range, self.body_radius, self.occlusion,
                                    self._columns, self._near)

    def step(self) -> None:
        """One control step of motion for every robot, then the new hearing graph."""
        z, rng = self._z, self._rng
        drive = self._heading + self._push()
        size = np.abs(drive)
        heading = np.divide(drive, size, out=self._heading.copy(), where=size > 0)
        heading *= np.exp(1j * rng.normal(0.0, self.dispersion.turn_noise, len(z)))
        wanted = z + (self.dispersion.stride * np.minimum(1.0, size)) * heading
        moved = self._allowed(wanted)
        bumped = np.flatnonzero(~moved)
        if len(bumped):
            heading[bumped] = np.exp(1j * rng.uniform(0.0, 2 * math.pi, len(bumped)))
        self._heading = heading
        self._z = np.where(moved, wanted, z)
        self._sense()

    def _push(self) -> NDArray[np.complex128]:
        """The repulsive field on every robot, from the robots it senses, the walls and the columns."""
        z, rho = self._z, self.body_radius
        scale = self.dispersion.repulsion**2
        reach = 2 * self.dispersion.repulsion  # the largest gap that pushes
        src, dst = self.hearing.src, self.hearing.dst
        away = z[src] - z[dst]
        dist = np.abs(away)
        gap = np.maximum(dist - 2 * rho, _MIN_GAP)
        close = np.flatnonzero(gap <= reach)
        if len(close):
            along = away[close] * (scale / (gap[close] ** 2 * dist[close]))
            push = np.bincount(src[close], along.real, len(z)) + 1j * np.bincount(src[close], along.imag, len(z))
        else:
            push = np.zeros(len(z), dtype=np.complex128)
        # Walls: the one behind pushes forward, the one ahead pushes back, on each axis.
        half = self.arena.side / 2 - rho
        xy = self.positions
        behind = np.maximum(half + xy, _MIN_GAP)
        ahead = np.maximum(half - xy, _MIN_GAP)
        walls = np.where(behind <= reach, scale / behind**2, 0.0) - np.where(ahead <= reach, scale / ahead**2, 0.0)
        push += _complex(walls)
        away = z[:, None] - self._column_centres[None, :]
        dist = np.abs(away)
        gap = np.maximum(dist - self._columns.radius - rho, _MIN_GAP)
        push += np.sum(away * np.where(gap <= reach, scale / (gap * gap * dist), 0.0), axis=1)
        return push

    def _allowed(self, wanted: NDArray[np.complex128]) -> NDArray[np.bool_]:
        """Which robots may make their move: into free space, and not into another body, moved or not.

        A refused move leaves its robot where it was, which may refuse a move
        beside it in turn; the loop ends because refusing every move gives back
        the current, overlap-free layout.
        """
        moved = self.arena.fits(wanted.view(np.float64).reshape(-1, 2), self.body_radius)
        a, b = self._pairs
        contact = 2 * self.body_radius
        while len(a):
            where = np.where(moved, wanted, self._z)
            clash = np.flatnonzero(np.abs(where[a] - where[b]) < contact)
            if not len(clash):
                break
            stop: Index = np.concatenate([a[clash], b[clash]])
            if not moved[stop].any():  # two bodies that did not move overlap: the layout was broken before
                raise RuntimeError("bodies overlap in the current layout")
            moved[stop] = False
        return moved


def _complex(xy: NDArray[np.float64]) -> NDArray[np.complex128]:
    """(N, 2) -> N complex numbers x + iy."""
    z: NDArray[np.complex128] = np.ascontiguousarray(xy, dtype=np.float64).view(np.complex128)[:, 0]
    return z
