"""The compiled data path, when this install has it and it is not turned off.

C twin: vstig_hw/_cext/module.c (the module: `setup`, `DECLARED`); held equal by tests/native (index:
vstig_hw/_vstig.pyi).

`vstig_hw._vstig` is built from libvstig (firmware_spec/libvstig) when the package is
installed where a C compiler and Python's headers are; elsewhere the install is pure Python
and everything works the same, slower. `VSTIG_PURE=1` in the environment turns the compiled
path off (for comparing the two, or if it ever misbehaves): nothing compiled is loaded.

`native` is the extension module, or None; `why_pure` says why not ("" when it is loaded).
firmware_spec/SPEC.md is normative; the Python is the reference implementation of it, and each
compiled type is its twin, with the interface of one Python class and held equal to it by
tests/native (the twins: vstig_hw/_vstig.pyi; DECISIONS.md, "The gateway's compiled data path").
"""

from __future__ import annotations

import importlib
import os
from types import ModuleType

from .engine import Entry, Outcome, higher_robot_wins, larger_value_wins, sum_merge
from .wire import Message

__all__ = ["PURE_ENV", "native", "why_pure"]

PURE_ENV = "VSTIG_PURE"  # set to 1: the pure-Python path, whatever is installed


def _load() -> tuple[ModuleType | None, str]:
    if os.environ.get(PURE_ENV, "") not in ("", "0"):
        return None, f"{PURE_ENV}={os.environ[PURE_ENV]}"
    try:  # by name: a compiled module is no source the layers contract (pyproject.toml) could read
        _vstig = importlib.import_module(f"{__package__}._vstig")
    except ImportError as error:
        return None, f"the compiled data path is not built here ({error})"
    _vstig.setup(message=Message, entry=Entry, outcomes=tuple(Outcome),
                 rules=(higher_robot_wins, larger_value_wins, sum_merge))
    return _vstig, ""


native, why_pure = _load()
