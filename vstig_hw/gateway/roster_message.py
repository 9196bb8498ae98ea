"""The roster as one message, for the views that publish it whole: the live view's `/vstig/robots` and a ros2:
link's `robots` topic. Its rows are `sniff --robots --jsonl`'s (`RobotView.as_json`), so every view agrees."""

from __future__ import annotations

import time
from typing import Any

from .kept_roster import KeptRoster
from .roster import RobotState

__all__ = ["robots_message", "standing"]


def robots_message(kept: KeptRoster) -> dict[str, Any]:
    """Every robot's row (sorted by state then id), how many are in each state, and how many more were heard
    than the roster may track."""
    views = kept.snapshot()
    states = {state.value: sum(view.state is state for view in views) for state in RobotState}
    return {"t": round(time.time(), 3), "robots_total": len(views), **states, "untracked": kept.roster.untracked,
            "rows": [view.as_json() for view in views]}


def standing(message: dict[str, Any]) -> list[tuple[Any, ...]]:
    """What a change of the roster is, for a view sent on change: who is there, in which state, on which links,
    behind on which keys (not the counts and rates, which change with every message)."""
    return [(row["robot"], row["state"], row["links"], row["behind"]) for row in message["rows"]]
