"""`vstig keys`: a new swarm key (mode 600, never overwritten), robot keys as the vectors give them, and the C
form that libvstig really takes (compiled and run against the vectors)."""

from __future__ import annotations

import json
import stat
import subprocess
from pathlib import Path

import pytest
from click.testing import CliRunner
from required import require_tool

from vstig_cli.main import cli
from vstig_hw.auth import read_swarm_key

ROOT = Path(__file__).resolve().parents[2]
LIBVSTIG = ROOT / "firmware_spec" / "libvstig"
VECTORS = json.loads((ROOT / "firmware_spec" / "vectors" / "auth.json").read_text(encoding="utf-8"))


def invoke(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(cli, list(args))
    return result.exit_code, result.output


def _vector_master(tmp_path: Path) -> Path:
    path = tmp_path / "swarm.key"
    path.write_text(VECTORS["master"] + "\n", encoding="ascii")
    path.chmod(0o600)
    return path


def test_new_writes_a_private_key_once(tmp_path: Path) -> None:
    path = tmp_path / "swarm.key"
    code, output = invoke("keys", "--new", str(path))
    assert code == 0, output
    assert stat.S_IMODE(path.stat().st_mode) == 0o600 and len(read_swarm_key(path)) == 32
    before = path.read_bytes()
    code, output = invoke("keys", "--new", str(path))
    assert code == 1 and "already exists" in output and path.read_bytes() == before


def test_robot_keys_are_the_vectors(tmp_path: Path) -> None:
    robots = [case["robot"] for case in VECTORS["robot_keys"]]
    code, output = invoke("keys", "--swarm-key", str(_vector_master(tmp_path)), *map(str, robots))
    assert code == 0, output
    assert output.splitlines() == [f"{case['robot']} {case['key']}" for case in VECTORS["robot_keys"]]


def test_the_c_form_is_what_libvstig_takes(tmp_path: Path) -> None:
    gcc = require_tool("gcc")
    case = VECTORS["tags"][0]
    code, initializer = invoke("keys", "--swarm-key", str(_vector_master(tmp_path)), str(case["signer"]),
                               "--format", "c")
    assert code == 0, initializer
    message = ", ".join(f"0x{byte:02x}" for byte in bytes.fromhex(case["message"]))
    program = tmp_path / "robot.c"
    program.write_text(f"""#include <stdio.h>
#include "vstig_auth.h"
{initializer}
int main(void) {{
    static const uint8_t msg[8] = {{{message}}};
    uint8_t tag[VSTIG_TAG_SIZE], i;
    vstig_tag_key_t ready;
    vstig_tag_key_init(&ready, vstig_own_key);
    vstig_tag(&ready, {case['stigmergy']}, msg, {case['epoch']}ul, tag);
    for (i = 0; i < VSTIG_TAG_SIZE; i++) printf("%02x", tag[i]);
    return 0;
}}
""", encoding="utf-8")
    exe = tmp_path / "robot"
    subprocess.run([gcc, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-I", str(LIBVSTIG), "-o", str(exe),
                    str(program), str(LIBVSTIG / "vstig_auth.c")], check=True, timeout=120)
    assert subprocess.run([exe], capture_output=True, text=True, timeout=30, check=True).stdout == case["tag"]


@pytest.mark.parametrize(
    ("args", "says"),
    [
        ([], "give --swarm-key FILE"),
        (["1"], "give --swarm-key FILE"),
        (["--swarm-key", "{key}"], "name the ROBOT ids"),
        (["--swarm-key", "{key}", "65536"], "65536 is not in the range"),
        (["--swarm-key", "{key}", "--new", "{dir}/other.key"], "--new FILE makes a swarm key"),
        (["--swarm-key", "{dir}/absent.key", "1"], "absent.key: cannot read the swarm key file"),
    ],
)
def test_usage_errors_exit_2_naming_the_input(tmp_path: Path, args: list[str], says: str) -> None:
    key = _vector_master(tmp_path)
    code, output = invoke("keys", *(a.format(key=key, dir=tmp_path) for a in args))
    assert code == 2 and says in output and "Traceback" not in output, output


def test_a_key_others_may_read_is_refused(tmp_path: Path) -> None:
    key = _vector_master(tmp_path)
    key.chmod(0o644)
    code, output = invoke("keys", "--swarm-key", str(key), "1")
    assert code == 2 and "readable or writable by others (mode 644): chmod 600" in output
