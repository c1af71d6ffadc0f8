"""Symbols shared by every stage of the pipeline."""
from __future__ import annotations

import sympy as sp

#: The time step. It is a run-time argument of every generated function.
h = sp.Symbol("h", positive=True)


#: The sign assumptions of a parameter symbol that its values must meet, strongest first.
SIGNS = (("positive", lambda v: v > 0), ("nonnegative", lambda v: v >= 0),
         ("negative", lambda v: v < 0), ("nonpositive", lambda v: v <= 0))


def sign(symbol: sp.Symbol) -> str | None:
    """The strongest sign assumption of ``symbol`` (``m = sp.Symbol("m", positive=True)``:
    "positive"), or None."""
    return next((name for name, _ in SIGNS if getattr(symbol, f"is_{name}")), None)
