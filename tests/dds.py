"""ROS 2 in the tests, kept on this machine: a namespace per host, a ROS domain of this run's own.

DDS discovery multicasts on every interface it finds, so every ROS 2 process of the
tests (and of the docs' examples) runs in a network namespace holding `lo` alone
(`Host`; `cable` joins two for the tests that play a second host). Fast DDS's
shared memory is seen across namespaces, so each run takes its own domain id
(`DOMAIN`), which keeps concurrent runs apart. `environment()` is what such a
process adds to its environment: this run's domain and the vstig_msgs interfaces importable.
`vstig_environment()` is what a vstig gateway runs with: as a user's, without the ROS 2
wheels' library path or their re-execution, which only its node process gets.
"""

from __future__ import annotations

import os
import random
import subprocess
import sys
import sysconfig
from pathlib import Path

from vstig_hw.extras import missing

DOMAIN = str(random.Random(os.getpid()).randint(1, 100))  # of the ids whose ports Fast DDS has on Linux


def unavailable() -> str | None:
    """Why ROS 2 processes cannot run here (in a namespace of their own), or None."""
    if missing(["rclpy"]):
        return "the ros2 extra is not installed (pip install 'vstig-hw[ros2]')"
    if os.geteuid() != 0:
        return "a ROS 2 process runs in a network namespace of its own, which needs root (`ip netns add`)"
    probe = Host("probe")
    probe.close()
    return None


def environment() -> dict[str, str]:
    """The variables a ROS 2 process adds to this environment: this run's domain, the vstig_msgs interfaces
    importable (built if needed)."""
    from vstig_hw import ros2msgs

    return {**ros2msgs.environment(), "ROS_DOMAIN_ID": DOMAIN}


def vstig_environment() -> dict[str, str]:
    """This environment without the ROS 2 wheels' library path (a run of pytest straight from the venv was
    re-executed with it), with their bootstrapper's guard set and this run's domain: a gateway started so finds
    the wheels' libraries for its node process itself (ros2msgs.ros_environment)."""
    from vstig_hw.ros2msgs import BOOTSTRAP_GUARD

    site = Path(sysconfig.get_paths()["purelib"])
    wheels = {os.path.join(sys.prefix, "lib"), *(str(path.resolve()) for path in site.glob("ros_*.libs"))}
    kept = [part for part in os.environ.get("LD_LIBRARY_PATH", "").split(os.pathsep) if part and part not in wheels]
    return {**os.environ, "LD_LIBRARY_PATH": os.pathsep.join(kept), BOOTSTRAP_GUARD: "1",
            "ROS_DOMAIN_ID": DOMAIN}


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True, timeout=20)


class Host:
    """A namespace of our own standing for one host: `lo` up and nothing else, or joined to another by `cable`.

    For DDS (the ros2: link tests), whose discovery multicasts on every interface it finds: in a namespace
    with only `lo` nothing can leave the machine. `interfaces()` lists what the namespace holds.
    """

    def __init__(self, role: str) -> None:
        self.name = f"vstig-{os.getpid() % 100000:05d}-{role}"
        _ip("netns", "add", self.name)
        try:
            _ip("-n", self.name, "link", "set", "lo", "up")
        except BaseException:
            self.close()
            raise

    def command(self) -> list[str]:
        return ["ip", "netns", "exec", self.name]

    def interfaces(self) -> list[str]:
        shown = subprocess.run(["ip", "-n", self.name, "-o", "link", "show"], capture_output=True, text=True,
                               timeout=20, check=True).stdout
        return [line.split(":")[1].strip().split("@")[0] for line in shown.splitlines()]

    def cable(self, other: Host, subnet: str = "10.78.0") -> tuple[str, str]:
        """A veth pair between the two, with addresses and a multicast route each; (our address, theirs)."""
        ours, theirs = f"{self.name[-12:]}a".replace("-", ""), f"{self.name[-12:]}b".replace("-", "")
        _ip("link", "add", ours, "netns", self.name, "type", "veth", "peer", "name", theirs, "netns", other.name)
        for host, device, address in ((self, ours, f"{subnet}.1"), (other, theirs, f"{subnet}.2")):
            _ip("-n", host.name, "addr", "add", f"{address}/24", "dev", device)
            _ip("-n", host.name, "link", "set", device, "up")
            _ip("-n", host.name, "route", "add", "224.0.0.0/4", "dev", device)
        self.device = ours
        return f"{subnet}.1", f"{subnet}.2"

    def close(self) -> None:
        subprocess.run(["ip", "netns", "del", self.name], capture_output=True, timeout=20, check=False)
