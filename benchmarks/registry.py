"""The benchmark registry and result type shared by every bench module."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass

BenchFn = Callable[[], Iterable["Result"]]
REGISTRY: dict[str, BenchFn] = {}


@dataclass(frozen=True)
class Result:
    """One figure beside its anchor. `ratio` is value / anchor_value."""

    name: str
    value: float
    unit: str
    anchor: str
    anchor_value: float

    @property
    def ratio(self) -> float:
        return self.value / self.anchor_value if self.anchor_value else float("nan")

    def as_json(self) -> dict[str, object]:
        return {"value": self.value, "unit": self.unit, "anchor": self.anchor,
                "anchor_value": self.anchor_value, "ratio": self.ratio}


def benchmark(group: str) -> Callable[[BenchFn], BenchFn]:
    def register(fn: BenchFn) -> BenchFn:
        REGISTRY[f"{group}.{fn.__name__}"] = fn
        return fn
    return register


def rate(fn: Callable[[], int], min_seconds: float = 0.5) -> float:
    """Items per second: `fn` does a batch and returns how many items it handled.

    Repeats until `min_seconds` have passed and keeps the best batch, which is
    the least disturbed by the rest of the machine.
    """
    best = 0.0
    spent = 0.0
    while spent < min_seconds:
        start = time.perf_counter()
        count = fn()
        elapsed = time.perf_counter() - start
        spent += elapsed
        best = max(best, count / elapsed)
    return best
