"""SPEC.md holds together: its links and anchors resolve, the files it names exist, and its
drop-reason table names exactly the reasons the code, the C codec and the vectors count."""

from __future__ import annotations

import json
import re
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
from conftest import C_DIR, ROOT, SPEC, VECTORS

DOCS = [SPEC / "SPEC.md", SPEC / "DECISIONS.md", VECTORS / "README.md"]
_LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
_FENCE = re.compile(r"^\s*```")


def _prose_lines(path: Path) -> list[str]:
    """The file's lines outside fenced code blocks (a `# ...` inside a fence is no heading)."""
    lines, fenced = [], False
    for line in path.read_text(encoding="utf-8").splitlines():
        if _FENCE.match(line):
            fenced = not fenced
        elif not fenced:
            lines.append(line)
    return lines


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation but '-' and '_' dropped, spaces to '-'."""
    text = re.sub(r"[^\w\- ]", "", heading.replace("`", "").strip().lower())
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    seen: Counter[str] = Counter()
    out = set()
    for line in _prose_lines(path):
        match = re.match(r"#{1,6} (.+)", line)
        if match:
            slug = _slug(match.group(1))
            out.add(slug if not seen[slug] else f"{slug}-{seen[slug]}")
            seen[slug] += 1
    return out


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_every_link_and_anchor_resolves(doc: Path) -> None:
    targets = [m.group(1) for line in _prose_lines(doc) for m in _LINK.finditer(line)]
    assert targets or doc.name == "README.md", f"{doc.name} has no links to check"
    for target in targets:
        if re.match(r"[a-z]+://", target):
            continue
        file_part, _, anchor = target.partition("#")
        path = (doc.parent / file_part).resolve() if file_part else doc
        assert path.exists(), f"{doc.name} links to missing {file_part}"
        if anchor:
            assert anchor in anchors(path), f"{doc.name} links to #{anchor}, not a heading of {path.name}"


def test_the_table_of_contents_covers_every_numbered_section() -> None:
    lines = _prose_lines(SPEC / "SPEC.md")
    start = lines.index("## Contents")
    end = next(i for i in range(start + 1, len(lines)) if lines[i].startswith("## "))
    listed = {m.group(1).lstrip("#") for line in lines[start:end] for m in _LINK.finditer(line)}
    numbered = {_slug(line.lstrip("#")) for line in lines if re.match(r"#{2,4} \d", line)}
    assert numbered - listed == set(), "sections missing from the contents"


def test_files_the_documents_name_exist() -> None:
    # Paths with a folder are ours; bare names may be kilolib's (`ohc.c`, `message.h`).
    named = re.compile(r"`((?:[\w.-]+/)+[\w.-]+\.(?:json|md|c|h|py|lua|dbc))`")
    for doc in [*DOCS, ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]:
        for name in named.findall(doc.read_text(encoding="utf-8")):
            candidates = [doc.parent / name, SPEC / name, ROOT / name, ROOT / "vstig_hw" / name]
            assert any(p.exists() for p in candidates), f"{doc.name} names {name}, which does not exist"


def _spec_drop_table() -> set[str]:
    text = (SPEC / "SPEC.md").read_text(encoding="utf-8")
    section = text.split("### 6.6 Drop reasons", 1)[1].split("\n### ", 1)[0]
    rows = [line.split("|") for line in section.splitlines() if line.startswith("| ")]
    return {cells[3].strip().strip("`") for cells in rows[1:]}  # link | order | `name` | ...


def _vector_reasons(node: Any) -> set[str]:
    found: set[str] = set()
    if isinstance(node, dict):
        for key, value in node.items():
            if key == "drops" and isinstance(value, dict):
                found |= set(value)
            elif key in ("drop", "reason") and isinstance(value, str):
                found.add(value)
            else:
                found |= _vector_reasons(value)
    elif isinstance(node, list):
        for item in node:
            found |= _vector_reasons(item)
    return found


def test_drop_table_names_exactly_what_code_c_and_vectors_count() -> None:
    table = _spec_drop_table()
    python = {name for path in (ROOT / "vstig_hw" / "framing").glob("*.py")
              for name in re.findall(r'drops\["(\w+)"\]', path.read_text(encoding="utf-8"))}
    c_source = (C_DIR / "vstig_wire.c").read_text(encoding="utf-8")
    c_names = set(re.findall(r'"(\w+)"', c_source.split("drop_names[", 1)[1].split("};", 1)[0]))
    vectors = set().union(*(_vector_reasons(json.loads(p.read_text(encoding="utf-8")))
                            for p in VECTORS.glob("*.json")))
    assert python and c_names and vectors, "found no drop reasons to compare"
    for where, names in (("vstig_hw/framing", python), ("libvstig/vstig_wire.c", c_names), ("vectors", vectors)):
        assert names - table == set(), f"{where} counts reasons SPEC.md 6.6 does not list"
    assert table - (python | c_names | vectors) == set(), "SPEC.md 6.6 lists reasons nothing counts"
