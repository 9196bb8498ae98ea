"""`vstig sim`: predict convergence and bandwidth for a swarm, or reproduce the paper's Figures 3 and 5.

    vstig sim --topology cluster --robots 100 --drop 0.75 --runs 20 [--json]
    vstig sim --topology motion --density 3 --speed 0.1 --drop 0.5 --runs 10 [--snapshot out.png]
    vstig sim paper --runs 50 -o results/
    vstig sim paper-motion --runs 50 -o results/
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

import click

from vstig_hw.sim import Config, Summary, run_many, summarize
from vstig_hw.sim.experiment import MAX_RUNS, MAX_WORKERS, MOTION, TOPOLOGY_NAMES, RunResult, Task
from vstig_hw.sim.grid import Cell
from vstig_hw.sim.topology import BODY_RADIUS, DENSITY, RANGE
from vstig_hw.wire import U16_MAX
from vstig_hw.wording import counted

from ..options import Finite, finite, overwrite_option, refuse_links_in, refuse_to_replace


def _model_options(fn: Any) -> Any:
    """Radio and program options shared by a single condition and the paper grid."""
    options = [
        click.option("--budget", default=1, show_default=True, type=click.IntRange(1),
                     help="messages a robot may broadcast per control step"),
        click.option("--range", "radio_range", default=RANGE, show_default=True,
                     type=Finite(0, min_open=True),
                     help="communication range R in metres"),
        click.option("--density", default=DENSITY, show_default=True, type=Finite(0, min_open=True),
                     help="density D = N*pi*R^2 / area (cluster: L^2; motion: L^2 minus the 4 columns)"),
        click.option("--body-radius", default=BODY_RADIUS, show_default=True, type=Finite(0),
                     help="robot body radius in metres (overlap and line of sight)"),
        click.option("--occlusion/--no-occlusion", default=True, show_default=True,
                     help="bodies block line of sight, as in ARGoS"),
        click.option("--redraw-disconnected", is_flag=True,
                     help="re-draw split layouts (else each robot must learn its own component's highest id)"),
        click.option("--max-steps", default=200_000, show_default=True, type=click.IntRange(1),
                     help="give up on a run after this many control steps"),
        click.option("--seed", default=1, show_default=True, type=click.IntRange(0),
                     help="Base random seed (each run derives its own from it): the same seed, the same results."),
        click.option("--workers", default=None, type=click.IntRange(1, MAX_WORKERS),
                     help="processes [default: all cores]"),
    ]
    for option in reversed(options):
        fn = option(fn)
    return fn


def _motion_options(fn: Any) -> Any:
    """How robots move in the motion arena (section 4.2); the speed cap is set per command."""
    options = [
        click.option("--control-step", default=Config.control_step, show_default=True,
                     type=Finite(0, min_open=True),
                     help="seconds per control step: how long robots move in one (motion), and what turns steps "
                          "into seconds (B/s, --capture's times)"),
        click.option("--repulsion", default=Config.repulsion, show_default=True, type=Finite(0),
                     help="gap in metres at which a neighbour's or obstacle's push equals the forward drive (motion)"),
        click.option("--turn-noise", default=Config.turn_noise, show_default=True, type=Finite(0),
                     help="standard deviation of the random turn per control step, in radians (motion)"),
    ]
    for option in reversed(options):
        fn = option(fn)
    return fn


_MOTION_FIELDS = ("speed", "control_step", "repulsion", "turn_noise")


def _config(topology: str, robots: int, drop: float, **model: Any) -> Config:
    motion = {name: model[name] for name in _MOTION_FIELDS if name in model}
    try:
        return Config(topology, robots, drop, budget=model["budget"], radio_range=model["radio_range"],
                      density=model["density"], body_radius=model["body_radius"], occlusion=model["occlusion"],
                      redraw_disconnected=model["redraw_disconnected"], max_steps=model["max_steps"], **motion)
    except ValueError as error:
        raise click.UsageError(str(error)) from None


def _progress(transient: bool = False) -> Any:
    """A bar on stderr, so stdout stays clean for pipes; none at all when stderr is not a terminal."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    console = Console(stderr=True)
    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                    console=console, transient=transient, disable=not console.is_terminal)


@click.group(invoke_without_command=True)
@click.option("--topology", type=click.Choice(TOPOLOGY_NAMES), default="cluster", show_default=True,
              help="How robots are placed: a static layout of section 4.1 (who hears whom follows from it), "
                   "or motion: robots diffusing through the arena of section 4.2.")
