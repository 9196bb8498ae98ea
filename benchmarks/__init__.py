"""`make bench`: our figures beside an anchor measured in the same run.

Each `bench_*.py` module registers functions with `@benchmark`; a function
returns one or more `Result`s. Run from the repo root: `python -m benchmarks
[--json] [--only SUBSTRING]`.
"""
