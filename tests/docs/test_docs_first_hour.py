"""What a newcomer pastes in the first hour works, or says why not.

The README's and getting-started's blocks run in the venv `make demo` builds (test_docs_examples.py, through
docs_venvs.py): these check that venv holds the core alone, that every wait loop in the docs ends when the process
it waits for dies (instead of hanging a shell), that no background process's errors are thrown away, that the two
pages list the same extras, and that a Python block headed as a recipe of its own runs on its own.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import docs_venvs
import pytest
from docs_blocks import ROOT, SHELL, all_blocks, blocks

from vstig_hw.extras import EXTRAS

RUNNABLE_SHELL = [b for b in all_blocks() if b.lang in SHELL and b.runs]
_WAIT_LOOP = re.compile(r"^\s*(until|while)\b")
_BACKGROUND = re.compile(r"&\s*(?:\w+=\$!)?\s*(?:#.*)?$")  # `cmd &`, `cmd & pid=$!`, either with a comment


def test_every_wait_loop_ends_when_the_process_it_waits_for_dies() -> None:
    loops = [(b.where, line) for b in RUNNABLE_SHELL for line in b.body.splitlines() if _WAIT_LOOP.match(line)]
    assert len(loops) >= 5  # the README's, and the gateways the how-to pages start
    for where, line in loops:
        assert "kill -0" in line, f"{where}: `{line.strip()}` waits forever if the process dies: add || ! kill -0 PID"


def test_no_background_process_throws_its_errors_away() -> None:
    background = [(b.where, line) for b in RUNNABLE_SHELL for line in b.body.splitlines()
                  if _BACKGROUND.search(line) and not line.rstrip().endswith("&&")]
    assert len(background) >= 5
    for where, line in background:
        assert not re.search(r"(2|&)>\s*/dev/null", line.split("#")[0]), \
            f"{where}: a background process whose failure would go unseen: `{line.strip()}`"


def _extras_lines(path: Path) -> list[str]:
    (listing,) = [b for b in blocks(path) if "pip install 'vstig-hw[all]'" in b.body]
    return listing.body.splitlines()


def test_the_readme_and_getting_started_list_the_same_extras_and_every_one() -> None:
    readme, getting_started = (_extras_lines(path) for path in docs_venvs.FIRST_HOUR)
    assert readme == getting_started
    listed = {found[1] for line in readme if (found := re.match(r"pip install 'vstig-hw\[(\w+)\]'", line))}
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert listed == set(extras) - {"test", "fuzz"}  # the project's own tools are `make test`'s and `make fuzz`'s


def _importable(folder: Path, modules: list[str]) -> set[str]:
    script = "import importlib.util as u, json, sys; print(json.dumps([m for m in sys.argv[1:] if u.find_spec(m)]))"
    done = subprocess.run([str(folder / "bin" / "python"), "-c", script, *modules], capture_output=True, text=True,
                          timeout=60, check=True)
    return set(json.loads(done.stdout))


@pytest.mark.slow
@pytest.mark.parametrize("extras", [(), ("zenoh",)], ids=["core", "zenoh"])
def test_the_first_hour_venv_holds_the_core_and_only_the_extras_asked_for(extras: tuple[str, ...]) -> None:
    folder = docs_venvs.venv_folder(extras)
    every = sorted({module for modules in EXTRAS.values() for module in modules})
    wanted = {module for extra in extras for module in EXTRAS[extra]}
    assert _importable(folder, [*every, "vstig_hw", "vstig_cli", "pytest"]) == {"vstig_hw", "vstig_cli", *wanted}
    shown = subprocess.run(["bash", "-c", "command -v vstig python pip"], capture_output=True, text=True, timeout=30,
                           env=docs_venvs.environment(folder, {"PATH": f"{Path(sys.executable).parent}:/usr/bin:/bin"}),
                           check=True)
    assert shown.stdout.split() == [str(folder / "bin" / name) for name in ("vstig", "python", "pip")]


def test_a_block_that_installs_an_extra_runs_with_it() -> None:
    assert docs_venvs.installed_extras("vstig demo\npip install 'vstig-hw[zenoh]'   # one line\n") == ("zenoh",)
    assert docs_venvs.installed_extras("pip install -e '.[mcap,zenoh]'\n") == ("mcap", "zenoh")
    assert docs_venvs.installed_extras("echo pip install 'vstig-hw[sim]'\npip install vstig-hw\n") == ()


@pytest.mark.slow
def test_the_asyncio_recipe_runs_on_its_own(tmp_path: Path) -> None:
    """Each section of python.md's reader may start there: the asyncio block brings its own robots."""
    page = (ROOT / "docs" / "how-to" / "python.md").read_text(encoding="utf-8")
    section = page.split("\n## asyncio\n", 1)[1]
    (block,) = [b for b in blocks(ROOT / "docs" / "how-to" / "python.md") if b.lang == "python" and b.body in section]
    done = subprocess.run([sys.executable, "-c", block.body], cwd=tmp_path, capture_output=True, text=True,
                          timeout=60, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.startswith("Change(key=3, old=None, new=Entry(value=1500")
