"""Run pytest inside User-Mode Linux, where the kernel has SocketCAN (vcan0, vcan1) and this host's has not.

The UML kernel boots with this machine's root shared read-write (hostfs), so it
sees the repo and its .venv at the same paths. PID 1 is a shell script written
here at run time: it mounts the pseudo file systems, loads vcan/can-raw/can-bcm
from the user-mode-linux package's modules, creates vcan0 (classic) and vcan1
(CAN FD, MTU 72), runs pytest, writes pytest's exit code and junit file into a
work directory on the shared file system, and powers the guest off.

The kernel runs under `fxsave_only.py`, which keeps UML 6.1 off the XSAVE
ptrace requests it cannot use on a host with AVX-512 or AMX (it would die as it
starts PID 1); the guest then keeps x87/SSE state only, so its glibc is told to
use no AVX, nor are OpenSSL and numpy (`_NO_AVX`).

A boot that dies before PID 1 runs anything (the kernel sometimes dies in its
early memory setup, exit 134) is retried up to BOOT_RETRIES times; when every try
dies, the result says so with the kernel log's last lines. Anything that ran
(setup, pytest) is never retried, so a real failure still fails.

By hand: `.venv/bin/python tests/socketcan/uml.py [pytest args]` (default: the
socketcan module); it prints pytest's output and exits with its code.
"""

from __future__ import annotations

import os
import platform
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SOCKETCAN_MODULE = "tests/socketcan/test_socketcan.py"
UML_MODULES = Path("/usr/lib/uml/modules")
# Only these reach the guest (the kernel command line cannot carry an environment).
_PASSED_ENV = ("PATH", "HOME", "LANG", "LC_ALL", "TMPDIR", "VIRTUAL_ENV", "CI")
_PASSED_PREFIXES = ("VSTIG_", "HYPOTHESIS")
_STANDARD_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
BOOT_RETRIES = 2  # extra boots after one that died before running anything
KERNEL_TAIL = 15  # kernel log lines shown when a run fails
FXSAVE_ONLY = Path(__file__).with_name("fxsave_only.py")
# The guest keeps only x87/SSE state (fxsave_only.py), and a host with AVX reloads the rest as it likes: every
# library that picks AVX code by CPUID is kept off it (glibc's string functions, OpenSSL, numpy's dispatch).
_NO_AVX = {
    "GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX,-AVX2,-AVX512F,-AVX512VL,-AVX512BW,-AVX512DQ,-AVX512CD,-FMA,"
                      "-AVX_Fast_Unaligned_Load",
    "OPENSSL_ia32cap": "~0x1000100000000000:0",  # CPUID.1 without AVX (bit 60) and FMA (bit 44); no CPUID.7 features
    "NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR",
}

_INIT = """#!/bin/sh
# PID 1 inside User-Mode Linux, written by tests/socketcan/uml.py for one run.
PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
export PATH
{no_avx}mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t tmpfs tmpfs /run
mkdir -p /dev/shm && mount -t tmpfs tmpfs /dev/shm
mkdir -p /dev/pts && mount -t devpts devpts /dev/pts
(
  set -e
  modprobe -d {moddir} vcan
  modprobe -d {moddir} can-raw
  modprobe -d {moddir} can-bcm
  ip link add dev vcan0 type vcan
  ip link add dev vcan1 type vcan
  ip link set vcan1 mtu 72
  ip link set up vcan0
  ip link set up vcan1
) > {out}/setup.log 2>&1
rc=$?
if [ $rc -eq 0 ]; then
  . {out}/env.sh
  cd {repo}
  # through cat, so pytest's output is not a TTY
  ( {pytest} ; echo $? > {out}/pytest.rc ) 2>&1 | cat > {out}/pytest.log
  rc=$(cat {out}/pytest.rc)
else
  rc=98
fi
echo $rc > {out}/status
sync  # hostfs writes back through the guest's page cache: flush before the power goes
# /proc/exitcode exists only in UML: never touch a real machine's sysrq
if [ -e /proc/exitcode ]; then
  echo $rc > /proc/exitcode
  echo o > /proc/sysrq-trigger
  while :; do sleep 1; done  # PID 1 must outlive the power-off request, or the kernel panics
fi
"""


@dataclass(frozen=True)
class UmlRun:
    """What came back from one guest: pytest's exit code (None if it never ran), its output, files."""

    exit_code: int | None
    status: str
    pytest_log: str
    setup_log: str
    kernel_log: str
    junit: Path
    seconds: float
    boots: int = 1  # how many times the kernel was started (more than 1: earlier boots died)

    def explain(self) -> str:
        tail = "\n".join(self.pytest_log.splitlines()[-40:])
        return (f"UML run: status={self.status!r} after {self.seconds:.1f}s, {self.boots} boot(s)\n"
                f"--- setup ---\n{self.setup_log}\n--- pytest ---\n{tail}\n--- kernel (tail) ---\n"
                + "\n".join(self.kernel_log.splitlines()[-KERNEL_TAIL:]))


def uml_binary() -> str | None:
    return shutil.which("linux.uml") or ("/usr/bin/linux.uml" if os.access("/usr/bin/linux.uml", os.X_OK) else None)


