"""`python -m vstig_hw.ros2msgs env`: the exports that let another process import the cached interfaces.

`build PREFIX WORK` is the child process `load` runs to build them.
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

from . import BuildError, environment
from .build import build

USAGE = "usage: python -m vstig_hw.ros2msgs env | build PREFIX WORK"


def main(argv: list[str]) -> int:
    try:
        if argv == ["env"]:
            for variable, value in environment().items():
                print(f"export {variable}={shlex.quote(value)}")
            return 0
        if len(argv) == 3 and argv[0] == "build":
            build(Path(argv[1]), Path(argv[2]))
            return 0
    except BuildError as error:
        print(error, file=sys.stderr)
        return 1
    print(USAGE, file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
