"""What a declaration may contain: model names and expressions symvi can compile.

A model's name becomes a top-level package in the output folder, so it must import as
written and must not shadow a module that other code in that folder imports. Its
expressions are compiled to C and differentiated twice (the residual's Jacobian holds
second derivatives of L_d), so they must be real, finite, closed-form and smooth in the
coordinates.
"""
from __future__ import annotations

import functools
import keyword
import sys
import unicodedata
from typing import Any, Iterable

import numpy as np
import sympy as sp
from sympy.core.function import AppliedUndef

from ..errors import ModelError

#: Functions with a kink or a jump: their second derivatives hold DiracDelta (or worse).
NONSMOOTH = (sp.Abs, sp.sign, sp.Heaviside, sp.DiracDelta, sp.Max, sp.Min, sp.floor,
             sp.ceiling, sp.frac, sp.Mod)
#: Unevaluated operations symvi cannot compile.
UNEVALUATED = (sp.Derivative, sp.Integral, sp.Sum, sp.Product, sp.Limit)
#: Values that convert to a float but are not numbers: the run time refuses them for its
#: numbers (``_runtime.core.arguments.real``), so a declaration refuses them where it takes one.
NOT_NUMBERS = (str, bytes, bool, np.bool_)


@functools.lru_cache(maxsize=1)
def _installed() -> dict[str, list[str]]:
    import importlib.metadata
    return importlib.metadata.packages_distributions()


def _shadowed(name: str) -> str | None:
    """What a top-level package called ``name`` would shadow, if anything."""
    if name in sys.stdlib_module_names or name in sys.builtin_module_names:
        return "a module of Python's standard library"
    if name == "symvi":
        return "symvi itself"
    distributions = _installed().get(name)
    if distributions:
        return f"the installed package {name!r} (distribution {', '.join(distributions)})"
    return None


def check_model_name(name: Any) -> None:
    """Refuse a model name that cannot be imported as written or would shadow a module."""
    if not isinstance(name, str) or not name.isidentifier() or keyword.iskeyword(name) \
            or name.startswith("_"):
        raise ModelError(f"model name {name!r} must be a public Python identifier (letters, "
                         f"digits and underscores, not a keyword, not starting with '_'); "
                         f"the generated package is imported under this name")
    normal = unicodedata.normalize("NFKC", name)
    if normal != name:
        raise ModelError(f"model name {name!r} has compatibility characters: Python imports "
                         f"it as {normal!r}, which is not the folder's name; use {normal!r}")
    shadowed = _shadowed(name)
    if shadowed:
        raise ModelError(f"model name {name!r} is taken by {shadowed}: a generated package of "
                         f"that name would shadow it for all code run with the output folder "
                         f"on sys.path; choose another name, e.g. {name + '_model'!r}")


def scalar(expr: Any, what: str) -> sp.Expr:
    """``expr`` as a real, finite, closed-form SymPy scalar, or a ModelError naming why not."""
    if isinstance(expr, (sp.MatrixBase, list, tuple, np.ndarray)):
        shape = getattr(expr, "shape", (len(expr),))
        raise ModelError(f"the {what} must be a scalar expression, got shape {tuple(shape)}")
    try:
        value = sp.sympify(expr)
    except (sp.SympifyError, TypeError) as exc:
        raise ModelError(f"the {what} is not a SymPy expression: {exc}") from None
    if not isinstance(value, sp.Expr):
        raise ModelError(f"the {what} must be a scalar expression, got {type(value).__name__}")
    if value.has(sp.nan, sp.zoo, sp.oo, -sp.oo):
        raise ModelError(f"the {what} is not finite: {value}")
    if value.has(sp.I):
        raise ModelError(f"the {what} is complex (it contains I): {value}; symvi needs a real "
                         f"expression")
    undefined = sorted(map(str, value.atoms(AppliedUndef)))
    if undefined:
        raise ModelError(f"the {what} contains the undefined function(s) {', '.join(undefined)}; "
                         f"symvi compiles closed-form expressions: write them out, or make "
                         f"their values parameters")
    unevaluated = sorted({type(a).__name__ for a in value.atoms(*UNEVALUATED)})
    if unevaluated:
        raise ModelError(f"the {what} contains an unevaluated {', '.join(unevaluated)}; "
                         f"evaluate it (.doit()) to a closed form first")
    return value


def check_smooth(expr: sp.Expr, coordinates: Iterable[sp.Symbol], what: str) -> None:
    """Refuse kinks and jumps in ``coordinates``: Newton's Jacobian needs the second
    derivatives of L_d, which would hold DiracDelta there."""
    coordinates = set(coordinates)
    kinks = sorted({str(a) for a in expr.atoms(*NONSMOOTH) if a.free_symbols & coordinates})
    if kinks:
        raise ModelError(
            f"the {what} is not twice differentiable in its coordinates: {', '.join(kinks)} "
            f"has a kink or a jump, and Newton's method needs its second derivatives; "
            f"smooth it (e.g. sqrt(x**2 + eps**2) for Abs(x)) or write a Piecewise whose "
            f"pieces join with continuous second derivatives")
