"""Many real `Stigmergy` engines on a simulated radio: the paper's experiments, reproducible."""

from .experiment import Config, RunResult, Summary, run_many, run_once, run_tasks, seed_for, summarize
from .radio import Links, Radio, links
from .topology import BODY_RADIUS, DENSITY, RANGE, TOPOLOGIES, arena_side

__all__ = [
    "BODY_RADIUS",
    "DENSITY",
    "RANGE",
    "TOPOLOGIES",
    "Config",
    "Links",
    "Radio",
    "RunResult",
    "Summary",
    "arena_side",
    "links",
    "run_many",
    "run_once",
    "run_tasks",
    "seed_for",
    "summarize",
]
