"""The built site, looked at in a real browser: headless Chromium opens pages from file:// and fails on a
console error, an uncaught exception, a resource that did not load, or a missing page.

The site is built here (strict, as `make docs`) into a scratch folder, so the test checks the tree as it is.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from browser import Browser, chromium_path
from docs_blocks import ROOT

# page -> a text its main content must hold (the page really is the one asked for, rendered)
PAGES = {
    "index.html": "virtual stigmergy",
    "getting-started.html": "The two commands",
    "reference/cli.html": "vstig bridge",
    "reference/api.html": "Stigmergy",
    "explanation/paper.html": "Figure 3",
}
CONTENT = "document.querySelector('article') ? document.querySelector('article').innerText : ''"


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("site")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
                          cwd=ROOT, capture_output=True, text=True, env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert done.returncode == 0, done.stderr[-3000:]
    return out


@pytest.fixture(scope="module")
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Browser]:
    if chromium_path() is None:
        reason = "chromium is not installed (Debian package chromium, installed by tests/sysdeps.sh as root)"
        if os.environ.get("VSTIG_REQUIRE_PEERS") == "1":
            pytest.fail(f"VSTIG_REQUIRE_PEERS=1 but {reason}")
        pytest.skip(reason)
    chromium = Browser(tmp_path_factory.mktemp("chromium-profile"))
    yield chromium
    chromium.close()


@pytest.mark.parametrize("page", sorted(PAGES))
def test_page_opens_from_disk_without_errors(site: Path, browser: Browser, page: str) -> None:
    visit = browser.visit((site / page).as_uri(), CONTENT)
    assert visit.load_error is None, f"{page}: {visit.load_error}"
    assert visit.errors == [], f"{page}: {visit.errors}"
    assert PAGES[page] in (visit.value or ""), f"{page} does not show {PAGES[page]!r}"


def test_every_picture_on_the_paper_page_loads(site: Path, browser: Browser) -> None:
    visit = browser.visit((site / "explanation/paper.html").as_uri(),
                          "Array.from(document.images).map(i => [i.src, i.complete && i.naturalWidth > 0])")
    pictures = [src for src, _ in visit.value if src.endswith(".png")]
    assert len(pictures) >= 5
    assert all(ok for _, ok in visit.value), visit.value


def test_the_browser_check_fails_on_a_missing_page_and_a_console_error(site: Path, browser: Browser,
                                                                        tmp_path: Path) -> None:
    assert browser.visit((site / "no-such-page.html").as_uri()).load_error == "net::ERR_FILE_NOT_FOUND"
    broken = tmp_path / "broken.html"
    broken.write_text('<html><body><img src="missing.png"><script>console.error("boom"); nope();</script>'
                      "</body></html>")
    errors = browser.visit(broken.as_uri()).errors
    assert any("boom" in e for e in errors), errors
    assert any("nope" in e for e in errors), errors
    assert any("missing.png" in e for e in errors), errors
