"""What a capture says about itself beside its records (clock_notes, decision_notes), read from any format
that keeps notes: our line captures as comment lines, MCAP as metadata records (capture.rosbag). Each note
comes back as the comment line a line capture holds (`# vstig ...`), so every note's parser reads lines."""

from __future__ import annotations

from collections.abc import Iterator

from .records import MCAP_EXTENSION, capture_suffix, line_capture_at

__all__ = ["capture_notes", "keeps_notes"]


def keeps_notes(path: str) -> bool:
    """Whether the capture at `path` is of a format that keeps notes (a line capture, any name; .mcap)."""
    return capture_suffix(path) == MCAP_EXTENSION or line_capture_at(path) is not None


def capture_notes(path: str) -> Iterator[str]:
    """Every `# vstig ...` note the capture at `path` holds, in file order (none for a format without notes)."""
    if capture_suffix(path) == MCAP_EXTENSION:
        from .rosbag import read_mcap_notes

        yield from read_mcap_notes(path)
    elif line_capture_at(path) is not None:
        with open(path, encoding="utf-8", errors="replace") as file:
            yield from (line for line in file if line.startswith("# vstig "))
