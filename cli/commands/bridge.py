"""`vstig bridge LINK LINK... --robot-id N`: the PC joins the swarm on every link."""

from __future__ import annotations

import sys
from typing import Any

import click

from vstig_hw.api.recording import Recording, link_medium
from vstig_hw.capture.plan import capture_medium
from vstig_hw.engine import larger_value_wins
from vstig_hw.extras import require
from vstig_hw.gateway import DEFAULT_BUDGET, DEFAULT_PERIOD, Mode, Node, RoundRobinGet, favour_latency, stop_on_signals
from vstig_hw.gateway.ros2 import serve_ros2
from vstig_hw.links import Link, LinkSpec

from ..config import ConfiguredCommand, config_options
from ..live import foxglove_option, live_view
from ..ops.metrics import metrics_option, metrics_served
from ..options import Address, Finite, GuardChoice, guard_options, overwrite_option, refuse_to_replace, take_warnings
from ..robots import roster_options, start_roster
from ..running import (
    LINK,
    LinkArguments,
    build_links,
    describe_links,
    opened,
    print_counters,
    reports_errors,
    run_until_stopped,
)
from ..swarm_key import swarm_key_option, swarm_keys_for


def _raw_note(robot_id: int | None) -> str:
    """What a raw bridge sends as: messages re-encoded onto CAN carry a sender id in the CAN ID."""
    if robot_id is None:
        return "raw; messages re-encoded onto CAN go out as node 0, --robot-id N chooses"
    return f"raw; messages re-encoded onto CAN go out as node {robot_id}"


@click.command(cls=ConfiguredCommand)
@click.argument("links", nargs=-1, required=True, type=LINK, cls=LinkArguments)
@click.option("--robot-id", type=click.IntRange(0, 0xFFFF), help="The PC's robot id (required unless --raw).")
@click.option("--tick", type=Finite(0.001, 60), default=DEFAULT_PERIOD, show_default=True,
              help="Control period in seconds.")
@click.option("--budget", type=click.IntRange(1, 1_000_000), default=DEFAULT_BUDGET, show_default=True,
              help="Messages per link per tick, shared fairly among their sources.")
@click.option("--raw", is_flag=True, help="Relay every frame between links, translating framings, with no engine.")
@click.option("--larger-value-wins", "larger", is_flag=True,
              help="Resolve conflicts by the larger value (the paper's Figure 1) instead of the higher robot id.")
@click.option("--refresh/--no-refresh", default=True, show_default=True,
              help="GET one key of the table per tick, round-robin, as a robot's program would: repairs gateways "
                   "that were apart (network partition, restart) without waiting for the next write.")
@click.option("--for", "duration", type=Finite(0.0), help="Stop after this many seconds.")
@click.option("--record", "record", type=click.Path(path_type=str), metavar="FILE",
              help="Record every link's traffic, heard and sent, and the gateway's own decisions into FILE "
                   "(formats as vstig record -o; docs/how-to/why.md).")
