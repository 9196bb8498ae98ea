"""The paper's three layouts (section 4.1) and the line-of-sight radio built on them."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vstig_hw.sim import BODY_RADIUS, DENSITY, RANGE, arena_side, links
from vstig_hw.sim.radio import Discs
from vstig_hw.sim.topology import cluster, line, scale_free


def _min_gap(positions: np.ndarray) -> float:
    diff = positions[:, None, :] - positions[None, :, :]
    dist = np.sqrt(np.sum(diff**2, axis=2))
    np.fill_diagonal(dist, np.inf)
    return float(dist.min())


@pytest.mark.parametrize("robots", [10, 100, 1000])
def test_cluster_arena_keeps_density_five(robots: int) -> None:
    side = arena_side(robots)
    assert robots * math.pi * RANGE**2 / side**2 == pytest.approx(DENSITY)
    positions = cluster(robots, np.random.default_rng(robots))
    assert positions.shape == (robots, 2)
    assert np.all(np.abs(positions) <= side / 2)
    assert _min_gap(positions) >= 2 * BODY_RADIUS  # overlapping draws were re-drawn


def test_cluster_interior_robots_hear_about_d_neighbours() -> None:
    # A robot at least R from the border has (N-1) * pi R^2 / L^2 ~= D robots in range on average.
    robots = 1000
    positions = cluster(robots, np.random.default_rng(3))
    degrees = links(positions, occlusion=False).degrees()
    interior = np.all(np.abs(positions) <= arena_side(robots) / 2 - RANGE, axis=1)
    assert interior.sum() > 500
    assert 4.5 <= degrees[interior].mean() <= 5.5
    # Bodies block a few links but not many in so sparse a cluster.
    occluded = links(positions).degrees()
    assert np.all(occluded <= degrees) and occluded.mean() > 0.9 * degrees.mean()


def test_line_is_robot_i_at_i_i_with_exactly_two_neighbours() -> None:
    positions = line(50, np.random.default_rng(0))
    assert positions.tolist() == [[i, i] for i in range(1, 51)]
    degrees = links(positions).degrees().tolist()
    assert degrees == [1] + [2] * 48 + [1]  # the paper's "exactly two neighbours"
    # Without line of sight the robot two places away (2.83 m) is in range too.
    assert links(positions, occlusion=False).degrees().tolist() == [2, 3] + [4] * 46 + [3, 2]


def test_a_body_on_the_line_of_sight_blocks_it() -> None:
    blocked = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    assert links(blocked).degrees().tolist() == [1, 2, 1]
    aside = blocked.copy()
    aside[1, 1] = BODY_RADIUS * 1.01  # the middle body no longer touches the segment
    assert links(aside).degrees().tolist() == [2, 2, 2]
    grazing = blocked.copy()
    grazing[1, 1] = BODY_RADIUS * 0.99
    assert links(grazing).degrees().tolist() == [1, 2, 1]


def test_scale_free_robots_attach_within_range_and_the_rich_get_richer() -> None:
    robots = 400
    positions = scale_free(robots, np.random.default_rng(5))
    assert positions[0].tolist() == [0.0, 0.0]
    assert _min_gap(positions) >= 2 * BODY_RADIUS
    for i in range(1, robots):  # every robot landed within range of an earlier one: its pivot
        assert np.min(np.hypot(*(positions[:i] - positions[i]).T)) <= RANGE
    degrees = links(positions, occlusion=False).degrees()
    # Preferential attachment: early robots collect far more neighbours than late ones;
    # dense hubs sit beside thin tips (the paper's clusters joined by thin lines).
    assert degrees[: robots // 10].mean() > 1.5 * degrees[-robots // 10 :].mean()
    assert degrees.min() <= 10 and degrees.max() >= 10 * degrees.min()


def test_layouts_depend_only_on_the_seed() -> None:
    for generate in (cluster, scale_free):
        first = generate(100, np.random.default_rng(11))
        assert np.array_equal(first, generate(100, np.random.default_rng(11)))
        assert not np.array_equal(first, generate(100, np.random.default_rng(12)))


def _hears_by_definition(positions: list[tuple[float, float]], radio_range: float, blocker: float,
                         columns: list[tuple[float, float]], column_radius: float) -> set[tuple[int, int]]:
    """Who hears whom, straight from the model: every pair, every third body, every column."""

    def gap(p: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
        (px, py), (ax, ay), (bx, by) = p, a, b
        dx, dy = bx - ax, by - ay
        length_sq = dx * dx + dy * dy
        t = 0.0 if length_sq == 0 else min(1.0, max(0.0, ((px - ax) * dx + (py - ay) * dy) / length_sq))
        return math.hypot(px - ax - t * dx, py - ay - t * dy)

    heard = set()
    for a, pa in enumerate(positions):
        for b, pb in enumerate(positions):
            if a == b or math.dist(pa, pb) > radio_range:
                continue
            if any(gap(pc, pa, pb) < blocker for c, pc in enumerate(positions) if c not in (a, b)):
                continue
            if any(gap(centre, pa, pb) < column_radius for centre in columns):
                continue
            heard.add((a, b))
    return heard


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), robots=st.integers(1, 40), occlusion=st.booleans(),
       with_columns=st.booleans())
def test_the_hearing_graph_is_the_models_definition(seed: int, robots: int, occlusion: bool,
                                                     with_columns: bool) -> None:
    rng = np.random.default_rng(seed)
    side = rng.uniform(2.0, 12.0)
    positions = rng.uniform(-side / 2, side / 2, size=(robots, 2))
    columns = Discs(rng.uniform(-side / 2, side / 2, size=(3, 2)), side / 10) if with_columns else None
    heard = links(positions, RANGE, BODY_RADIUS, occlusion, columns)
    pairs = list(zip(heard.src.tolist(), heard.dst.tolist(), strict=True))
    assert pairs == sorted(pairs), "links are listed by sender, then receiver"
    expected = _hears_by_definition(
        [tuple(p) for p in positions.tolist()], RANGE, BODY_RADIUS if occlusion else 0.0,
        [tuple(c) for c in columns.centres.tolist()] if columns is not None and occlusion else [],
        columns.radius if columns is not None else 0.0)
    assert set(pairs) == expected
