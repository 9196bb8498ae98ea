"""What every example takes: link specs (none: stand-in robots), --robot-id and --seconds."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from vstig_hw.links import parse


def example_arguments(doc: str, seconds: float,
                      more: Callable[[argparse.ArgumentParser], object] = lambda parser: None) -> argparse.Namespace:
    """Parse the command line; a bad link spec is one line (exit 2), before anything opens."""
    parser = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    parser.add_argument("links", nargs="*", help="link specs (vstig links); none: stand-in robots, checked")
    parser.add_argument("--robot-id", type=int, default=100, help="this PC's id in the swarm (default 100)")
    parser.add_argument("--seconds", type=float, default=seconds, help=f"how long at most (default {seconds:g})")
    more(parser)
    args = parser.parse_args()
    for spec in args.links:
        try:
            parse(spec)
        except ValueError as error:
            parser.error(str(error))
    args.error = parser.error
    return args