@click.option("--robots", default=100, show_default=True, type=click.IntRange(1, U16_MAX + 1),
              help="swarm size N (robot ids 0..N-1)")
@click.option("--drop", default=0.0, show_default=True, type=Finite(0, 1, max_open=True),
              help="packet drop probability P")
@click.option("--runs", default=10, show_default=True, type=click.IntRange(1, MAX_RUNS),
              help=f"Independent runs (new layout and losses each); the summary is over all of them (at most "
                   f"{MAX_RUNS:,}; a bar on a terminal shows how far they are).")
@click.option("--json", "as_json", is_flag=True, help="print one JSON object")
@click.option("--capture", type=click.Path(dir_okay=False, writable=True),
              help="also write run 0's radio traffic as a CAN capture (.log candump, .asc, .blf...): robot i is "
                   "CAN node i, time = step x --control-step; for checking `vstig analyze`")
@_model_options
@click.option("--speed", default=Config.speed, show_default=True, type=Finite(0),
              help="forward speed cap S in m/s (motion)")
@_motion_options
@click.option("--snapshot", type=click.Path(dir_okay=False, path_type=Path),
              help="instead of running, draw run 0 at --snapshot-step to this PNG (motion; as Figure 4)")
@click.option("--snapshot-step", default=1, show_default=True, type=click.IntRange(1),
              help="the control step --snapshot draws")
@overwrite_option("the --capture or --snapshot FILE")
@click.pass_context
def command(ctx: click.Context, /, topology: str, robots: int, drop: float, runs: int, as_json: bool,
            capture: str | None, seed: int, workers: int | None, snapshot: Path | None, snapshot_step: int,
            overwrite: bool, **model: Any) -> None:
    """Simulate the paper's task (agree on the highest id) on real engines over a lossy radio."""
    if ctx.invoked_subcommand is not None:
        return
    if topology not in ("cluster", "motion") \
            and ctx.get_parameter_source("density") is click.core.ParameterSource.COMMANDLINE:
        raise click.UsageError(f"--density sets the arena of cluster and motion runs; a {topology} layout is built "
                               "by distance and does not use it")
    config = _config(topology, robots, drop, **model)
    if snapshot is not None:
        refuse_to_replace(snapshot, overwrite)
        _draw_snapshot(config, seed, snapshot_step, snapshot)
        return
    if capture:
        refuse_to_replace(capture, overwrite)  # before the runs, which may take minutes
    try:
        with _progress(transient=True) as progress:
            bar = progress.add_task(_label(config), total=runs)
            results = run_many(config, runs, seed, workers, lambda _task, _result: progress.advance(bar))
        summary = summarize(results)
    except ValueError as error:  # a layout that cannot be built (e.g. a density too high to place bodies)
        raise click.ClickException(str(error)) from None
    if capture:
        _capture(config, seed, capture)
    if as_json:
        click.echo(json.dumps({**summary.as_json(), "config": {**vars(config), "seed": seed}}))
        return
    click.echo(f"{_label(config)}: {counted(runs, 'run')}, seed {seed}")
    click.echo(_steps_line(summary))
    click.echo(_bandwidth_line(summary, config.control_step))
    click.echo(f"graph: mean degree {summary.mean_degree:.2f}" + _split_note(summary, config.topology == MOTION))
    _unconverged_note(summary, config.max_steps)


def _label(c: Config) -> str:
    moving = f" D={c.density:g} S={c.speed:g}" if c.topology == MOTION else ""
    return f"{c.topology}{moving} N={c.robots} P={c.drop}"


def _capture(config: Config, seed: int, path: str) -> None:
    """Run 0 again (its seed makes it the same run) with every broadcast written to `path`."""
    from vstig_hw.sim.capture import capture_run
    from vstig_hw.sim.experiment import seed_for

    try:
        result = capture_run(config, seed_for(config, seed, 0), path)
    except ValueError as error:  # an extension no CAN writer knows
        raise click.UsageError(str(error)) from None
    ending = f"converged at step {result.steps}" if result.steps is not None else counted(result.steps_run, "step")
    click.echo(f"captured run 0 ({ending}, {counted(result.messages, 'message')}) to {path}", err=True)


def _steps_line(s: Summary) -> str:
    if s.median is None:
        return "convergence steps: no run converged"
    return (f"convergence steps: median {s.median:g}  min {s.min}  max {s.max}  mean {s.mean:.2f}"
            f"  ({s.converged}/{s.runs} converged)")


