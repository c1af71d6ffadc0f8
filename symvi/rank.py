"""Generic rank of a symbolic matrix, sampled at random points.

The rank of an analytic matrix function at a random point equals its generic rank with
probability one, so a few samples decide "identically singular" without symbolic
determinants (which are slow and blow up for transcendental entries).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import sympy as sp


def sequential_lambdify(args: Sequence[sp.Symbol],
                        definitions: Sequence[tuple[sp.Symbol, sp.Expr]], expr):
    """NumPy function of ``args`` computing ``expr``, which may use the symbols of
    ``definitions`` — (symbol, expression) pairs evaluated in order first.

    One function whose body assigns the definitions, then the common subexpressions of
    ``expr``: lambdify's ``cse`` hook takes the pairs as they are (one lambdify per
    definition cost seconds on the SE(3) models). The definitions ride along in the
    expression lambdify sees, so that it finds the implementations of the functions
    they call (the exponential's coefficients).
    """
    definitions = list(definitions)

    def with_definitions(exprs):
        common, reduced = sp.cse(exprs[0], symbols=sp.numbered_symbols("_rank_cse"))
        return definitions + common, reduced[0]
    carried = (expr,) + tuple(e for _, e in definitions)
    return sp.lambdify(list(args), carried, "numpy", cse=with_definitions)


def generic_rank(matrix: sp.Matrix, symbols: Sequence[sp.Symbol],
                 fixed: dict[sp.Symbol, float] | None = None, samples: int = 4,
                 seed: int = 20261121, definitions=()) -> int | None:
    """Largest numerical rank of ``matrix`` over random points of ``symbols``.

    ``fixed`` gives values for the remaining symbols (parameters, the step);
    ``definitions`` intermediate quantities ``matrix`` may use (see
    :func:`sequential_lambdify`). Returns None when no sample point gave finite entries
    or the matrix holds a function NumPy cannot evaluate.
    """
    fixed = dict(fixed or {})
    args = list(symbols) + list(fixed)
    f = sequential_lambdify(args, definitions, matrix)
    rng = np.random.default_rng(seed)
    best = None
    for _ in range(samples):
        values = list(rng.uniform(-0.7, 0.7, len(symbols))) + list(fixed.values())
        try:
            with np.errstate(all="ignore"):
                M = np.array(f(*values), dtype=float)
        except (NameError, TypeError):
            return None     # a function NumPy lacks: the rank is not known
        if not np.all(np.isfinite(M)):
            continue
        rank = int(np.linalg.matrix_rank(M, tol=1e-10 * max(1.0, float(np.abs(M).max()))))
        best = rank if best is None else max(best, rank)
    return best
