"""Section 4.2 in the simulator: the 4-column arena, dispersion motion, and the paper's statements on small runs."""

from __future__ import annotations

import math
import statistics

import numpy as np
import pytest

from vstig_hw.sim import Config, run_many, run_once, seed_for
from vstig_hw.sim.arena import Arena, motion_arena_side
from vstig_hw.sim.experiment import motion_at, moving_swarm
from vstig_hw.sim.graph import component_labels
from vstig_hw.sim.motion import Dispersion, MovingSwarm
from vstig_hw.sim.radio import Discs, links
from vstig_hw.sim.topology import BODY_RADIUS, RANGE


def _min_gap(positions: np.ndarray) -> float:
    diff = positions[:, None, :] - positions[None, :, :]
    dist = np.sqrt(np.sum(diff**2, axis=2))
    np.fill_diagonal(dist, np.inf)
    return float(dist.min())


def _medians(config: Config, runs: int, **changes: float) -> float:
    from dataclasses import replace

    results = run_many(replace(config, **changes), runs=runs, seed=3, workers=1)  # type: ignore[arg-type]
    steps = [r.steps for r in results]
    assert None not in steps, f"a run did not converge: {steps}"
    return float(statistics.median(s for s in steps if s is not None))


@pytest.mark.parametrize("density", [1.0, 3.0, 5.0])
def test_arena_side_keeps_the_density_over_the_walkable_area(density: float) -> None:
    arena = Arena.for_density(100, RANGE, density)
    assert arena.walkable_area == pytest.approx(arena.side**2 - 4 * math.pi * (arena.side / 10) ** 2)
    assert 100 * math.pi * RANGE**2 / arena.walkable_area == pytest.approx(density)
    columns = arena.columns
    assert columns.radius == pytest.approx(arena.side / 10)
    # Four columns at the inner corners of a 3 x 3 grid of regions.
    assert sorted(map(tuple, np.round(columns.centres / (arena.side / 6)).astype(int).tolist())) == [
        (-1, -1), (-1, 1), (1, -1), (1, 1)]
    assert motion_arena_side(100, RANGE, 1.0) > motion_arena_side(100, RANGE, 5.0)


def test_robots_start_uniform_in_the_walkable_area_without_overlap() -> None:
    arena = Arena.for_density(2000, RANGE, 5.0)
    positions = arena.place(2000, np.random.default_rng(4))
    assert arena.fits(positions, BODY_RADIUS).all()  # inside the walls, outside every column
    assert _min_gap(positions) >= 2 * BODY_RADIUS
    # Uniform: each quarter of the square (one column each) holds about a quarter of the robots.
    quarters = np.bincount((positions[:, 0] > 0) * 2 + (positions[:, 1] > 0), minlength=4)
    assert np.all(np.abs(quarters - 500) < 100), quarters


def test_a_column_blocks_line_of_sight() -> None:
    column = Discs(np.array([[0.0, 0.0]]), 0.5)
    across = np.array([[-1.2, 0.0], [1.2, 0.0]])  # 2.4 m apart: in range, but the column stands between
    assert links(across).degrees().tolist() == [1, 1]
    assert links(across, obstacles=column).degrees().tolist() == [0, 0]
    assert links(across, obstacles=column, occlusion=False).degrees().tolist() == [1, 1]
    beside = across + np.array([0.0, 0.6])  # the segment passes 0.6 m from the centre: clear of the 0.5 m column
    assert links(beside, obstacles=column).degrees().tolist() == [1, 1]


def _swarm(density: float, speed: float, seed: int = 0, robots: int = 100) -> MovingSwarm:
    arena = Arena.for_density(robots, RANGE, density)
    return MovingSwarm(arena, robots, np.random.default_rng(seed), RANGE, BODY_RADIUS, True, Dispersion(speed))


@pytest.mark.parametrize("density", [1.0, 5.0])
def test_motion_never_overlaps_and_respects_the_speed_cap(density: float) -> None:
    swarm = _swarm(density, speed=0.2)
    start = swarm.positions.copy()
    for _ in range(400):
        before = swarm.positions
        swarm.step()
        stride = np.hypot(*(swarm.positions - before).T)
        assert stride.max() <= 0.2 * 0.1 + 1e-12  # S x control step
        assert swarm.arena.fits(swarm.positions, BODY_RADIUS).all()
        assert _min_gap(swarm.positions) >= 2 * BODY_RADIUS
    travelled = np.hypot(*(swarm.positions - start).T)
    assert np.median(travelled) > 2.0  # they diffuse: most robots left their start well behind (max 8 m)


def test_a_crowded_arena_still_moves_without_overlap() -> None:
    # Bumps are frequent when bodies are packed: refused moves must keep every body apart.
    arena = Arena(4.0)
    swarm = MovingSwarm(arena, 60, np.random.default_rng(2), RANGE, BODY_RADIUS, True, Dispersion(0.2))
    for _ in range(200):
        swarm.step()
        assert _min_gap(swarm.positions) >= 2 * BODY_RADIUS
        assert arena.fits(swarm.positions, BODY_RADIUS).all()


