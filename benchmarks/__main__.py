"""Run every registered benchmark and print a table (or one JSON object)."""

from __future__ import annotations

import argparse
import importlib
import json
import pkgutil
import sys
from pathlib import Path

from .registry import REGISTRY, Result


def _load_all() -> None:
    here = Path(__file__).parent
    for module in pkgutil.iter_modules([str(here)]):
        if module.name.startswith("bench_"):
            importlib.import_module(f"benchmarks.{module.name}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__)
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--only", default="", help="run benchmarks whose name contains this")
    args = parser.parse_args(argv)
    _load_all()
    results: list[Result] = []
    for name, fn in sorted(REGISTRY.items()):
        if args.only in name:
            if not args.json:
                print(f"running {name} ...", file=sys.stderr)
            results.extend(fn())
    if args.json:
        print(json.dumps({r.name: r.as_json() for r in results}, indent=2))
        return 0
    from rich.console import Console
    from rich.table import Table

    table = Table(title="vstig-hw benchmarks (one run; ratio = value / anchor)")
    for column in ("benchmark", "value", "unit", "anchor", "anchor value", "ratio"):
        table.add_column(column, justify="right" if column in ("value", "anchor value", "ratio") else "left")
    for r in results:
        table.add_row(r.name, f"{r.value:,.4g}", r.unit, r.anchor, f"{r.anchor_value:,.4g}", f"{r.ratio:.3f}")
    # Piped output would be cut to 80 columns; the names are long, so give it room.
    Console(width=None if sys.stdout.isatty() else 200).print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
