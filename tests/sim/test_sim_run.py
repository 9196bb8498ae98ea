"""Runs of the paper's task on real engines: reproducible, detected at the right step, bounded by hops."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest

from vstig_hw.sim import Config, run_many, run_once, seed_for, summarize
from vstig_hw.sim.experiment import layout


def _bfs_hops(neighbours: list[list[int]], source: int) -> list[int]:
    hops = [-1] * len(neighbours)
    hops[source] = 0
    queue = deque([source])
    while queue:
        here = queue.popleft()
        for there in neighbours[here]:
            if hops[there] < 0:
                hops[there] = hops[here] + 1
                queue.append(there)
    return hops


def test_seeded_runs_repeat_exactly_and_ignore_the_worker_count() -> None:
    config = Config("cluster", 30, 0.5)
    alone = run_many(config, runs=4, seed=7, workers=1)
    assert run_many(config, runs=4, seed=7, workers=1) == alone
    assert run_many(config, runs=4, seed=7, workers=2) == alone
    other = run_many(config, runs=4, seed=8, workers=1)
    assert [r.steps for r in other] != [r.steps for r in alone] or [r.deliveries for r in other] != [
        r.deliveries for r in alone]


@pytest.mark.parametrize("seed", range(5))
def test_convergence_is_the_first_step_where_every_robot_holds_the_maximum(seed: int) -> None:
    config = Config("cluster", 20, 0.6, redraw_disconnected=True)
    seen: list[tuple[int, list[int | None]]] = []
    result = run_once(config, seed_for(config, seed, 0), on_step=lambda step, values: seen.append((step, values)))
    assert result.steps is not None and result.steps == result.steps_run == len(seen)
    assert result.components == 1
    assert seen[-1][1] == [19] * 20
    assert all(values != [19] * 20 for _, values in seen[:-1])
    # Capping the run one step short ends it unconverged, with nothing else changed.
    short = run_once(Config("cluster", 20, 0.6, redraw_disconnected=True, max_steps=result.steps - 1),
                     seed_for(config, seed, 0))
    assert short.steps is None and short.steps_run == result.steps - 1


@pytest.mark.parametrize("seed", range(8))
def test_lossless_cluster_converges_in_the_steps_its_hops_allow(seed: int) -> None:
    # One hop per step, and init's PUT leaves at the end of step 1: the swarm agrees at
    # step 1 + (hops from the highest id to the farthest robot) <= 1 + diameter.
    config = Config("cluster", 10, 0.0, redraw_disconnected=True)
    hearing, _ = layout(config, np.random.default_rng(seed_for(config, seed, 0)))
    neighbours = hearing.neighbours()
    from_highest = _bfs_hops(neighbours, 9)
    diameter = max(max(_bfs_hops(neighbours, robot)) for robot in range(10))
    assert min(from_highest) >= 0
    result = run_once(config, seed_for(config, seed, 0))
    assert result.steps == 1 + max(from_highest) <= 1 + diameter


def test_line_needs_one_step_per_robot_without_loss_and_longer_with_it() -> None:
    lossless = summarize(run_many(Config("line", 25, 0.0), runs=3, workers=1))
    assert (lossless.min, lossless.max) == (25, 25)
    lossy = summarize(run_many(Config("line", 25, 0.5), runs=3, workers=1))
    assert lossy.min is not None and lossy.min > 25


def test_split_swarm_agrees_per_component_and_bandwidth_is_one_message_per_step() -> None:
    result = run_once(Config("cluster", 100, 0.0), seed_for(Config("cluster", 100, 0.0), 1, 0))
    assert result.components > 1  # at D = 5 a hundred robots almost never all hear each other
    assert result.steps is not None
    assert result.msgs_per_robot_step == 1.0  # every robot gets every step: its budget is always used
    # Lossless: every robot hears every neighbour every step after the first.
    assert result.deliveries == round(result.mean_degree * 100) * (result.steps_run - 1)


def test_bad_conditions_are_refused_with_their_name() -> None:
    bad = (({"topology": "ring"}, "topology"), ({"robots": 0}, "robots"), ({"robots": 65537}, "robots"),
           ({"drop": 1.0}, "drop"), ({"budget": 0}, "budget"), ({"max_steps": 0}, "max_steps"))
    for kwargs, word in bad:
        fields = {"topology": "cluster", "robots": 10, "drop": 0.0, **kwargs}
        with pytest.raises(ValueError, match=word):
            Config(**fields)  # type: ignore[arg-type]
