"""Hop distances and components of the hearing graph."""

from __future__ import annotations

from collections import deque

from .radio import Links

__all__ = ["component_labels", "component_maxima", "hops_from", "is_connected"]


def hops_from(hearing: Links, source: int) -> list[int]:
    """Breadth-first hop count from `source` to every robot (-1 where unreachable)."""
    neighbours = hearing.neighbours()
    hops = [-1] * hearing.robots
    hops[source] = 0
    frontier = deque([source])
    while frontier:
        here = frontier.popleft()
        for there in neighbours[here]:
            if hops[there] < 0:
                hops[there] = hops[here] + 1
                frontier.append(there)
    return hops


def component_labels(hearing: Links) -> list[int]:
    """For each robot, the lowest robot index of its connected component."""
    neighbours = hearing.neighbours()
    labels = [-1] * hearing.robots
    for root in range(hearing.robots):
        if labels[root] >= 0:
            continue
        labels[root] = root
        frontier = [root]
        while frontier:
            for there in neighbours[frontier.pop()]:
                if labels[there] < 0:
                    labels[there] = root
                    frontier.append(there)
    return labels


def component_maxima(hearing: Links) -> list[int]:
    """For each robot, the highest robot index it can ever hear of (its component's maximum)."""
    labels = component_labels(hearing)
    highest: dict[int, int] = {}
    for robot, label in enumerate(labels):
        highest[label] = robot  # robots are visited in increasing index order
    return [highest[label] for label in labels]


def is_connected(hearing: Links) -> bool:
    return hearing.robots <= 1 or min(hops_from(hearing, 0)) >= 0
