"""One run of the paper's task on N real `Stigmergy` engines, and many runs over the cores.

The task is the paper's Figure 1: at init every robot puts its own id under one
key, conflicts keep the larger value (`larger_value_wins`), and every control
step the robot gets the key. A run has converged at the first step whose get
returns the highest id on every robot.

Timing within a control step k (k = 1, 2, ...) follows ARGoS driving a Buzz
controller: the radio medium moves messages between steps, so
  1. every robot receives what its neighbours broadcast at the end of step k-1
     (each copy through `Stigmergy.receive`, in sender order);
  2. every robot runs its step: `get(key)`; convergence is checked here;
  3. every robot drains at most `budget` messages from its queue and broadcasts them.
So a message needs one step per hop, and init's PUT leaves at the end of step 1:
on a lossless radio the swarm converges at step 1 + (hops from the highest id
to the farthest robot).

Each run's randomness (layout and drops) comes from its own seed, derived from
the base seed and the run's identity (topology, N, P, run index), so results do
not depend on how many worker processes share the work or in which order.

The "motion" topology is section 4.2: the robots diffuse through an arena with
4 columns (`arena`, `motion`), the hearing graph is rebuilt after every control
step's move, and a run converges when every robot holds the highest id of the
whole swarm (motion can carry it to every region). Motion and drops draw from
two streams of the run's seed, so a run's trajectory does not depend on P's draws.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import signal
import statistics
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np

from ..engine import Stigmergy, larger_value_wins
from ..wire import MESSAGE_SIZE, U16_MAX, Message
from .arena import Arena
from .graph import component_labels, component_maxima, is_connected
from .motion import Dispersion, MovingSwarm
from .radio import Links, Radio, links
from .topology import BODY_RADIUS, DENSITY, RANGE, TOPOLOGIES

__all__ = ["MOTION", "TOPOLOGY_NAMES", "Config", "RunResult", "Summary", "layout", "motion_at", "moving_swarm",
           "run_many", "run_once", "run_tasks", "seed_for", "summarize"]

KEY = 1  # the paper's VSKEY
MOTION = "motion"  # section 4.2: robots diffusing through the arena with 4 columns
TOPOLOGY_NAMES = (*TOPOLOGIES, MOTION)  # the static ones first: their seeds stay as they were
_MAX_LAYOUTS = 1_000


@dataclass(frozen=True)
class Config:
    """One experimental condition <topology, N, P> and the radio and program around it."""

    topology: str
    robots: int
    drop: float
    budget: int = 1  # messages a robot may broadcast per control step (the paper: one 8-byte message)
    radio_range: float = RANGE
    density: float = DENSITY  # D: sets the arena side (over the walkable area for motion)
    body_radius: float = BODY_RADIUS
    occlusion: bool = True
    max_steps: int = 100_000
    # A split hearing graph can never agree on one id. By default each robot must
    # then hold the highest id of its own component (the best the radio allows);
    # with `redraw_disconnected`, layouts are re-drawn until the swarm is connected.
    redraw_disconnected: bool = False
    # Motion only (see `motion.Dispersion`): forward speed cap S in m/s, the control step in
    # seconds, the gap in metres at which a push equals the forward drive, the random turn in rad.
    speed: float = 0.1
    control_step: float = 0.1
    repulsion: float = 0.5
    turn_noise: float = 0.05

    def __post_init__(self) -> None:
        if self.topology not in TOPOLOGY_NAMES:
            raise ValueError(f"unknown topology {self.topology!r}; choose from {', '.join(TOPOLOGY_NAMES)}")
        if not 1 <= self.robots <= U16_MAX + 1:
            raise ValueError(f"robots must be in 1..{U16_MAX + 1} (robot ids are 16-bit), got {self.robots}")
        if not 0.0 <= self.drop < 1.0:
            raise ValueError(f"drop probability must be in [0, 1), got {self.drop}")
        for name in ("radio_range", "density", "body_radius", "speed", "control_step", "repulsion", "turn_noise"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):  # NaN passes every comparison click makes
                raise ValueError(f"{name} must be a finite number >= 0, got {value}")
        if not (self.radio_range > 0 and self.density > 0 and self.control_step > 0):
            raise ValueError(f"radio_range, density and control_step must be positive, got {self.radio_range}, "
                             f"{self.density} and {self.control_step}")
        reach = self.radio_range + self.body_radius
        side = math.sqrt(self.robots * math.pi * reach * reach / self.density)  # no **: it raises on overflow
        if not math.isfinite(side * side):
            raise ValueError(f"radio_range {self.radio_range} and density {self.density} make an arena too large "
                             "to compute with")
        if self.redraw_disconnected and self.topology == MOTION:
            raise ValueError("redraw_disconnected is for static topologies: a motion run must join its components")
        if self.budget < 1:
            raise ValueError(f"budget must be at least 1 message per step, got {self.budget}")
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be at least 1, got {self.max_steps}")


@dataclass(frozen=True)
class RunResult:
    run: int
    robots: int
    steps: int | None  # the convergence step; None when max_steps passed first
    steps_run: int
    messages: int  # broadcasts, all robots, all steps run
    deliveries: int  # copies that reached a receiver
    layouts: int  # layouts drawn (more than 1 only with redraw_disconnected)
    mean_degree: float  # for motion: averaged over the steps run
    components: int  # connected components of the hearing graph (1: everyone can agree); motion: at step 1
    largest_share: float = 1.0  # fraction of robots in the largest component (motion: at step 1)

    @property
    def msgs_per_robot_step(self) -> float:
        return self.messages / (self.robots * self.steps_run)

    @property
    def deliveries_per_robot_step(self) -> float:
        return self.deliveries / (self.robots * self.steps_run)


def seed_for(config: Config, base_seed: int, run: int) -> np.random.SeedSequence:
    topology = TOPOLOGY_NAMES.index(config.topology)
    return np.random.SeedSequence(base_seed, spawn_key=(topology, config.robots, round(config.drop * 1e6), run))


def layout(config: Config, rng: np.random.Generator) -> tuple[Links, int]:
    """The hearing graph of one layout, and how many layouts were drawn to get it."""
    generate = TOPOLOGIES[config.topology]
    for attempt in range(1, _MAX_LAYOUTS + 1):
        positions = generate(config.robots, rng, config.radio_range, config.body_radius, config.density)
        hearing = links(positions, config.radio_range, config.body_radius, config.occlusion)
        if not config.redraw_disconnected or is_connected(hearing):
            return hearing, attempt
    raise ValueError(f"no connected {config.topology} layout of {config.robots} robots in {_MAX_LAYOUTS} draws")


StepHook = Callable[[int, list[int | None]], None]
BroadcastHook = Callable[[int, list[list[Message]]], None]


def moving_swarm(config: Config, rng: np.random.Generator) -> MovingSwarm:
    """The robots of a motion run, placed in the arena that gives `config.density`."""
    arena = Arena.for_density(config.robots, config.radio_range, config.density)
    dispersion = Dispersion(config.speed, config.control_step, config.repulsion, config.turn_noise)
    return MovingSwarm(arena, config.robots, rng, config.radio_range, config.body_radius, config.occlusion,
                       dispersion)


def motion_at(config: Config, seed: np.random.SeedSequence, step: int) -> MovingSwarm:
    """Where a motion run's robots stand, and who hears whom, at control step `step` (1: the start).

    Motion draws from its own stream, so this replays the run's trajectory without its engines.
    """
    swarm = moving_swarm(config, motion_streams(seed)[0])
    for _ in range(step - 1):
        swarm.step()
    return swarm


def motion_streams(seed: np.random.SeedSequence) -> tuple[np.random.Generator, np.random.Generator]:
    """A motion run's two random streams, (motion, radio), derived from its seed without mutating it."""
    motion, radio = (np.random.SeedSequence(seed.entropy, spawn_key=(*seed.spawn_key, stream)) for stream in (0, 1))
    return np.random.default_rng(motion), np.random.default_rng(radio)


