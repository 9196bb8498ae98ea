"""Links from what a user names them by: spec strings, parsed specs or ready Link objects, with unique names.

Shared by the CLI (`bridge`, `put`, `get`...) and the Python API (`vstig_hw.join`), so a spec means the
same thing in both and the same bad spec gets the same one line.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from ..counters import ENGINE_STATS
from .link import Link, LinkSpec, NamesSenders
from .registry import parse

__all__ = ["LinkBuildError", "assemble_links", "check_robot_id"]


class LinkBuildError(ValueError):
    """A link that cannot be built as asked; `argument` names what is wrong: "robot_id" or "links"."""

    def __init__(self, message: str, argument: str) -> None:
        super().__init__(message)
        self.argument = argument


def check_robot_id(specs: Sequence[LinkSpec], robot_id: int) -> None:
    """LinkBuildError("robot_id") when a spec's sender field (a CAN ID scheme) has no room for `robot_id`."""
    for spec in specs:
        if isinstance(spec, NamesSenders):
            try:
                spec.check_sender(robot_id)
            except ValueError as error:
                raise LinkBuildError(str(error), "robot_id") from None


def assemble_links(items: Sequence[str | LinkSpec | Link[Any]], robot_id: int = 0,
                   listen_only: bool = False) -> list[Link[Any]]:
    """One Link per item, a spec named after its device (made unique: radio, radio-2...); Links pass as they are.

    A bad spec or item raises LinkBuildError("links") with one line naming it.
    """
    specs: list[LinkSpec | Link[Any]] = []
    for number, item in enumerate(items):
        if isinstance(item, str):
            try:
                specs.append(parse(item))
            except ValueError as error:
                raise LinkBuildError(str(error), "links") from None
        elif isinstance(item, Link | LinkSpec):
            specs.append(item)
        else:
            raise LinkBuildError(f"link {number + 1} is a {type(item).__name__}: give a spec string "
                                 "(e.g. 'can:socketcan:can0') or a Link", "links")
    if not listen_only:
        check_robot_id([spec for spec in specs if not isinstance(spec, Link)], robot_id)
    links: list[Link[Any]] = []
    seen: dict[str, int] = {ENGINE_STATS: 1}  # that name is taken by the engine's counters
    for spec in specs:
        if isinstance(spec, Link):
            seen[spec.name] = seen.get(spec.name, 0) + 1
            links.append(spec)
            continue
        name = spec.name
        seen[name] = seen.get(name, 0) + 1
        if seen[name] > 1:
            name = f"{name}-{seen[name]}"
        try:
            links.append(spec.build(name, robot_id=robot_id, listen_only=listen_only))
        except ValueError as error:  # building opens nothing: what fails here is how the link was asked for
            raise LinkBuildError(f"{spec.kind}:{spec.name}: {error}", "links") from None
    return links
