"""The fenced blocks of the docs' Markdown, with the HTML-comment marks written just above them.

A shell block (sh, console, bash) carries exactly one mark:
- `<!-- run -->`: `make test` runs it (python-can's virtual bus, ptys, Zenoh on loopback);
- `<!-- hardware: ... -->`: it needs real hardware, and the next example block on the page is its
  runnable virtual twin;
- `<!-- no-run: REASON -->`: shown only (an install from the package index, a half-hour grid...).
Python blocks all run (sybil), except one under `<!-- skip: next -->`, which must be marked hardware too,
or `<!-- tested-by: TEST FILE -->` when a test of its own runs it (e.g. against robots in another process).
"""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SHELL = {"sh", "console", "bash", "shell"}
EXECUTED: Counter[str] = Counter()  # examples run in this session, by kind: printed by conftest.py
_MARK = re.compile(r"^<!--\s*(?P<mark>[a-z-]+)(?::\s*(?P<note>.*?))?\s*-->$")


@dataclass(frozen=True)
class Block:
    path: Path
    line: int              # 1-based line of the opening fence
    lang: str
    body: str
    marks: dict[str, str]  # mark -> note ("" when none)

    @property
    def where(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"

    @property
    def runs(self) -> bool:
        if self.lang in SHELL:
            return "run" in self.marks
        return self.lang == "python" and "skip" not in self.marks


def markdown_files() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def blocks(path: Path) -> list[Block]:
    lines = path.read_text(encoding="utf-8").splitlines()
    found: list[Block] = []
    i = 0
    while i < len(lines):
        opening = re.match(r"^(`{3,})\s*([\w+-]*)", lines[i])
        if not opening:
            i += 1
            continue
        fence, lang = opening[1], opening[2].lower()
        marks: dict[str, str] = {}
        above = i - 1
        while above >= 0 and (mark := _MARK.match(lines[above].strip())):
            marks[mark["mark"]] = mark["note"] or ""
            above -= 1
        end = i + 1
        while end < len(lines) and not lines[end].startswith(fence):
            end += 1
        found.append(Block(path, i + 1, lang, "\n".join(lines[i + 1:end]) + "\n", marks))
        i = end + 1
    return found


def all_blocks() -> list[Block]:
    return [block for path in markdown_files() for block in blocks(path)]


def shell_script(block: Block) -> str:
    """A console block's `$ ` lines are its commands (the rest is output); an sh block is all script."""
    if block.lang != "console":
        return block.body
    return "\n".join(line[2:] for line in block.body.splitlines() if line.startswith("$ ")) + "\n"
