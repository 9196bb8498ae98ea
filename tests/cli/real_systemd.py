"""A real systemd, as PID 1 of a PID and mount namespace of its own, for units `vstig service` writes.

This machine's PID 1 is not systemd, so `systemd-run` has no manager to talk to. systemd runs in a
container (`container=` set) as PID 1 of a new PID namespace: it starts an empty target, then only the
units a test asks for, with every sandbox setting applied as on a host (mount namespaces, seccomp, the
devices cgroup, a dynamic user). It knows no unit but the test's and a few empty targets, and its /run,
/tmp, /var/tmp, /var/log and /etc/systemd/system are tmpfs of its own namespace: the host's units and
files are not touched (a systemd that loaded the host's units would run sysinit.target's, and
systemd-tmpfiles would empty the host's /tmp). Killing it ends every process it started.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import time
from pathlib import Path
from types import TracebackType

from required import missing

# Only these units exist for it (SYSTEMD_UNIT_PATH): the targets a service's default dependencies name, empty.
# Nothing of the host's (/lib/systemd/system) is loaded, so nothing of sysinit.target runs: no
# systemd-tmpfiles emptying /tmp, no sysctl, no udev, no journald.
_EMPTY_TARGETS = ("vstig-empty", "sysinit", "basic", "shutdown", "network-online", "network", "multi-user")
_SLICE = "[Unit]\nDescription=System Slice\nDefaultDependencies=no\n"
_BOOT = """set -e
mount --make-rprivate /
for folder in /run /tmp /var/tmp /var/log /etc/systemd/system; do mount -t tmpfs tmpfs "$folder"; done
cp "$1"/* /etc/systemd/system/
export container=vstig-test SYSTEMD_UNIT_PATH=/etc/systemd/system
exec /lib/systemd/systemd --system --unit=vstig-empty.target --log-target=null
"""


class RealSystemd:
    def __init__(self, units: Path) -> None:
        """`units`: a folder of unit files, loaded at boot."""
        for tool in ("unshare", "nsenter"):
            if shutil.which(tool) is None:
                missing(f"{tool} (util-linux) to run systemd in a namespace")
        if os.geteuid() != 0 or not os.path.exists("/lib/systemd/systemd"):
            missing("root and /lib/systemd/systemd to run a systemd in a namespace")
        for name in _EMPTY_TARGETS:
            (units / f"{name}.target").write_text("[Unit]\nDescription=empty\n")
        (units / "system.slice").write_text(_SLICE)
        self._unshare = subprocess.Popen(
            ["unshare", "--pid", "--fork", "--mount", "--mount-proc", "--uts", "sh", "-c", _BOOT, "boot",
             str(units)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        self.pid = self._manager_pid()
        end = time.monotonic() + 30
        while self.systemctl("is-system-running").stdout.strip() not in ("running", "degraded"):
            assert time.monotonic() < end, "systemd did not finish starting"
            time.sleep(0.1)

    def _manager_pid(self) -> int:
        end = time.monotonic() + 10
        children = Path(f"/proc/{self._unshare.pid}/task/{self._unshare.pid}/children")
        while time.monotonic() < end:
            if self._unshare.poll() is not None:
                said = self._unshare.stderr.read() if self._unshare.stderr else ""
                raise AssertionError(f"systemd did not start: {said}")
            found = children.read_text().split() if children.exists() else []
            if found and Path(f"/proc/{found[0]}/comm").read_text().strip() == "systemd":
                return int(found[0])
            time.sleep(0.05)
        raise AssertionError("systemd did not start")

    def systemctl(self, *args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
        return self.run("systemctl", "--no-pager", *args, timeout=timeout)

    def run(self, *argv: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
        """A command in the manager's namespaces (its /run, its processes)."""
        return subprocess.run(["nsenter", "-t", str(self.pid), "-m", "-p", *argv], capture_output=True, text=True,
                              timeout=timeout, check=False)

    def show(self, unit: str, prop: str) -> str:
        return self.systemctl("show", "--value", "-p", prop, unit).stdout.strip()

    def close(self) -> None:
        """SIGKILL to PID 1 of the namespace: the kernel ends every process in it."""
        os.kill(self.pid, signal.SIGKILL)
        self._unshare.wait(timeout=10)

    def __enter__(self) -> RealSystemd:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.close()
