"""Where the robots stand: the paper's three static topologies (section 4.1).

Each generator returns an (N, 2) array of positions in metres; robot i gets
robot id i, so the id order is the placement order (for the line, the highest
id sits at one end: the paper's worst case for spreading it).

* cluster: uniform in a square of side L = sqrt(N*pi*R^2/D), D = 5; a draw that
  overlaps an already placed body is re-drawn (the paper's footnote 3).
* line: robot i at (i, i) for i in 1..N, so neighbours are sqrt(2) m apart.
* scale-free: the first robot at the origin; each next robot picks a pivot with
  probability proportional to its degree (the number of robots within range)
  and lands uniformly in the disc of radius R around it, re-drawn on overlap.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "BODY_RADIUS",
    "DENSITY",
    "RANGE",
    "TOPOLOGIES",
    "Positions",
    "arena_side",
    "cluster",
    "line",
    "place_apart",
    "scale_free",
]

Positions = NDArray[np.float64]

RANGE = 3.0  # m: the marXbot range-and-bearing range the paper uses
DENSITY = 5.0  # the paper's D: total communication area / arena area
# The marXbot body (ARGoS calls it the foot-bot): radius 0.085 m. Bodies decide
# overlap when placing robots and block line of sight in the radio model.
BODY_RADIUS = 0.085

_MAX_REDRAWS = 10_000


def arena_side(robots: int, radio_range: float = RANGE, density: float = DENSITY) -> float:
    """L such that N*pi*R^2 / L^2 == D."""
    return math.sqrt(robots * math.pi * radio_range**2 / density)


Draw = Callable[[int, Positions], NDArray[np.float64]]


Placed = Callable[[int, Positions], None]


def place_apart(robots: int, draw: Draw, body_radius: float, placed: Placed | None = None) -> Positions:
    """Place robots one by one: `draw(i, so_far)` proposes robot i's spot, re-drawn while it overlaps a body."""
    positions = np.empty((robots, 2))
    min_gap_sq = (2 * body_radius) ** 2
    for i in range(robots):
        so_far = positions[:i]
        for _ in range(_MAX_REDRAWS):
            spot = draw(i, so_far)
            if i == 0 or np.min(np.sum((so_far - spot) ** 2, axis=1)) >= min_gap_sq:
                break
        else:
            raise ValueError(f"cannot place robot {i} without overlap after {_MAX_REDRAWS} draws: arena too dense")
        positions[i] = spot
        if placed is not None:
            placed(i, positions[: i + 1])
    return positions


def cluster(
    robots: int, rng: np.random.Generator, radio_range: float = RANGE, body_radius: float = BODY_RADIUS,
    density: float = DENSITY,
) -> Positions:
    half = arena_side(robots, radio_range, density) / 2
    return place_apart(robots, lambda _i, _so_far: rng.uniform(-half, half, size=2), body_radius)


def line(
    robots: int, rng: np.random.Generator, radio_range: float = RANGE, body_radius: float = BODY_RADIUS,
    density: float = DENSITY,
) -> Positions:
    steps = np.arange(1, robots + 1, dtype=np.float64)
    return np.column_stack([steps, steps])


def scale_free(
    robots: int, rng: np.random.Generator, radio_range: float = RANGE, body_radius: float = BODY_RADIUS,
    density: float = DENSITY,
) -> Positions:
    degree = np.zeros(robots)
    range_sq = radio_range**2

    def draw(i: int, so_far: Positions) -> NDArray[np.float64]:
        if i == 0:
            return np.zeros(2)
        weights = degree[:i]
        total = weights.sum()
        # Only while the first robot stands alone is every degree 0.
        pivot = 0 if total == 0 else int(rng.choice(i, p=weights / total))
        radius = radio_range * math.sqrt(rng.random())  # uniform over the disc's area
        angle = rng.uniform(0.0, 2 * math.pi)
        spot: NDArray[np.float64] = so_far[pivot] + radius * np.array([math.cos(angle), math.sin(angle)])
        return spot

    def placed(i: int, so_far: Positions) -> None:
        in_range = np.sum((so_far[:i] - so_far[i]) ** 2, axis=1) <= range_sq
        degree[:i] += in_range
        degree[i] = in_range.sum()

    return place_apart(robots, draw, body_radius, placed)


# Every generator takes (robots, rng, radio_range, body_radius, density); only the
# cluster's arena depends on the density, the other two are built by distance.
Generator = Callable[[int, np.random.Generator, float, float, float], Positions]
TOPOLOGIES: dict[str, Generator] = {"cluster": cluster, "line": line, "scale-free": scale_free}
