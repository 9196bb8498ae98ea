"""The roster (issue 47): what keeping it costs a relay, and sniff's robots table at 1,000 robots.

* CPU per message of a `vstig bridge` relaying pty -> pty (raw and engine, the compiled data path), the roster on
  (the default) beside the same bridge with `--no-roster`, the runs alternating, the median of ROUNDS each; and,
  where valgrind is, user-space instructions per message (callgrind: a figure the shared VM's load cannot move).
* `vstig sniff --robots`'s table at 1,000 robots, built and drawn at 80 columns: against one control period.
"""

from __future__ import annotations

import io
import statistics
import sys
import time
from collections.abc import Callable, Iterator

from vstig_hw.gateway.node import DEFAULT_PERIOD
from vstig_hw.gateway.roster import Roster
from vstig_hw.wire import Message, Op

from .bench_datapath import _engine, _raw, _relay_run, instructions_per_msg
from .registry import Result, benchmark

ROUNDS = 5


def _without_roster(argv: Callable[[str, str], list[str]]) -> Callable[[str, str], list[str]]:
    return lambda a, b: [*argv(a, b), "--no-roster"]


# name -> (argv, whether it re-broadcasts onto the radio it heard)
_RELAYS: dict[str, tuple[Callable[[str, str], list[str]], bool]] = {
    "raw": (_raw, False),
    "raw_no_roster": (_without_roster(_raw), False),
    "engine": (_engine, True),
    "engine_no_roster": (_without_roster(_engine), True),
}


@benchmark("roster")
def relay_cpu_roster_on_vs_off() -> Iterator[Result]:
    runs: dict[str, list[float]] = {}
    for _ in range(ROUNDS):  # alternated, so the VM's load falls on both alike; the median of each
        for name, (argv, echo) in _RELAYS.items():
            runs.setdefault(name, []).append(_relay_run(argv, echo)[0])
    for name in ("raw", "engine"):
        yield Result(f"roster.relay_{name}_cpu_per_msg", statistics.median(runs[name]) * 1e6, "us",
                     "same bridge --no-roster", statistics.median(runs[f"{name}_no_roster"]) * 1e6)


@benchmark("roster")
def relay_instructions_roster_on_vs_off() -> Iterator[Result]:
    """Instructions per message: a run of 10,000 messages less one of 500 (start-up cancels out; its own wobble, ~1M
    instructions a run, is then +-1% of a message's, small against the 5% the goal allows)."""
    try:
        per_msg = instructions_per_msg("roster.relay_instructions",
                                       {name: (argv, echo, {}) for name, (argv, echo) in _RELAYS.items()}, many=10_000)
    except RuntimeError as error:  # a bridge under callgrind on a busy VM may not come up in time
        print(f"roster.relay_instructions: {error}", file=sys.stderr)
        return
    if per_msg is None:
        return
    for name in ("raw", "engine"):
        yield Result(f"roster.relay_{name}_instructions_per_msg", per_msg[name], "instr", "same bridge --no-roster",
                     per_msg[f"{name}_no_roster"])


@benchmark("roster")
def sniff_table_at_1000_robots() -> Iterator[Result]:
    from rich.console import Console

    from vstig_cli.robots import robots_table

    roster = Roster(DEFAULT_PERIOD)
    now = time.time()
    for n in range(1000):
        who = 0x0013A20040A10000 + n
        roster.take("radio0", now - 5 - n % 7, who, [Message(Op.GET, key, 0, 1, 1) for key in range(20)])
        roster.take("radio1", now - n % 7, who, [Message(Op.PUT, n, 1, 2, 1)])
    roster.sweep(now)
    console = Console(width=80, height=50, file=io.StringIO(), force_terminal=True)
    best = float("inf")
    for _ in range(10):
        start = time.perf_counter()
        console.print(robots_table(roster, height=50))
        best = min(best, time.perf_counter() - start)
    yield Result("roster.sniff_table_1000_robots_redraw", best * 1e3, "ms", "one control period", DEFAULT_PERIOD * 1e3)
