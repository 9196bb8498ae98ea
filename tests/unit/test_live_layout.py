"""The Foxglove layout in the repo is what docs/foxglove/make_layout.py builds, and names only our channels."""

from __future__ import annotations

import json
import runpy
from pathlib import Path

DOCS = Path(__file__).resolve().parents[2] / "docs" / "foxglove"


def _paths(node: object) -> list[str]:
    if isinstance(node, dict):
        return [v for k, v in node.items() if k in ("topicPath", "value") and isinstance(v, str)] + \
            [p for v in node.values() for p in _paths(v)]
    if isinstance(node, list):
        return [p for v in node for p in _paths(v)]
    return []


def test_the_layout_file_is_what_the_script_builds() -> None:
    built = runpy.run_path(str(DOCS / "make_layout.py"))["layout"]()
    assert (DOCS / "vstig-layout.json").read_text(encoding="utf-8") == built


def test_the_layout_shows_table_robots_writes_and_stats() -> None:
    paths = _paths(json.loads((DOCS / "vstig-layout.json").read_text(encoding="utf-8")))
    topics = {path.split(".")[0] for path in paths}
    assert topics == {"/vstig/table", "/vstig/robots", "/vstig/writes", "/vstig/stats"}
    fields = {path.split(".", 1)[1] for path in paths if "." in path}
    from vstig_hw.live.server import ROBOTS_SCHEMA, STATS_SCHEMA, TABLE_SCHEMA, WRITE_SCHEMA

    known = {"rows"} | set(WRITE_SCHEMA["properties"]) | {f"{part}.{name}" for part in STATS_SCHEMA["properties"]
                                                          for name in ("stored", "conflict", "sent", "throttled",
                                                                       "drop_behind")}
    assert fields <= known, fields - known
    assert set(TABLE_SCHEMA["properties"]) >= {"rows"} and set(ROBOTS_SCHEMA["properties"]) >= {"rows"}