def run_once(config: Config, seed: np.random.SeedSequence, run: int = 0, on_step: StepHook | None = None,
             on_broadcast: BroadcastHook | None = None) -> RunResult:
    """One run; `on_step(step, values)` sees what every robot's get returned at each step,
    `on_broadcast(step, outgoing)` what every robot broadcast at its end."""
    swarm: MovingSwarm | None = None
    if config.topology == MOTION:
        motion_rng, rng = motion_streams(seed)
        swarm = moving_swarm(config, motion_rng)
        hearing, layouts = swarm.hearing, 1
        targets = [config.robots - 1] * config.robots  # motion can carry the highest id to every region
    else:
        rng = np.random.default_rng(seed)
        hearing, layouts = layout(config, rng)
        targets = component_maxima(hearing)  # the highest id each robot can learn: all robots - 1 when connected
    labels = component_labels(hearing)
    radio = Radio(hearing, config.drop, rng)
    engines = [Stigmergy(robot_id, onconflict=larger_value_wins) for robot_id in range(config.robots)]
    for engine in engines:
        engine.put(KEY, engine.robot_id)
    budget = config.budget
    gets = [engine.get for engine in engines]
    drains = [engine.drain for engine in engines]
    receives = [engine.receive for engine in engines]
    outgoing: list[list[Message]] = [[] for _ in engines]
    messages = deliveries = links_heard = 0
    converged: int | None = None
    step = 0
    while step < config.max_steps:
        step += 1
        deliveries += radio.deliver(outgoing, receives)
        links_heard += len(radio.links.src)
        values = [get(KEY) for get in gets]
        agreed = values == targets
        if on_step:
            on_step(step, values)
        outgoing = [drain(budget) for drain in drains]
        messages += sum(map(len, outgoing))
        if on_broadcast:
            on_broadcast(step, outgoing)
        if agreed:
            converged = step
            break
        if swarm is not None:
            swarm.step()
            radio.hear(swarm.hearing)
    mean_degree = links_heard / (config.robots * step) if swarm else float(hearing.degrees().mean())
    return RunResult(run, config.robots, converged, step, messages, deliveries, layouts, mean_degree,
                     len(set(labels)), max(Counter(labels).values()) / config.robots)


