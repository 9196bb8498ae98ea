"""Every section of the one-page README lives on a docs page.

The README was one 1,161-line file; it is now the front door (at most 200 lines) and the docs site. The old
text comes from git (the commit named in readme_sections.toml); each of its headings must be mapped to pages,
and nearly every sentence of its section must be on one of them as they stood at the commit named there (links
may have been re-pointed and a few list items reworded into prose, so a small share may differ).
"""

from __future__ import annotations

import re
import subprocess
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
MAP = tomllib.loads((Path(__file__).parent / "readme_sections.toml").read_text(encoding="utf-8"))
LANDED = 0.9  # the share of a section's sentences that must be found verbatim (normalised)


def old_readme() -> str:
    done = subprocess.run(["git", "-C", str(ROOT), "show", f"{MAP['readme']}:README.md"],
                          capture_output=True, text=True)
    assert done.returncode == 0, f"the old README must be in git history: {done.stderr.strip()}"
    return done.stdout


def sections(text: str) -> dict[str, str]:
    """Heading -> body, for `#`, `##` and `###` headings outside fenced code."""
    found: dict[str, list[str]] = {}
    current: list[str] = []
    fenced = False
    for line in text.splitlines():
        if line.startswith("```"):
            fenced = not fenced
        heading = None if fenced else re.match(r"^#{1,3} (.+)$", line)
        if heading:
            current = found.setdefault(heading[1].strip(), [])
        else:
            current.append(line)
    return {name: "\n".join(body) for name, body in found.items()}


def normalise(text: str) -> str:
    text = re.sub(r"\]\([^)]*\)", "]", text)                # links re-pointed to pages keep their text
    text = re.sub(r"^\s*(?:[-*]|\d+\.)\s+", "", text, flags=re.M)  # list markers
    text = re.sub(r"<!--.*?-->", " ", text)
    return re.sub(r"\s+", " ", text).strip()


def sentences(body: str) -> list[str]:
    """The body's sentences, never across a paragraph or a code fence."""
    pieces = re.split(r"\n\s*\n|^```.*$", body, flags=re.M)
    return [s for piece in pieces for s in re.split(r"(?<=[.:;!?])\s+", normalise(piece)) if len(s) >= 25]


def page_text(pages: list[str]) -> str:
    """The pages as they stood at the commit the split was checked against (readme_sections.toml's `pages`)."""
    return normalise("\n".join(_at_split(f"docs/{page}") for page in pages))


def _at_split(path: str) -> str:
    done = subprocess.run(["git", "-C", str(ROOT), "show", f"{MAP['pages']}:{path}"], capture_output=True, text=True)
    assert done.returncode == 0, f"{path} must be in git history at {MAP['pages']}: {done.stderr.strip()}"
    return done.stdout


def test_the_readme_is_a_front_door() -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.splitlines()) <= 200
    for page in re.findall(r"\]\((docs/[^)#]+)", readme):
        assert (ROOT / page).is_file(), f"README links to a missing page {page}"


def test_every_old_heading_is_mapped_to_existing_pages() -> None:
    old = sections(old_readme())
    assert len(old) >= 15, "the old README's headings were not found"
    assert sorted(old) == sorted(MAP["sections"]), "readme_sections.toml must map exactly the old headings"
    for pages in MAP["sections"].values():
        for page in pages:
            _at_split(f"docs/{page}")  # the page existed when the split was checked


@pytest.mark.parametrize("heading", sorted(MAP["sections"]))
def test_old_section_text_landed_on_its_pages(heading: str) -> None:
    body = sections(old_readme())[heading]
    wanted = sentences(body)
    text = page_text(MAP["sections"][heading])
    missing = [s for s in wanted if s not in text]
    share = 1 - len(missing) / max(1, len(wanted))
    assert share >= LANDED, f"{heading!r}: {len(missing)} of {len(wanted)} sentences missing, e.g. {missing[:3]}"
