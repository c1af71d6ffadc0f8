"""Symbols shared by every stage of the pipeline."""
from __future__ import annotations

import sympy as sp

from .._runtime.core.signs import SIGNS

#: The time step. It is a run-time argument of every generated function.
h = sp.Symbol("h", positive=True)


def sign(symbol: sp.Symbol) -> str | None:
    """The strongest sign assumption of ``symbol`` (``m = sp.Symbol("m", positive=True)``:
    "positive") among those the run time checks (``symvi._runtime.core.signs.SIGNS``), or None."""
    return next((name for name in SIGNS if getattr(symbol, f"is_{name}")), None)
