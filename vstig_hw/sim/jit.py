"""Compiled inner loops for the simulator (numba).

A motion run rebuilds the hearing graph and moves every robot ten times per
simulated second, for tens of thousands of steps. As vectorised numpy, each
step was some hundred small array calls, and their fixed cost, not the
arithmetic, set the pace. A compiled loop over the robots and their near pairs
does the same work in a few microseconds, and reads as the model is written.

Compiled functions are cached on disk next to this package, so only the first
run after an install pays the compilation (a few seconds).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar, cast

import numba

__all__ = ["compiled"]

_F = TypeVar("_F", bound=Callable[..., object])


def compiled(function: _F) -> _F:
    """`function` compiled to machine code on first call (nopython mode, cached on disk)."""
    return cast(_F, numba.njit(cache=True, nogil=True)(function))
