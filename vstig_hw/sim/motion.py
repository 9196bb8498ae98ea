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
from .jit import compiled
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
    number, so the compiled step (`_move`) reads as the vector algebra it does.
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
        self._column_x, self._column_y = self._columns.x, self._columns.y  # once: every step reads them
        # Line of sight needs pairs within R + body radius, a bump check pairs that one stride each can join.
        self._reach = max(radio_range + body_radius, 2 * body_radius + 2 * dispersion.stride) + _SKIN
        self._z = _complex(arena.place(robots, rng, body_radius))
        self._heading = np.exp(1j * rng.uniform(0.0, 2 * math.pi, robots))
        self._drift = 0.0  # how far the farthest robot is from where the pairs were listed
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
        self._listed_at, self._drift = self._z, 0.0
        self._near = near_pairs(self.positions, self._reach)
        a, b = self._near
        ordered = a < b
        self._pairs = (a[ordered], b[ordered])

    def _sense(self) -> None:
        if self._drift > _SKIN / 2:
            self._list_pairs()
        self.hearing: Links = links(self.positions, self.radio_range, self.body_radius, self.occlusion,
                                    self._columns, self._near)

    def step(self) -> None:
        """One control step of motion for every robot, then the new hearing graph."""
        robots, rng = len(self._z), self._rng
        turns = rng.normal(0.0, self.dispersion.turn_noise, robots)
        bumps = rng.uniform(0.0, 2 * math.pi, robots)  # a new heading, for the robots whose move is refused
        self._z, self._heading, self._drift = _move(
            self._z, self._heading, self.hearing.src, self.hearing.dst, self._pairs[0], self._pairs[1], turns, bumps,
            self._listed_at, self.arena.side / 2 - self.body_radius, self._column_x, self._column_y,
            self._columns.radius, self.body_radius, self.dispersion.repulsion, self.dispersion.stride)
        self._sense()


@compiled
def _move(z: NDArray[np.complex128], heading: NDArray[np.complex128], src: Index, dst: Index, pair_a: Index,
          pair_b: Index, turns: NDArray[np.float64], bumps: NDArray[np.float64], listed_at: NDArray[np.complex128],
          half: float, column_x: NDArray[np.float64], column_y: NDArray[np.float64], column_radius: float, rho: float,
          repulsion: float, stride: float) -> tuple[NDArray[np.complex128], NDArray[np.complex128], float]:
    """Every robot's move: (new positions, new headings, the farthest any robot now is from `listed_at`).

    `half` bounds a body's centre on each axis (the walls), `src`/`dst` are the
    links sensed now, `pair_a`/`pair_b` every pair that one stride each can bring
    into contact, `turns` each robot's random turn and `bumps` the heading it
    takes if its move is refused.
    """
    robots = len(z)
    scale, reach = repulsion * repulsion, 2 * repulsion  # no push beyond a gap of twice `repulsion`
    push = np.zeros(robots, np.complex128)
    for link in range(len(src)):
        robot = src[link]
        away = z[robot] - z[dst[link]]
        dist = abs(away)
        gap = max(dist - 2 * rho, _MIN_GAP)
        if gap <= reach:
            push[robot] += away * (scale / (gap * gap * dist))
    columns = column_x + 1j * column_y
    wanted = np.empty(robots, np.complex128)
    new_heading = np.empty(robots, np.complex128)
    moved = np.empty(robots, np.bool_)
    for robot in range(robots):
        here = z[robot]
        field = push[robot] + _wall_push(here.real, half, scale, reach) + 1j * _wall_push(here.imag, half, scale, reach)
        for column in columns:
            away = here - column
            dist = abs(away)
            gap = max(dist - column_radius - rho, _MIN_GAP)
            if gap <= reach:
                field += away * (scale / (gap * gap * dist))
        drive = heading[robot] + field
        size = abs(drive)
        towards = (drive / size if size > 0 else heading[robot]) * np.exp(1j * turns[robot])
        new_heading[robot] = towards
        wanted[robot] = step_to = here + stride * min(1.0, size) * towards
        fits = abs(step_to.real) <= half and abs(step_to.imag) <= half
        for column in columns:
            fits = fits and abs(step_to - column) >= column_radius + rho
        moved[robot] = fits
    _refuse_clashes(z, wanted, moved, pair_a, pair_b, 2 * rho)
    drift = 0.0
    for robot in range(robots):
        if not moved[robot]:  # a bump: stay, and turn to a random heading
            wanted[robot] = z[robot]
            new_heading[robot] = np.exp(1j * bumps[robot])
        drift = max(drift, abs(wanted[robot] - listed_at[robot]))
    return wanted, new_heading, drift


@compiled
def _wall_push(coordinate: float, half: float, scale: float, reach: float) -> float:
    """On one axis: the wall behind pushes forward, the wall ahead pushes back."""
    behind, ahead = max(half + coordinate, _MIN_GAP), max(half - coordinate, _MIN_GAP)
    return (scale / behind**2 if behind <= reach else 0.0) - (scale / ahead**2 if ahead <= reach else 0.0)


@compiled
def _refuse_clashes(z: NDArray[np.complex128], wanted: NDArray[np.complex128], moved: NDArray[np.bool_],
                    pair_a: Index, pair_b: Index, contact: float) -> None:
    """Refuse (in `moved`) every move that would bring two bodies closer than `contact`, moved or not.

    A refused move leaves its robot where it was, which may refuse a move beside
    it in turn; the loop ends because refusing every move gives back the
    current, overlap-free layout.
    """
    clashing = np.zeros(len(z), np.bool_)
    while True:
        for pair in range(len(pair_a)):
            a, b = pair_a[pair], pair_b[pair]
            at_a = wanted[a] if moved[a] else z[a]
            at_b = wanted[b] if moved[b] else z[b]
            if abs(at_a - at_b) < contact:
                if not (moved[a] or moved[b]):  # two bodies that did not move overlap: the layout was broken before
                    raise RuntimeError("bodies overlap in the current layout")
                clashing[a] = clashing[b] = True
        if not clashing.any():
            return
        for robot in range(len(z)):
            if clashing[robot]:
                moved[robot] = clashing[robot] = False


def _complex(xy: NDArray[np.float64]) -> NDArray[np.complex128]:
    """(N, 2) -> N complex numbers x + iy."""
    z: NDArray[np.complex128] = np.ascontiguousarray(xy, dtype=np.float64).view(np.complex128)[:, 0]
    return z
