"""mkdocs hooks: pages that show a file kept elsewhere in the repository, so it is never copied by hand.

A line `{{ include PATH }}` or `{{ include PATH#section-slug }}` on a page is replaced at build time by that
file (or by its `## ` section whose heading slugifies to the slug), headings one level deeper, and links into
other files turned into their text with the file named (they point outside the site, which strict mode
would refuse). A missing file or section fails the build.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

ROOT = Path(__file__).parent
_INCLUDE = re.compile(r"^\{\{ include (?P<path>[^#\s]+)(?:#(?P<section>\S+))? \}\}$", re.M)
_LINK = re.compile(r"\[(?P<text>[^\]]+)\]\((?P<target>[^)\s]+)\)")


def _slug(heading: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", heading.lower()).strip("-")


def _section(text: str, slug: str, path: str) -> str:
    parts = re.split(r"^(?=## )", text, flags=re.M)
    for part in parts:
        if part.startswith("## ") and _slug(part.splitlines()[0][3:]) == slug:
            return part.split("\n", 1)[1]
    raise ValueError(f"{path} has no section '{slug}'")


def _unlink(match: re.Match[str], path: str) -> str:
    target = match["target"]
    if target.startswith(("http://", "https://")):
        return match[0]
    return f"{match['text']} (in `{path}`)" if not target.startswith("#") else match["text"]


def include(markdown: str) -> str:
    def replace(match: re.Match[str]) -> str:
        path = match["path"]
        text = (ROOT / path).read_text(encoding="utf-8")
        if match["section"]:
            text = _section(text, match["section"], path)
        text = re.sub(r"^(#+) ", r"#\1 ", text, flags=re.M)
        return _LINK.sub(lambda m: _unlink(m, path), text)

    return _INCLUDE.sub(replace, markdown)


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    return include(markdown)
