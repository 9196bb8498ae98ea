"""DECISIONS.md names only paths that exist, so a rename cannot leave it pointing at nothing.

A path is a backticked word that contains a `/` or ends in a file extension. It is looked up from the
repository's root, or from `vstig_hw/` (the sections name the package's modules from inside it, as
`links/registry.py`); a module path with an attribute (`links/grammar.split_query`) names its `.py`; a bare
file name (`decoded.py`) must be some file of the repository. What is not a repository path is left
alone: absolute paths and URLs (devices, ROS topics), options, placeholders (`<link>`). The few words
that look like paths and are not files of ours are listed below with what they are.
"""

from __future__ import annotations

import glob
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DECISIONS = ROOT / "DECISIONS.md"
FROM = (ROOT, ROOT / "vstig_hw")
EXTENSION = re.compile(r"\.(py|pyi|c|h|md|toml|json|lua|ya?ml|txt|cfg|ini|sh|idl|xml|service|dbc|html|js|css|so)$")

NOT_OURS = {
    # a kind of file, not a file
    ".pyi",
    # another project's file (h11's), cited as a model
    "_state.py",
    # Zenoh configuration keys and an endpoint
    "transport/link/rx/max_message_size", "transport/shared_memory/enabled", "transport/unicast/max_sessions",
    "tcp/0.0.0.0",
    # the libraries a ROS 2 wheel brings
    "site-packages/ros_*.libs",
    # what `mkdocs build` makes (`make docs`), not kept in the tree
    "site/index.html",
}


def named_paths(text: str) -> dict[str, int]:
    """Each path-like backticked word and the first line it is on."""
    named: dict[str, int] = {}
    for number, line in enumerate(text.splitlines(), 1):
        for word in re.findall(r"`([^`\s]+)`", line):
            if word.startswith(("/", "~", "-", "$")) or "://" in word or "<" in word or word in NOT_OURS:
                continue
            if "/" in word or EXTENSION.search(word):
                named.setdefault(word, number)
    return named


def repository_files() -> set[str]:
    listed = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                            capture_output=True, text=True, check=True).stdout.split()
    return {Path(name).name for name in listed}


def spellings(word: str) -> list[str]:
    """The paths a word may mean: braces expanded (`vstig_wire.{h,c}`), a module's attribute dropped."""
    word = re.sub(r":\d+(-\d+)?$", "", word.split("::")[0])  # path:line, path::test
    ros_type = re.fullmatch(r"vstig_msgs/(?:msg/|srv/)?(\w+)", word)
    if ros_type:  # a ROS 2 type of ours names its interface file
        return [f"vstig_hw/ros2msgs/*/{ros_type[1]}.idl"]
    braces = re.fullmatch(r"(.*)\{([^}]*)\}(.*)", word)
    words = [braces[1] + part + braces[3] for part in braces[2].split(",")] if braces else [word]
    return [w for word in words for w in (word, re.sub(r"\.[A-Za-z_]\w*$", ".py", word))]


def exists(word: str, files: set[str]) -> bool:
    for spelling in spellings(word):
        if "/" not in spelling.rstrip("/") and spelling in files:
            return True
        if any(glob.glob(str(base / spelling)) for base in FROM):
            return True
    return False


def test_every_path_named_exists() -> None:
    files = repository_files()
    missing = [f"line {line}: {word}" for word, line in named_paths(DECISIONS.read_text()).items()
               if not exists(word, files)]
    assert not missing, "DECISIONS.md names paths that do not exist:\n" + "\n".join(missing)


@pytest.mark.parametrize("text, found", [
    ("see `vstig_hw/gone.py` and `cli/options.py`", {"vstig_hw/gone.py", "cli/options.py"}),
    ("`/dev/ttyUSB0`, `socket://host:1`, `--skip-bad`, `heard/<link>` and `a b.py`", set()),
])
def test_what_counts_as_a_path(text: str, found: set[str]) -> None:
    assert set(named_paths(text)) == found


def test_a_missing_path_is_caught() -> None:
    files = repository_files()
    assert exists("links/grammar.split_query", files) and exists("decoded.py", files)
    assert not exists("vstig_hw/gateway/nowhere.py", files) and not exists("nowhere.py", files)
    assert not exists("firmware_spec/c/vstig_wire.{h,c}", files)


def slug(heading: str) -> str:
    """The anchor GitHub and mkdocs give a heading: lower case, punctuation dropped, spaces as hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_every_link_within_the_file_finds_its_section() -> None:
    text = DECISIONS.read_text()
    anchors = {slug(heading) for heading in re.findall(r"^#+ (.+)$", text, flags=re.MULTILINE)}
    broken = sorted(set(re.findall(r"\]\(#([^)]+)\)", text)) - anchors)
    assert not broken, f"DECISIONS.md links to sections it does not have: {broken}"


def test_slug_is_the_anchor() -> None:
    assert slug("The data path: no `link` can stall (issue 25)") == "the-data-path-no-link-can-stall-issue-25"
