"""Generic rank of a symbolic matrix, sampled at random points.

The rank of an analytic matrix function at a random point equals its generic rank with
probability one, so a few samples decide "identically singular" without symbolic
determinants (which are slow and blow up for transcendental entries).

A sample's numerical rank counts the singular values above :data:`RELATIVE_TOLERANCE`
times its scale. The rank of cM is that of M for any c ≠ 0, so the scale is the sample's
own: a Lagrangian in small units (a mass of 1e-11 kg) is as regular as in large ones. But
an entry that vanishes identically without SymPy seeing it (sin²q + cos²q − 1) evaluates
to the rounding noise of its terms, which is as small as a genuine small entry. So the
scale of a sample whose entries are all below 1 is the size of the terms they are
computed from (:func:`term_sizes`: |a| + |b| + … for a + b + …): small units have small
terms, noise comes from large ones. Entries of 1 or more set the scale themselves (their
terms are not evaluated: that costs a second compilation of the matrix), as they always
did. The tolerance is generous, far above rounding, for the same reason. A sample that is
exactly zero has rank 0.
"""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np
import sympy as sp

from ..groupoids.analytic import used_coefficients

#: Singular values below this fraction of a sample's scale count as zero.
RELATIVE_TOLERANCE = 1e-10

#: A compiler of a matrix as a NumPy function of ``args``, or None where it cannot take
#: the matrix: ``engine(args, definitions, matrix)`` (see :func:`generic_rank`).
Engine = Callable[[Sequence[sp.Symbol], Sequence[tuple[sp.Symbol, sp.Expr]], sp.Matrix],
                  Callable | None]


def sequential_lambdify(args: Sequence[sp.Symbol],
                        definitions: Sequence[tuple[sp.Symbol, sp.Expr]], expr):
    """NumPy function of ``args`` computing ``expr``, which may use the symbols of
    ``definitions`` — (symbol, expression) pairs evaluated in order first.

    One function whose body assigns the definitions, then the common subexpressions of
    ``expr``: lambdify's ``cse`` hook takes the pairs as they are (one lambdify per
    definition cost seconds on the SE(3) models). The functions it calls that NumPy lacks
    (the exponential's coefficients) come with their own implementations (``_imp_``),
    found by :func:`~symvi.groupoids.analytic.used_coefficients`, which visits each
    distinct subexpression once: lambdify's own search walks the whole tree (6 s on
    se3_body_exp's step Jacobian).
    """
    definitions = list(definitions)

    def with_definitions(exprs):
        common, reduced = sp.cse(exprs[0], symbols=sp.numbered_symbols("_rank_cse"))
        return definitions + common, reduced[0]
    applied = list(expr) if isinstance(expr, sp.MatrixBase) else [expr]
    implementations = {c.__name__: c._imp_ for c in
                       used_coefficients(applied + [e for _, e in definitions])}
    return sp.lambdify(list(args), (expr,), [implementations, "numpy"], use_imps=False,
                       cse=with_definitions)


def generic_rank(matrix: sp.Matrix, symbols: Sequence[sp.Symbol],
                 fixed: dict[sp.Symbol, float] | None = None, samples: int = 4,
                 seed: int = 20261121, definitions=(), engine: Engine | None = None
                 ) -> int | None:
    """Largest numerical rank of ``matrix`` over random points of ``symbols``.

    ``fixed`` gives values for the remaining symbols (parameters, the step);
    ``definitions`` intermediate quantities ``matrix`` may use (see
    :func:`sequential_lambdify`). ``engine``, when given, compiles the matrix first
    (the derivation hands its :func:`symvi.derivation.differentiate.engine_function`,
    SymEngine's ``Lambdify``, for its large step Jacobians); where it gives None, or
    without one, :func:`sequential_lambdify` does. Returns None when no sample point gave
    finite entries or the matrix holds a function NumPy cannot evaluate.
    """
    fixed = dict(fixed or {})
    args = list(symbols) + list(fixed)
    f = (engine and engine(args, definitions, matrix)) \
        or sequential_lambdify(args, definitions, matrix)
    sizes = None     # compiled when a sample first needs it
    rng = np.random.default_rng(seed)
    best = None
    for _ in range(samples):
        values = list(rng.uniform(-0.7, 0.7, len(symbols))) + list(fixed.values())
        M = _evaluate(f, values)
        if M is None:
            return None     # a function NumPy lacks: the rank is not known
        if not np.all(np.isfinite(M)):
            continue
        scale = float(np.abs(M).max(initial=0.0))
        if 0.0 < scale < 1.0:
            sizes = sizes or sequential_lambdify(args, definitions, term_sizes(matrix))
            terms = _evaluate(sizes, values)
            scale = max(scale, float(np.abs(terms).max())) if terms is not None else 1.0
        rank = numerical_rank(M, scale)
        best = rank if best is None else max(best, rank)
    return best


def _evaluate(f, values) -> np.ndarray | None:
    """``f(*values)`` as a float array; None if it calls a function NumPy lacks."""
    try:
        with np.errstate(all="ignore"):
            return np.array(f(*values), dtype=float)
    except (NameError, TypeError):
        return None


def numerical_rank(M: np.ndarray, scale: float) -> int:
    """Rank of a finite matrix whose entries are significant down to ``scale`` times
    :data:`RELATIVE_TOLERANCE`; 0 for a zero matrix."""
    if not np.any(M):
        return 0
    return int(np.linalg.matrix_rank(M, tol=RELATIVE_TOLERANCE * scale))


def term_sizes(matrix: sp.Matrix) -> sp.Matrix:
    """Each entry with the terms of every sum taken in absolute value (|a| + |b| + … for
    a + b + …, through products and positive integer powers; anything else, a function
    or a symbol, by its absolute value): the size of what the entry is computed from,
    which bounds the rounding noise an identically vanishing entry evaluates to."""
    memo: dict[sp.Expr, sp.Expr] = {}

    def size(e: sp.Expr) -> sp.Expr:
        if e not in memo:
            if e.is_Add or e.is_Mul:
                memo[e] = e.func(*(size(a) for a in e.args))
            elif e.is_Pow and e.exp.is_Integer and e.exp > 0:
                memo[e] = size(e.base) ** e.exp
            else:
                memo[e] = sp.Abs(e)
        return memo[e]
    return matrix.applyfunc(size)
