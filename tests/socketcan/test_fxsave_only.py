"""fxsave_only.py refuses exactly the XSAVE ptrace requests, to the command it runs and that command's children."""

from __future__ import annotations

import errno
import platform
import subprocess
import sys
from pathlib import Path

import pytest

LAUNCHER = Path(__file__).with_name("fxsave_only.py")

pytestmark = pytest.mark.skipif(platform.system() != "Linux" or platform.machine() != "x86_64",
                                reason="the filter is for User-Mode Linux on x86_64 Linux")

# ptrace(GETREGSET|SETREGSET, pid 1, NOTE, NULL) from a process that does not trace pid 1: the kernel answers ESRCH,
# unless the filter answered first. Printed: the errno of each (request, note) in order, in a grandchild too.
_PROBE = """
import ctypes, os, sys
libc = ctypes.CDLL(None, use_errno=True)
def probe():
    codes = []
    for request in (0x4204, 0x4205):
        for note in (0x202, 1):  # NT_X86_XSTATE, NT_PRSTATUS
            ctypes.set_errno(0)
            libc.ptrace(request, 1, note, None)
            codes.append(ctypes.get_errno())
    return codes
pid = os.fork()
if pid == 0:
    print("child", *probe(), flush=True)
    os._exit(0)
os.waitpid(pid, 0)
print("parent", *probe(), flush=True)
"""


def _probe(*launcher: str) -> dict[str, list[int]]:
    done = subprocess.run([*launcher, sys.executable, "-c", _PROBE], capture_output=True, text=True, timeout=30,
                          check=True)
    return {line.split()[0]: [int(code) for code in line.split()[1:]] for line in done.stdout.splitlines()}


def test_only_the_xstate_requests_fail_with_eio_in_the_command_and_its_children() -> None:
    plain = _probe()
    assert plain["parent"] == [errno.ESRCH] * 4  # the probe asks about a process it does not trace
    filtered = _probe(sys.executable, str(LAUNCHER))
    expected = [errno.EIO, errno.ESRCH, errno.EIO, errno.ESRCH]  # XSTATE refused, PRSTATUS reaches the kernel
    assert filtered == {"parent": expected, "child": expected}


def test_without_a_command_it_says_how_to_use_it() -> None:
    done = subprocess.run([sys.executable, str(LAUNCHER)], capture_output=True, text=True, timeout=30, check=False)
    assert done.returncode == 2 and "usage: fxsave_only.py COMMAND" in done.stderr