def test_the_hearing_graph_follows_the_robots() -> None:
    swarm = _swarm(3.0, speed=0.2, seed=5)
    first = (swarm.hearing.src.copy(), swarm.hearing.dst.copy())
    for _ in range(300):
        swarm.step()
    again = links(swarm.positions, obstacles=swarm.arena.columns)
    assert np.array_equal(swarm.hearing.src, again.src) and np.array_equal(swarm.hearing.dst, again.dst)
    assert not (np.array_equal(first[0], again.src) and np.array_equal(first[1], again.dst))


def test_motion_runs_repeat_exactly_and_snapshots_replay_the_run() -> None:
    config = Config("motion", 40, 0.5, density=3.0, speed=0.2)
    alone = run_many(config, runs=2, seed=7, workers=1)
    assert run_many(config, runs=2, seed=7, workers=2) == alone
    seed = seed_for(config, 7, 0)
    start = motion_at(config, seed, 1)
    assert len(set(component_labels(start.hearing))) == alone[0].components
    later = motion_at(config, seed, 50)
    assert np.array_equal(later.positions, motion_at(config, seed_for(config, 7, 0), 50).positions)
    assert not np.array_equal(later.positions, start.positions)


def test_sparse_robots_need_motion_to_agree() -> None:
    # D = 1: islands. Standing still they can never agree; moving, they do.
    still = Config("motion", 30, 0.0, density=1.0, speed=0.0, max_steps=300)
    result = run_once(still, seed_for(still, 1, 0))
    assert result.components > 1 and result.steps is None
    moving = Config("motion", 30, 0.0, density=1.0, speed=0.2)
    result = run_once(moving, seed_for(moving, 1, 0))
    assert result.components > 1 and result.steps is not None
    assert result.msgs_per_robot_step == 1.0  # one message per robot per step


def test_at_d1_speed_is_the_limiting_factor() -> None:
    # Four times the speed: close to four times faster (the paper: speed limits convergence at D = 1).
    config = Config("motion", 10, 0.25, density=1.0)
    slow, fast = _medians(config, 3, speed=0.05), _medians(config, 3, speed=0.2)
    assert 2.0 <= slow / fast <= 8.0, (slow, fast)


@pytest.mark.parametrize("density", [3.0, 5.0])
def test_faster_robots_converge_faster_and_loss_degrades_gracefully(density: float) -> None:
    config = Config("motion", 50, 0.0, density=density)
    assert _medians(config, 5, speed=0.2) < _medians(config, 5, speed=0.05)
    # Graceful: three lost copies in four cost less than the 4x that a chain of single links would pay.
    lossless, lossy = _medians(config, 5, speed=0.1), _medians(config, 5, speed=0.1, drop=0.75)
    assert lossless < lossy < 4 * lossless


def test_motion_options_are_checked_by_name() -> None:
    for fields, word in (({"speed": -1.0}, "speed"), ({"control_step": 0.0}, "control_step"),
                         ({"turn_noise": math.nan}, "turn_noise"), ({"redraw_disconnected": True}, "redraw")):
        with pytest.raises(ValueError, match=word):
            Config("motion", 10, 0.0, **fields)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="cannot hold"):
        moving_swarm(Config("motion", 1, 0.0, radio_range=0.01, body_radius=1.0), np.random.default_rng(0))


def test_a_lone_robot_drives_straight_at_the_speed_cap_until_a_push() -> None:
    # From the centre of a 60 m arena, heading east: 8 m from every column, 30 m from the walls, so
    # nothing pushes it (no push beyond twice `repulsion`), and without noise it keeps heading and speed.
    swarm = MovingSwarm(Arena(60.0), 1, np.random.default_rng(4), RANGE, BODY_RADIUS, True,
                        Dispersion(0.2, turn_noise=0.0))
    swarm._z[:] = [0j]
    swarm._heading[:] = [1 + 0j]
    for _ in range(10):
        swarm.step()
    assert swarm.positions[0].tolist() == pytest.approx([10 * 0.2 * 0.1, 0.0], abs=1e-12)
    assert float(swarm.headings[0]) == 0.0


def test_two_robots_side_by_side_push_each_other_apart() -> None:
    arena = Arena(60.0)
    swarm = MovingSwarm(arena, 2, np.random.default_rng(1), RANGE, BODY_RADIUS, True, Dispersion(0.1, turn_noise=0.0))
    swarm._z[:] = [-0.2 + 5j, 0.2 + 5j]  # 0.4 m apart, far from the columns (at ±10 m) and the walls
    swarm._heading[:] = [1j, 1j]  # both facing the same way, along the gap between them
    swarm._list_pairs()
    swarm._sense()
    swarm.step()
    left, right = swarm.positions
    assert left[0] < -0.2 and right[0] > 0.2  # each moved away from the other
    assert left[1] > 5 and right[1] > 5  # while still driving forward
    assert right[0] - left[0] > 0.4