def _bandwidth_line(s: Summary, step_seconds: float) -> str:
    return (f"bandwidth: {s.msgs_per_robot_step:.3f} msg = {s.bytes_per_robot_step:.1f} B per robot per step "
            f"({s.bytes_per_robot_step / step_seconds:.0f} B/s at {step_seconds:g} s steps); "
            f"{s.deliveries_per_robot_step:.2f} messages received per robot per step")


def _split_note(s: Summary, moving: bool = False) -> str:
    if not s.split_runs:
        return ""
    if moving:
        return (f" over the steps run; {s.split_runs} of {s.runs} runs started split into components "
                f"({s.largest_share:.0%} of robots in the largest), which motion had to join")
    return (f"; {s.split_runs} of {s.runs} layouts split into components "
            "(each robot scored on its own component's highest id; --redraw-disconnected to avoid)")


def _unconverged_note(s: Summary, max_steps: int) -> None:
    if s.converged < s.runs:
        click.echo(f"note: {s.runs - s.converged} of {counted(s.runs, 'run')} did not converge within "
                   f"{counted(max_steps, 'step')} "
                   "(raise --max-steps)", err=True)


_REPORTS = ("summary.csv", "runs.csv", "comparison.md")  # what `sim paper` and `paper-motion` write in -o DIR


@command.command()
@click.option("--runs", default=50, show_default=True, type=click.IntRange(1, MAX_RUNS),
              help=f"runs per condition (at most {MAX_RUNS:,} over all conditions)")
@click.option("-o", "--output", "output", default=Path("sim-paper"), show_default=True,
              type=click.Path(file_okay=False, path_type=Path), help="folder for the CSV, PNG and markdown")
@click.option("--robots", "sizes", multiple=True, type=click.IntRange(1, U16_MAX + 1),
              help="swarm sizes to run (repeatable) [default: 10, 100, 1000]")
@_model_options
def paper(runs: int, output: Path, sizes: tuple[int, ...], seed: int, workers: int | None, **model: Any) -> None:
    """Run the Figure 3 grid: {cluster, line, scale-free} x N {10, 100, 1000} x P {0 .. 0.95}."""
    from vstig_hw.sim.grid import markdown_table, paper_configs, write_csv
    from vstig_hw.sim.plot import plot_figure3

    template = _config("cluster", 10, 0.0, **model)
    configs = [c for c in paper_configs(template) if not sizes or c.robots in sizes]
    _bounded(runs, len(configs))
    refuse_links_in(output, (*_REPORTS, "figure3.png"))  # before the runs, which may take hours
    output.mkdir(parents=True, exist_ok=True)
    cells, wall = _run_grid("Figure 3 grid", configs, runs, seed, workers)
    write_csv(cells, output / "summary.csv", output / "runs.csv")
    plot_figure3(cells, output / "figure3.png")
    (output / "comparison.md").write_text(markdown_table(cells, runs, wall))
    _unconverged_cells(cells)
    click.echo(f"wrote {output}/summary.csv, runs.csv, figure3.png, comparison.md in {wall:.0f} s")


def _bounded(runs: int, conditions: int) -> None:
    """A grid's runs over all its conditions stay within MAX_RUNS (every result is held until the end)."""
    if runs * conditions > MAX_RUNS:
        raise click.BadParameter(f"{runs} runs x {conditions} conditions = {runs * conditions:,} runs, more than the "
                                 f"{MAX_RUNS:,} a grid holds: at most {MAX_RUNS // conditions:,} per condition",
                                 param_hint="'--runs'")


def _run_grid(title: str, configs: list[Config], runs: int, seed: int, workers: int | None) -> tuple[list[Cell], float]:
    """Every condition `runs` times, behind a progress bar; the cells and the wall time in seconds."""
    from vstig_hw.sim.grid import run_grid

    started = time.monotonic()
    with _progress() as progress:
        bar = progress.add_task(f"{title}, {counted(runs, 'run')} x {counted(len(configs), 'condition')}",
                                total=runs * len(configs))

        def done(task: Task, result: RunResult) -> None:
            progress.advance(bar)
            progress.update(bar, description=f"last: {_label(task[0])}")

        try:
            cells = run_grid(configs, runs, seed, workers, done)
        except ValueError as error:
            raise click.ClickException(str(error)) from None
    return cells, time.monotonic() - started


def _unconverged_cells(cells: list[Cell]) -> None:
    for cell in cells:
        if cell.summary.converged < cell.summary.runs:
            c = cell.config
            click.echo(f"note: {_label(c)}: {counted(cell.summary.runs - cell.summary.converged, 'run')} "
                       f"did not converge within {counted(c.max_steps, 'step')}", err=True)


