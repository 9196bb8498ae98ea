"""Several captures on one clock: each one's shift onto the first's, from their clock notes (analyze, why)."""

from __future__ import annotations

import click

from vstig_hw.capture.clock_notes import CaptureClock, Shift, disputed, read_clock_notes, shifts
from vstig_hw.capture.notes import keeps_notes

__all__ = ["on_one_clock"]


def on_one_clock(names: dict[str, str], trust: bool) -> list[Shift | None]:
    """Several captures whose clock notes join them: each one's shift onto the first's clock, said on stderr
    (nothing when no capture names its clock: they merge on their own clocks, as before); `trust`: through
    unproved offsets too."""
    if len(names) < 2:
        return []
    clocks = [read_clock_notes(path) if keeps_notes(path) else CaptureClock(None, []) for path in names]
    if not any(clock.clock for clock in clocks):
        return []
    found = shifts(clocks, trust_unproved=trust)
    first, *others = names.values()
    if not trust:
        for clock, proofs in sorted(disputed(clocks).items()):
            click.echo(f"clock {clock}: answered for by more than one certificate ({', '.join(proofs)}): "
                       "its offsets are not used", err=True)
    unproved = 0 if trust else sum(trip.proof is None for clock in clocks for trip in clock.offsets)
    for name, shift in zip(others, found[1:], strict=True):
        if shift is None:
            why = (f"no proved clock offset joins it to {first}'s ({unproved} unproved not used: "
                   "--trust-clock-notes uses them)") if unproved else f"no clock offset to {first}'s was measured"
            click.echo(f"{name}: {why}: merged on its own clock", err=True)
        else:
            click.echo(f"{name}: on {first}'s clock: {-shift.seconds * 1e3:+.3f} ms "
                       f"(± {shift.error * 1e3:.3f} ms)", err=True)
    return found
