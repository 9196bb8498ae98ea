"""The arena of the paper's motion experiments (section 4.2): a walled square with 4 columns.

Four identical columns of radius L/10 stand at the inner corners of a 3 x 3
grid, (±L/6, ±L/6), dividing the square into 9 regions (the paper's Figure 4).
Density is counted over the walkable area:

    D = N*pi*R^2 / (L^2 - 4*pi*(L/10)^2)   =>   L = sqrt(N*pi*R^2 / (D * (1 - 4*pi/100)))
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from .radio import Discs
from .topology import BODY_RADIUS, RANGE, Positions, place_apart

__all__ = ["COLUMNS", "Arena", "motion_arena_side"]

COLUMNS = 4
_WALKABLE_FRACTION = 1 - COLUMNS * math.pi / 100  # columns of radius L/10 take 4*pi*L^2/100
_MAX_DRAWS = 100_000


def motion_arena_side(robots: int, radio_range: float = RANGE, density: float = 5.0) -> float:
    """L such that N*pi*R^2 / walkable area == D."""
    return math.sqrt(robots * math.pi * radio_range**2 / (density * _WALKABLE_FRACTION))


@dataclass(frozen=True)
class Arena:
    """A square of side `side` centred on the origin, walls on its border, and its columns."""

    side: float

    @classmethod
    def for_density(cls, robots: int, radio_range: float, density: float) -> Arena:
        return cls(motion_arena_side(robots, radio_range, density))

    @cached_property
    def columns(self) -> Discs:
        offset = self.side / 6
        centres = np.array([[-offset, -offset], [offset, -offset], [-offset, offset], [offset, offset]])
        return Discs(centres, self.side / 10)

    @property
    def walkable_area(self) -> float:
        return self.side**2 * _WALKABLE_FRACTION

    def fits(self, positions: Positions, body_radius: float) -> NDArray[np.bool_]:
        """For each centre, True when a body there touches neither a wall nor a column."""
        inside = np.all(np.abs(positions) <= self.side / 2 - body_radius, axis=1)
        columns = self.columns
        dx = positions[:, 0, None] - columns.centres[None, :, 0]
        dy = positions[:, 1, None] - columns.centres[None, :, 1]
        clear = np.all(dx * dx + dy * dy >= (columns.radius + body_radius) ** 2, axis=1)
        fits: NDArray[np.bool_] = inside & clear
        return fits

    def place(self, robots: int, rng: np.random.Generator, body_radius: float = BODY_RADIUS) -> Positions:
        """Uniform over the walkable area, no body overlapping a wall, a column or another body."""
        half = self.side / 2 - body_radius
        if half <= 0:
            raise ValueError(f"an arena of side {self.side:.3g} m cannot hold a body of radius {body_radius} m")

        def draw(_i: int, _so_far: Positions) -> NDArray[np.float64]:
            for _ in range(_MAX_DRAWS):
                spot = rng.uniform(-half, half, size=(1, 2))
                if self.fits(spot, body_radius)[0]:
                    found: NDArray[np.float64] = spot[0]
                    return found
            raise ValueError(f"no room for a body of radius {body_radius} m between the columns")

        return place_apart(robots, draw, body_radius)