Task = tuple[Config, int, int]  # (config, base seed, run index)


def _run_task(task: Task) -> tuple[Task, RunResult]:
    config, base_seed, run = task
    return task, run_once(config, seed_for(config, base_seed, run), run)


def estimated_cost(config: Config) -> float:
    """Rough robot-steps a run takes: used to start the longest runs first."""
    if config.topology == MOTION:  # sparse and slow robots wait for motion to cross the arena
        hops = Arena.for_density(config.robots, config.radio_range, config.density).side / (
            config.density * max(config.speed * config.control_step, 1e-3))
    else:
        hops = config.robots if config.topology == "line" else 4 * config.robots**0.5
    return config.robots * hops / (1.0 - config.drop)


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


# Every run's result is held until the summary: a bound on runs is a bound on memory (100,000 runs: tens of MB).
# Past a few thousand runs a summary's figures no longer move; `sim --runs` and the grids' runs x conditions
# are refused beyond this.
MAX_RUNS = 100_000
MAX_WORKERS = 256  # processes; more than a machine's cores only adds memory


def run_tasks(
    tasks: Iterable[Task], workers: int | None = None, on_done: Callable[[Task, RunResult], None] | None = None
) -> dict[Task, RunResult]:
    """Run every task over `workers` processes (default: all cores), longest first."""
    ordered = sorted(tasks, key=lambda task: -estimated_cost(task[0]))
    workers = max(1, min(workers or os.cpu_count() or 1, len(ordered)))
    results: dict[Task, RunResult] = {}
    if workers == 1:
        done: Iterable[tuple[Task, RunResult]] = map(_run_task, ordered)
        for task, result in done:
            results[task] = result
            if on_done:
                on_done(task, result)
        return results
    # Workers ignore Ctrl-C: the parent alone stops (the pool's exit terminates them), so a
    # terminal's SIGINT to the whole group ends the run once, without a traceback per worker.
    with multiprocessing.get_context("fork").Pool(workers, initializer=_ignore_sigint) as pool:
        for task, result in pool.imap_unordered(_run_task, ordered, chunksize=1):
            results[task] = result
            if on_done:
                on_done(task, result)
    return results


def run_many(
    config: Config, runs: int, seed: int = 1, workers: int | None = None,
    on_done: Callable[[Task, RunResult], None] | None = None,
) -> list[RunResult]:
    results = run_tasks([(config, seed, run) for run in range(runs)], workers, on_done)
    return sorted(results.values(), key=lambda r: r.run)


@dataclass(frozen=True)
class Summary:
    """Convergence statistics over runs (None when no run converged) and the bandwidth used."""

    runs: int
    converged: int
    median: float | None
    min: int | None
    max: int | None
    mean: float | None
    msgs_per_robot_step: float
    bytes_per_robot_step: float
    deliveries_per_robot_step: float
    mean_degree: float
    split_runs: int  # runs whose hearing graph had more than one component (motion: at step 1)
    largest_share: float  # mean fraction of robots in the largest component (motion: at step 1)
    steps: list[int] = field(default_factory=list)

    def as_json(self) -> dict[str, object]:
        return asdict(self)


def summarize(results: Sequence[RunResult]) -> Summary:
    if not results:
        raise ValueError("no runs to summarize")
    steps = sorted(r.steps for r in results if r.steps is not None)
    msgs = statistics.fmean(r.msgs_per_robot_step for r in results)
    return Summary(
        runs=len(results),
        converged=len(steps),
        median=statistics.median(steps) if steps else None,
        min=steps[0] if steps else None,
        max=steps[-1] if steps else None,
        mean=statistics.fmean(steps) if steps else None,
        msgs_per_robot_step=msgs,
        bytes_per_robot_step=msgs * MESSAGE_SIZE,
        deliveries_per_robot_step=statistics.fmean(r.deliveries_per_robot_step for r in results),
        mean_degree=statistics.fmean(r.mean_degree for r in results),
        split_runs=sum(r.components > 1 for r in results),
        largest_share=statistics.fmean(r.largest_share for r in results),
        steps=steps,
    )
