"""Writes vstig-layout.json beside this file: the Foxglove layout for `--foxglove` (docs/how-to/live-view.md).

Built with foxglove-sdk's own layout types (the live extra), so the file is what Foxglove expects;
tests/unit/test_live_layout.py checks that the committed file is what this writes.
Run: python docs/foxglove/make_layout.py
"""

from __future__ import annotations

import json
from pathlib import Path

import foxglove.layouts as fl

HERE = Path(__file__).parent


def layout() -> str:
    table = fl.TablePanel(title="keys (what sniff shows)", config=fl.TableConfig(topic_path="/vstig/table.rows"))
    robots = fl.TablePanel(title="robots: alive, quiet, gone, behind (what sniff --robots shows)",
                           config=fl.TableConfig(topic_path="/vstig/robots.rows"))
    spread = fl.PlotPanel(title="each write: seconds until every active sender had it", config=fl.PlotConfig(
        paths=[fl.PlotSeries(value="/vstig/writes.converged_after", label="converged after (s)", show_line=False),
               fl.PlotSeries(value="/vstig/writes.time_so_far", label="time so far (s)", show_line=False)]))
    writes = fl.RawMessagesPanel(title="writes as they spread",
                                 config=fl.RawMessagesConfig(topic_path="/vstig/writes"))
    counters = fl.PlotPanel(title="engine outcomes and the live view", config=fl.PlotConfig(paths=[
        fl.PlotSeries(value="/vstig/stats.engine.stored", label="stored"),
        fl.PlotSeries(value="/vstig/stats.engine.conflict", label="conflicts"),
        fl.PlotSeries(value="/vstig/stats.live.sent", label="sent to viewers"),
        fl.PlotSeries(value="/vstig/stats.live.throttled", label="throttled"),
        fl.PlotSeries(value="/vstig/stats.live.drop_behind", label="dropped (viewer behind)")]))
    stats = fl.RawMessagesPanel(title="link and engine counters",
                                config=fl.RawMessagesConfig(topic_path="/vstig/stats"))
    right = fl.SplitContainer(direction="column", items=[
        fl.SplitItem(content=spread), fl.SplitItem(content=writes), fl.SplitItem(content=counters),
        fl.SplitItem(content=stats)])
    left = fl.SplitContainer(direction="column", items=[fl.SplitItem(proportion=3, content=table),
                                                        fl.SplitItem(proportion=2, content=robots)])
    content = fl.SplitContainer(direction="row", items=[fl.SplitItem(proportion=3, content=left),
                                                         fl.SplitItem(proportion=2, content=right)])
    return json.dumps(json.loads(fl.Layout(content=content).to_json()), indent=2) + "\n"  # readable diffs


if __name__ == "__main__":
    (HERE / "vstig-layout.json").write_text(layout(), encoding="utf-8")
