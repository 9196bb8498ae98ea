"""`make fuzz`: every parser under atheris (coverage-guided libFuzzer), one process per parser.

    python tests/fuzz/run.py [--runs N] [TARGET ...]     # default: every target, FUZZ_RUNS or 1,000,000 each

Each target runs in its own process with a per-input timeout (a hang is a
failure) and prints how many inputs it tried and how fast. A crash (an exception
other than the parser's own error, a broken invariant) stops that target with
libFuzzer's report and the input that caused it (saved as .fuzz/crash-*), and the run
exits 1.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
PER_INPUT_TIMEOUT = 10  # seconds: longer than any parser needs for max_len bytes, so more is a hang
MAX_LEN = 512  # bytes per input
LONGER = {"capture-files": 4096, "mcap": 4096}  # a BLF file's headers alone take a kilobyte; MCAP's summary too
ARTIFACTS = Path(".fuzz")  # the corpus per target, and any input that crashed


def child(name: str, runs: int) -> None:
    import atheris

    sys.path.insert(0, str(HERE))
    with atheris.instrument_imports(include=["vstig_hw", "targets"]):
        from targets import TARGETS, seeds

    corpus = ARTIFACTS / f"corpus-{name}"  # kept: the next run starts from what this one learned
    corpus.mkdir(parents=True, exist_ok=True)
    for i, seed in enumerate(seeds()[name]):
        (corpus / f"seed-{i}").write_bytes(seed)
    options = [f"-runs={runs}", f"-max_len={LONGER.get(name, MAX_LEN)}", f"-timeout={PER_INPUT_TIMEOUT}",
               "-rss_limit_mb=2048", "-print_final_stats=1", f"-artifact_prefix={ARTIFACTS}/crash-{name}-"]
    atheris.Setup([sys.argv[0], str(corpus), *options], TARGETS[name])
    atheris.Fuzz()


def main() -> int:
    if len(sys.argv) > 2 and sys.argv[1] == "--child":  # before importing the targets: atheris instruments them
        child(sys.argv[2], int(sys.argv[4]))
        return 0
    sys.path.insert(0, str(HERE))
    from targets import TARGETS

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("targets", nargs="*", choices=[[], *TARGETS], metavar="TARGET",
                        help=f"default: all of {', '.join(TARGETS)}")
    parser.add_argument("--runs", type=int, default=int(os.environ.get("FUZZ_RUNS", 1_000_000)),
                        help="inputs per target (default: $FUZZ_RUNS or 1,000,000)")
    args = parser.parse_args()
    print(f"{'parser':<16} {'inputs':>10} {'seconds':>8} {'inputs/s':>9}  result")
    scratch = tempfile.mkdtemp(prefix="vstig-fuzz-", dir="/dev/shm" if os.path.isdir("/dev/shm") else None)
    env = {**os.environ, "VSTIG_FUZZ_SCRATCH": scratch}  # the targets' files; libFuzzer skips atexit
    try:
        failed = [name for name in args.targets or TARGETS if not fuzz_one(name, args.runs, env)]
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    if failed:
        print(f"fuzz: {len(failed)} target(s) failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


def fuzz_one(name: str, runs: int, env: dict[str, str]) -> bool:
    """Run one target in its own process and print its line; True if it tried every input and nothing broke."""
    start = time.monotonic()
    done = subprocess.run([sys.executable, __file__, "--child", name, "--runs", str(runs)],
                          capture_output=True, text=True, check=False, env=env)
    elapsed = time.monotonic() - start
    found = re.search(r"stat::number_of_executed_units:\s*(\d+)", done.stderr)
    tried = int(found.group(1)) if found else 0
    ok = done.returncode == 0 and tried >= runs
    print(f"{name:<16} {tried:>10,} {elapsed:>8.1f} {tried / elapsed:>9,.0f}  {'ok' if ok else 'FAILED'}", flush=True)
    if not ok:
        print(done.stderr[-4000:], file=sys.stderr)
    return ok


if __name__ == "__main__":
    sys.exit(main())