def _draw_snapshot(config: Config, seed: int, step: int, path: Path) -> None:
    from vstig_hw.sim.experiment import motion_at, seed_for
    from vstig_hw.sim.graph import component_labels
    from vstig_hw.sim.plot import plot_snapshot

    if config.topology != MOTION:
        raise click.UsageError("--snapshot draws the motion arena: use it with --topology motion")
    try:
        swarm = motion_at(config, seed_for(config, seed, 0), step)
    except ValueError as error:
        raise click.ClickException(str(error)) from None
    hearing, arena = swarm.hearing, swarm.arena
    components = len(set(component_labels(hearing)))
    title = (f"D = {config.density:g}, N = {config.robots}, L = {arena.side:.1f} m, S = {config.speed * 100:g} cm/s, "
             f"step {step}\nmean degree {hearing.degrees().mean():.2f}, {components} component(s)")
    try:
        plot_snapshot(swarm.positions, hearing, arena.side, arena.columns, config.body_radius, title, path)
    except OSError as error:
        raise click.ClickException(f"cannot write {path}: {error.strerror or error}") from None
    click.echo(f"wrote {path}: step {step}, {components} component(s), mean degree {hearing.degrees().mean():.2f}")


@command.command("paper-motion")
@click.option("--runs", default=50, show_default=True, type=click.IntRange(1, MAX_RUNS),
              help=f"runs per condition (at most {MAX_RUNS:,} over all conditions)")
@click.option("-o", "--output", "output", default=Path("sim-paper-motion"), show_default=True,
              type=click.Path(file_okay=False, path_type=Path), help="folder for the CSV, PNG and markdown")
@click.option("--robots", default=100, show_default=True, type=click.IntRange(1, U16_MAX + 1), help="swarm size N")
@click.option("--densities", default="1,3,5", show_default=True, help="comma-separated densities D")
@click.option("--speeds", default="0.05,0.1,0.2", show_default=True, help="comma-separated speed caps S in m/s")
@click.option("--drops", default="0,0.25,0.5,0.75,0.95", show_default=True,
              help="comma-separated drop probabilities P")
@_model_options
@_motion_options
def paper_motion(runs: int, output: Path, robots: int, densities: str, speeds: str, drops: str, seed: int,
                 workers: int | None, **model: Any) -> None:
    """Run the Figure 5 grid: N=100 moving robots, D {1, 3, 5} x S {5, 10, 20 cm/s} x P {0 .. 0.95}."""
    from vstig_hw.sim.figure5 import MOTION_CONDITION, motion_configs, motion_markdown
    from vstig_hw.sim.grid import write_csv
    from vstig_hw.sim.plot import plot_figure5

    model.pop("density")  # the grid's densities replace it
    template = _config(MOTION, robots, 0.0, density=1.0, **model)
    grid = {name: _numbers(name, text) for name, text in
            (("--densities", densities), ("--speeds", speeds), ("--drops", drops))}
    try:
        configs = [_checked(c) for c in motion_configs(template, grid["--densities"], grid["--speeds"],
                                                        grid["--drops"])]
    except ValueError as error:
        raise click.UsageError(str(error)) from None
    _bounded(runs, len(configs))
    refuse_links_in(output, (*_REPORTS, "figure5.png"))
    output.mkdir(parents=True, exist_ok=True)
    load_before = os.getloadavg()[0]
    cells, wall = _run_grid("Figure 5 grid", configs, runs, seed, workers)
    circumstances = (f"{workers or os.cpu_count()} worker process(es) on {os.cpu_count()} cores at niceness "
                     f"{os.nice(0)}; 1-minute load average {load_before:.1f} at the start, "
                     f"{os.getloadavg()[0]:.1f} at the end.")
    write_csv(cells, output / "summary.csv", output / "runs.csv", MOTION_CONDITION)
    plot_figure5(cells, output / "figure5.png")
    (output / "comparison.md").write_text(motion_markdown(cells, runs, wall, circumstances))
    _unconverged_cells(cells)
    click.echo(f"wrote {output}/summary.csv, runs.csv, figure5.png, comparison.md in {wall:.0f} s")


def _numbers(option: str, text: str) -> list[float]:
    try:
        values = [finite(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise click.BadParameter(f"{text!r} is not a comma-separated list of finite numbers",
                                 param_hint=option) from None
    if not values:
        raise click.BadParameter("needs at least one number", param_hint=option)
    return values


def _checked(config: Config) -> Config:
    """A grid condition built by dataclasses.replace, validated as the constructor would."""
    config.__post_init__()
    return config