@overwrite_option("the --record FILE")
@roster_options
@foxglove_option
@metrics_option
@guard_options
@swarm_key_option
@config_options
@reports_errors
def command(links: tuple[LinkSpec, ...], robot_id: int | None, tick: float, budget: int, raw: bool,
            larger: bool, refresh: bool, duration: float | None, record: str | None, overwrite: bool,
            no_roster: bool, quiet_after: float | None, gone_after: float | None, max_robots: int,
            foxglove: Address | None, foxglove_viewers: int, metrics: Address | None, guard: GuardChoice,
            swarm_key: bytes | None) -> None:
    """Run the gateway: one engine on every LINK, until Ctrl-C.

    The status line and the counters printed on exit have each link's counters
    and the engine's receive outcomes (stored, answered, stale, same, conflict,
    unknown, invalid).

    Example: vstig bridge can:socketcan:can0 serial:/dev/ttyUSB0?framing=epuck4 --robot-id 200

    A guard checks what every link hears before the engine sees it: timestamp jumps are refused by
    default; --learn, --rate, --source-rate, --trust, --deny, --keys, --read-only and --flap add
    policies. LINK names are those printed at start (the device's name: can0, ttyUSB0...). Refusals
    are counted per link (drop_jump, drop_rate, drop_source_rate, drop_untrusted, drop_key).

    Every link's --budget is shared fairly among the sources of what it carries (each link, each
    zenoh session connected to ours, the bridge itself), so a flooding radio or zenoh peer delays
    only its own messages; a quiet link's message goes first, from a sixteenth of the budget a
    backlog leaves free; the engine takes at most 16 ticks of budget per source and tick,
    on average, with bursts of ten times that (drop_intake).

    \b
    Many PCs: add a zenoh link on each (vstig links lists its options), e.g.
    vstig bridge can:socketcan:can0 zenoh:lab?connect=tcp/10.0.0.5:7447 --robot-id 201

    --foxglove 8765 shows the swarm live in Foxglove (docs/how-to/live-view.md).

    --record FILE keeps a capture of every link, what the bridge hears and what it sends, with
    notes of what it decided (refusals, drops, overflows, conflicts): vstig why reads it.

    --swarm-key FILE checks the writers' tags on links with auth=require or auth=prefer, and sends
    every entry with its writer's tag there (drop_untagged, drop_bad_tag; docs/how-to/auth.md).
    """
    if robot_id is None and not raw:
        raise click.UsageError("--robot-id is required (the PC's id in the swarm), or use --raw")
    if raw and len(links) < 2:
        raise click.UsageError("--raw needs at least two links to bridge")
    if raw and swarm_key is not None:
        raise click.UsageError("--swarm-key needs an engine to keep the entries' tags: drop --raw")
    built = build_links(links, robot_id or 0)
    keys = swarm_keys_for(built, swarm_key)
    if record is not None:
        _check_record_file(record, built, overwrite)
    firewall = guard.build(built)
    # A recording bridge relays on the Python path, whose writes the recording sees (Recording).
    node = Node(built, robot_id or 0, mode=Mode.RAW if raw else Mode.ENGINE,
                period=tick, budget=None if raw and budget == DEFAULT_BUDGET else budget,
                onconflict=larger_value_wins if larger else None, guard=firewall, pure=record is not None,
                swarm_keys=keys)
    recording = None if record is None else Recording(node, record, overwrite=True)
    start_roster(node, no_roster, quiet_after, gone_after, max_robots)  # who is heard: --metrics, the live view
    if refresh and not raw:
        node.listen(tick=RoundRobinGet())
    serve_ros2(node)
    live = sys.stderr.isatty()
    favour_latency()

    def status() -> None:
        for warning in take_warnings(firewall) + take_warnings(node.signing):
            click.echo(f"\r\x1b[K{warning}" if live else warning, err=True)
        if live:  # the line only where it is drawn: a service's log gets none, and its gateway builds none
            click.echo(f"\r\x1b[K{node.summary()}", nl=False, err=True)

    with (stop_on_signals() as stop, live_view(node, foxglove, larger_value_wins=larger, viewers=foxglove_viewers),
          metrics_served(node, metrics), opened(node, stop)):
        click.echo(f"bridging {', '.join(link.name for link in node.links)} "
                   f"({_raw_note(robot_id) if raw else f'robot {robot_id}'}); Ctrl-C stops", err=True)
        describe_links(node)
        try:
            run_until_stopped(node, stop, status, duration)
        finally:
            if live:
                click.echo(err=True)
    for warning in take_warnings(firewall) + take_warnings(node.signing):
        click.echo(warning, err=True)
    print_counters(node)
    if recording is not None:
        click.echo(f"{recording.records} units in {', '.join(recording.files)}", err=True)


def _check_record_file(path: str, links: list[Link[Any]], overwrite: bool) -> None:
    """--record's file, checked as vstig record checks -o, before any link opens."""
    try:
        medium = capture_medium(path, [link_medium(link) for link in links])
    except ValueError as error:
        raise click.UsageError(f"--record {error}") from None
    refuse_to_replace(path, overwrite)
    if medium == "mcap":
        require("mcap", f"vstig bridge --record {path}")
