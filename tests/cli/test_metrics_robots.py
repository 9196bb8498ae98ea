"""`--metrics` shows the roster: robots per link and state, never one series per robot, and the state changes,
scraped over real HTTP from a real `vstig bridge` between two pty robots, one of which goes silent."""

from __future__ import annotations

import re
import time
import urllib.request
from pathlib import Path

from peers import start_vstig, stop, wait_for
from ports import free_port
from robots import PtyRobot


def _scrape(port: int) -> str:
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=5) as answer:  # loopback only
            return bytes(answer.read()).decode()
    except OSError:  # not up yet
        return ""


def _series(page: str, name: str) -> dict[str, float]:
    """{labels: value} of the metric `name` on a scraped page."""
    return {labels: float(value) for labels, value in re.findall(rf"^{name}\{{(.*?)\}} (\S+)$", page, re.M)}


def test_robots_per_link_and_state_and_the_changes_are_scraped() -> None:
    talker, silent = PtyRobot(5), PtyRobot(6)
    port = free_port()
    gateway = start_vstig("bridge", talker.spec, silent.spec, "--robot-id", "200", "--metrics", str(port),
                          "--no-refresh", "--quiet-after", "0.3", "--gone-after", "1")
    talker_link, silent_link = Path(talker.radio.path).name, Path(silent.radio.path).name
    step = 0

    def both_talk() -> None:
        nonlocal step
        step += 1
        talker.put(105, step)
        silent.put(106, step)
        time.sleep(0.1)

    try:
        wait_for(lambda: _series(_scrape(port), "vstig_robots").get(
            f'link="{silent_link}",state="alive"') == 1.0, 30, both_talk)
        page = _scrape(port)
        robots = _series(page, "vstig_robots")
        assert len(robots) == 6, robots  # two links, three states each: never a series per robot

        def talker_alone() -> None:
            nonlocal step
            step += 1
            talker.put(105, step)
            time.sleep(0.1)

        wait_for(lambda: _series(_scrape(port), "vstig_robots").get(f'link="{silent_link}",state="gone"') == 1.0,
                 20, talker_alone)
        page = _scrape(port)
    finally:
        _, stderr = stop(gateway)
        talker.close()
        silent.close()
    robots = _series(page, "vstig_robots")
    assert robots[f'link="{talker_link}",state="alive"'] == 1.0 and robots[f'link="{silent_link}",state="alive"'] == 0
    changes = _series(page, "vstig_robot_state_changes_total")
    assert changes == {'from="alive",to="quiet"': 1.0, 'from="quiet",to="gone"': 1.0}, changes
    assert re.search(r"^vstig_robots_untracked_total 0\.0$", page, re.M), page
    assert "Traceback" not in stderr
