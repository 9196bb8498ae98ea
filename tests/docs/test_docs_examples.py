"""Every example in the docs and the README runs, or says why not and shows a twin that does.

Python blocks run through sybil, one namespace per page, in a scratch folder. Shell blocks marked
`<!-- run -->` run under `bash -e` in a scratch folder with this environment's `vstig` first on PATH,
against python-can's virtual bus, pyserial's loop:// and ptys, and Zenoh on loopback or a unix socket;
a block with a ros2: link runs in a network namespace with only lo, on this run's ROS domain (tests/dds.py).
The README's and getting-started's run in the venv `make demo` builds, the core alone, or the core and the
extras the block installs itself (docs_venvs.py). A block still running after TIMEOUT_S fails, its processes
killed.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from pathlib import Path

import dds
import docs_venvs
import pytest
from docs_blocks import EXECUTED, ROOT, SHELL, Block, all_blocks, markdown_files, shell_script
from sybil import Example, Sybil
from sybil.parsers.markdown import CodeBlockParser, SkipParser

BLOCKS = all_blocks()
SHELL_BLOCKS = [b for b in BLOCKS if b.lang in SHELL]
RUNNABLE_SHELL = [b for b in SHELL_BLOCKS if b.runs]
TIMEOUT_S = 180


def test_the_docs_have_runnable_examples() -> None:
    assert len(RUNNABLE_SHELL) >= 10
    assert sum(b.lang == "python" and b.runs for b in BLOCKS) >= 3


@pytest.mark.parametrize("block", SHELL_BLOCKS, ids=[b.where for b in SHELL_BLOCKS])
def test_every_shell_block_says_whether_it_runs(block: Block) -> None:
    kinds = {"run", "hardware", "no-run"} & set(block.marks)
    assert len(kinds) == 1, f"{block.where}: mark it <!-- run -->, <!-- hardware: ... --> or <!-- no-run: why -->"
    if "no-run" in block.marks:
        assert block.marks["no-run"], f"{block.where}: <!-- no-run: --> needs its reason"


def test_every_hardware_example_has_a_runnable_twin_beside_it() -> None:
    for path in markdown_files():
        page = [b for b in BLOCKS if b.path == path and (b.lang in SHELL or b.lang == "python")]
        if not page:
            continue
        for block, after in zip(page, [*page[1:], None], strict=True):
            if block.lang == "python" and "skip" in block.marks:
                assert "hardware" in block.marks or _tested_by(block), \
                    f"{block.where}: a skipped Python block is marked hardware, or tested-by a test reading its page"
            if "hardware" in block.marks:
                assert after is not None and after.runs, f"{block.where}: the next example must be its runnable twin"


def _tested_by(block: Block) -> bool:
    """The test file a `tested-by` mark names exists and reads the block's page."""
    test = ROOT / block.marks.get("tested-by", "")
    return test.is_file() and test != ROOT and block.path.name in test.read_text(encoding="utf-8")


@pytest.mark.parametrize("block", RUNNABLE_SHELL, ids=[b.where for b in RUNNABLE_SHELL])
def test_shell_example_runs(block: Block, tmp_path: Path) -> None:
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
           "COLUMNS": "120", "NO_COLOR": "1"}
    if block.path in docs_venvs.FIRST_HOUR:  # what a newcomer pastes after `make demo`
        env = docs_venvs.environment(docs_venvs.venv_folder(docs_venvs.installed_extras(block.body)), env)
    command = ["bash", "-e", "-c", shell_script(block)]
    with contextlib.ExitStack() as cleanup:
        if "ros2:" in block.body:  # DDS stays on this machine: a namespace with only lo, this run's domain
            reason = dds.unavailable()
            if reason:
                if os.environ.get("VSTIG_REQUIRE_PEERS") == "1":
                    pytest.fail(f"VSTIG_REQUIRE_PEERS=1 but {reason}")
                pytest.skip(reason)
            host = dds.Host("docs")
            cleanup.callback(host.close)
            env.update(dds.environment())
            command = [*host.command(), *command]
        code, stdout, stderr = _run(command, tmp_path, env)
    output = f"{stdout[-2000:]}\n{stderr[-2000:]}"
    if code is None:
        pytest.fail(f"{block.where}: still running after {TIMEOUT_S} s (or a process it started held its output "
                    f"open):\n{output}")
    assert code == 0, f"{block.where} exited {code}:\n{output}"
    EXECUTED["shell"] += 1


def _run(command: list[str], folder: Path, env: dict[str, str]) -> tuple[int | None, str, str]:
    """`command` in a session of its own, whose every process is killed when it is done or after TIMEOUT_S (a
    background `vstig` keeps the output pipes open, so killing the shell alone would wait forever): its exit
    status (None on timeout), stdout and stderr."""
    process = subprocess.Popen(command, cwd=folder, env=env, text=True, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, start_new_session=True)
    try:
        stdout, stderr = process.communicate(timeout=TIMEOUT_S)
        code: int | None = process.returncode
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        stdout, stderr = process.communicate()
        code = None
    finally:
        with contextlib.suppress(ProcessLookupError):  # what the block left running
            os.killpg(process.pid, signal.SIGKILL)
    return code, stdout, stderr


PYTHON_PAGES = [p for p in markdown_files() if any(b.path == p and b.lang == "python" for b in BLOCKS)]


@pytest.mark.parametrize("path", PYTHON_PAGES, ids=[str(p.relative_to(ROOT)) for p in PYTHON_PAGES])
def test_python_examples_run(path: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    ran: list[int] = []

    def run(example: Example) -> None:  # sybil skips a block under <!-- skip: next --> before this is called
        source = "\n" * example.line + example.parsed  # tracebacks name the page's own line numbers
        exec(compile(source, example.path, "exec", dont_inherit=True), example.namespace)
        ran.append(example.line)

    document = Sybil(parsers=[CodeBlockParser("python", run), SkipParser()]).parse(path)
    for example in document.examples():
        example.evaluate()
    expected = sum(b.path == path and b.lang == "python" and b.runs for b in BLOCKS)
    assert len(ran) == expected, f"{path}: {len(ran)} Python blocks ran, {expected} expected"
    EXECUTED["python"] += len(ran)
