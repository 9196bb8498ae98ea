"""Collect test_socketcan.py on the host only where it can run here.

Without vcan0 on this host, `test_in_uml.py` runs that module inside User-Mode
Linux (and fails or skips with the reason there), so collecting it here too would
only add a second, redundant skip.
"""

import os
from pathlib import Path

collect_ignore = []
if os.environ.get("VSTIG_IN_UML") != "1" and not Path("/sys/class/net/vcan0").exists():
    collect_ignore.append("test_socketcan.py")