def unavailable_reason() -> str | None:
    """Why a UML run cannot happen here, or None when it can."""
    if platform.system() != "Linux":
        return "User-Mode Linux needs a Linux host"
    if uml_binary() is None:
        return "User-Mode Linux is not installed (apt-get install user-mode-linux; tests/sysdeps.sh does it as root)"
    if not any(UML_MODULES.glob("*/kernel/drivers/net/can/vcan.ko")):
        return f"no vcan.ko under {UML_MODULES} (the user-mode-linux package ships it)"
    search = os.pathsep.join([os.environ.get("PATH", ""), "/usr/sbin", "/sbin", "/usr/bin"])  # as the guest's
    for tool in ("modprobe", "ip", "cansend", "candump"):
        if shutil.which(tool, path=search) is None:
            return f"`{tool}` is missing (apt-get install kmod iproute2 can-utils)"
    if not os.access("/dev/shm", os.W_OK):
        return "/dev/shm is not writable: UML keeps the guest's memory there"
    return None


def _env_script() -> str:
    env = {k: v for k, v in os.environ.items() if k in _PASSED_ENV or k.startswith(_PASSED_PREFIXES)}
    env.update(_NO_AVX)
    env.update(VSTIG_IN_UML="1", PYTHONDONTWRITEBYTECODE="1", PYTHONUNBUFFERED="1",
               PATH=os.pathsep.join([env.get("PATH", ""), _STANDARD_PATH]))
    return _exports(dict(sorted(env.items())))


def _exports(env: dict[str, str]) -> str:
    return "".join(f"export {k}={shlex.quote(v)}\n" for k, v in env.items())


def run(pytest_args: list[str], workdir: Path, *, timeout: float = 900.0, mem: str = "1G",
        program: list[str] | None = None, binary: str | None = None) -> UmlRun:
    """Boot UML, run `python -m pytest ARGS` in the repo inside it, and collect the result from `workdir`.

    `program` runs that command instead of pytest (benchmarks do): its output is `pytest_log`, its
    exit code `exit_code`. `binary` is the kernel to boot (default: the installed linux.uml).
    """
    uml = binary or uml_binary()
    if uml is None:
        raise RuntimeError(unavailable_reason())
    workdir = workdir.resolve()
    moddir = workdir / "modroot"
    (moddir / "lib").mkdir(parents=True, exist_ok=True)
    (moddir / "lib" / "modules").symlink_to(UML_MODULES)
    junit = workdir / "junit.xml"
    pytest = program or [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", f"--junitxml={junit}",
                         *pytest_args]
    (workdir / "env.sh").write_text(_env_script())
    init = workdir / "init.sh"
    init.write_text(_INIT.format(no_avx=_exports(_NO_AVX), moddir=moddir, out=workdir, repo=shlex.quote(str(REPO)),
                                 pytest=shlex.join(pytest)))
    init.chmod(0o755)
    if any(c.isspace() for c in str(init)):
        raise RuntimeError(f"the UML kernel command line cannot carry spaces: {init}")
    command = [sys.executable, str(FXSAVE_ONLY), uml, f"mem={mem}", "root=/dev/root", "rootfstype=hostfs", "rw",
               f"init={init}", f"uml_dir={workdir / 'uml'}", "umid=vstig", "con=null", "con0=null,fd:1", "ssl=null"]
    started = time.monotonic()
    boots = 0
    while True:
        boots += 1
        exit_code = _boot(command, workdir, timeout)
        died_at_boot = exit_code is not None and not (workdir / "setup.log").exists()
        if not died_at_boot or boots > BOOT_RETRIES:
            break
        print(f"uml: the kernel died at boot (exit {exit_code}) before running anything; booting again",
              file=sys.stderr)
    seconds = time.monotonic() - started

    def text(name: str) -> str:
        path = workdir / name
        return path.read_text(errors="replace") if path.exists() else ""

    if died_at_boot:
        status = f"the kernel died at boot {boots} times (last exit {exit_code}) before running anything"
    else:
        status = text("status").strip() or f"no status: the guest did not finish within {timeout:.0f}s or crashed"
    rc = text("pytest.rc").strip()
    return UmlRun(int(rc) if rc.isdigit() else None, status, text("pytest.log"), text("setup.log"),
                  text("kernel.log"), junit, seconds, boots)


def _boot(command: list[str], workdir: Path, timeout: float) -> int | None:
    """One boot: the kernel's exit code, or None if it outlived `timeout` (then it is killed)."""
    shutil.rmtree(workdir / "uml", ignore_errors=True)  # a dead kernel's leftovers
    (workdir / "uml").mkdir()
    with open(workdir / "kernel.log", "wb") as kernel_log:
        try:
            return subprocess.run(command, stdin=subprocess.DEVNULL, stdout=kernel_log, stderr=subprocess.STDOUT,
                                  timeout=timeout, check=False).returncode
        except subprocess.TimeoutExpired:
            return None


def main(argv: list[str]) -> int:
    reason = unavailable_reason()
    if reason:
        print(f"uml: {reason}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="vstig-uml-") as tmp:
        result = run(argv or [SOCKETCAN_MODULE, "-q"], Path(tmp))
        print(result.pytest_log or result.explain())
        print(f"uml: pytest exit code {result.exit_code} in {result.seconds:.1f}s (boot included)", file=sys.stderr)
        return 1 if result.exit_code is None else result.exit_code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
