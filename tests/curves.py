"""Smooth curves for the consistency tests: functions of the time t of
:mod:`symvi.checks.expansions`, their derivatives, and a model's parameters by name."""
from __future__ import annotations

import sympy as sp

from symvi.checks.expansions import TIME


def curve(name: str) -> sp.Expr:
    """The real function ``name``(t)."""
    return sp.Function(name, real=True)(TIME)


def derivative(f: sp.Expr, k: int = 1) -> sp.Expr:
    """d^k f/dt^k, unevaluated."""
    return sp.Derivative(f, (TIME, k))


def parameters(model) -> dict:
    """Parameter name → symbol of ``model``."""
    return {str(s): s for s, _ in model.parameters}
