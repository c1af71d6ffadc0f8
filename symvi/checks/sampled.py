"""The sampled-point verdict of the ``equations`` check (issue 53, item 3).

Before any symbolic work, the hand display and the derived object are evaluated at random
points, in double precision through SymEngine's ``Lambdify``
(:func:`symvi.derivation.differentiate.engine_function`; SymPy's ``lambdify`` where it
cannot take them). Every symbol — the unknown quantities and the parameters and h alike —
gets an independent value in [0.3, 1.3] at each point, so that a display must hold for
every parameter value, not only at the defaults.

* ``mode="equations"``: the derived equations D(p, x) = 0 are linear in their unknowns x
  (:func:`.equivalence.linear_unknowns`), with D(p, x) = J(p)·x + D(p, 0) and J(p)
  generically invertible. At each point x*(p) = −J(p)⁻¹ D(p, 0) is the derived solution;
  the hand equations hold on it, H(p, x*(p)) = 0, for each row, exactly when every row
  is a combination of the derived equations with coefficients that may depend on p
  (rescaling and recombination), and they determine the same x* when the rank of ∂H/∂x
  at x* is the number of unknowns. Without such unknowns, a row agrees with derived
  equation j when H_i/D_j takes one value at points that share their parameters.
* ``mode="value"``: H(p) = D(p).

A residual counts as zero below :data:`TOLERANCE` relative to the sizes of the terms it
sums (|H(p, 0)| + Σ_j |∂H/∂x_j · x*_j|): rounding leaves about 1e-14 of them, a slip a
fraction of one. Identity testing at random points decides with probability one; the
symbolic location (:mod:`.equivalence`) then only says where a display differs.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Collection, Sequence

import numpy as np
import sympy as sp

from ..declaration.rank import sequential_lambdify
from ..derivation.differentiate import engine_function

#: Relative size below which a sampled residual is zero.
TOLERANCE = 1e-8
#: Random points per verdict (each with its own parameter values).
POINTS = 4


@dataclass(frozen=True)
class Sampled:
    """The sampled verdict on one display: a row agrees (True), differs (False) or could not
    be evaluated (None); ``rank`` the rank of ∂H/∂x at the derived solution (equations
    mode with unknowns), ``unknowns`` their count; ``pairs`` for rows proportional to one
    derived equation, its index (else None)."""

    rows: tuple
    rank: int | None = None
    unknowns: int = 0
    pairs: tuple = ()

    @property
    def decided(self) -> bool:
        """Whether every row was evaluated."""
        return all(r is not None for r in self.rows)

    @property
    def ok(self) -> bool:
        """All rows agree and, with unknowns, the display determines all of them."""
        return (self.decided and all(self.rows)
                and (self.rank is None or self.rank == self.unknowns))


def _compiled(args: list, matrix: sp.Matrix) -> Callable | None:
    """``matrix`` as a function of ``args`` (floats): SymEngine, else SymPy's lambdify."""
    f = engine_function(args, (), matrix)
    if f is not None:
        return f
    try:
        g = sequential_lambdify(args, (), matrix)
    except (TypeError, NameError, SyntaxError):
        return None
    shape = matrix.shape
    return lambda *point: np.asarray(g(*point), dtype=float).reshape(shape)


def _evaluated(f: Callable, point: Sequence[float]) -> np.ndarray | None:
    try:
        with np.errstate(all="ignore"):
            value = np.asarray(f(*point), dtype=float).ravel()
    except (NameError, TypeError, ValueError, ZeroDivisionError):
        return None
    return value if np.all(np.isfinite(value)) else None


def _points(symbols: list, seed: int, count: int = POINTS) -> list[list[float]]:
    rng = np.random.default_rng(seed)
    return [list(rng.uniform(0.3, 1.3, len(symbols))) for _ in range(count)]


def sampled_equations(hand: Sequence[sp.Expr], derived: Sequence[sp.Expr],
                      unknowns: Sequence[sp.Symbol] | None, variables: Collection[sp.Symbol],
                      seed: int = 20261121) -> Sampled:
    """The verdict on ``hand`` (= 0) against ``derived`` (= 0), both in the model's
    symbols, with the derived system solved for ``unknowns`` at each point (module
    docstring); without unknowns, row by row up to a factor free of ``variables``."""
    if not unknowns or len(unknowns) != len(derived):
        return _sampled_proportional(hand, derived, set(variables), seed)
    x = list(unknowns)
    H, D = sp.Matrix(list(hand)), sp.Matrix(list(derived))
    others = sorted((H.free_symbols | D.free_symbols) - set(x), key=str)
    args = others + x
    fD = _compiled(args, D.col_join(D.jacobian(x).reshape(len(x) ** 2, 1)))
    fH = _compiled(args, H.col_join(H.jacobian(x).reshape(len(hand) * len(x), 1)))
    unknown = Sampled(tuple(None for _ in hand))
    if fD is None or fH is None:
        return unknown
    n, rows, rank, used = len(x), np.ones(len(hand), dtype=bool), 0, 0
    for p in _points(others, seed, 2 * POINTS):
        d = _evaluated(fD, p + [0.0] * n)
        if d is None:
            continue
        J = d[n:].reshape(n, n)
        if np.linalg.cond(J) > 1e10:
            continue
        xs = list(np.linalg.solve(J, -d[:n]))
        h0, hx = _evaluated(fH, p + [0.0] * n), _evaluated(fH, p + xs)
        if h0 is None or hx is None:
            continue
        m = len(hand)
        JH = hx[m:].reshape(m, n)
        scale = np.abs(h0[:m]) + np.abs(JH * np.asarray(xs)).sum(axis=1)
        rows &= np.abs(hx[:m]) <= TOLERANCE * np.maximum(scale, 1e-300)
        size = np.abs(JH).max(initial=0.0)
        if size > 0:
            rank = max(rank, int(np.linalg.matrix_rank(JH, tol=1e-9 * size)))
        used += 1
        if used == POINTS:
            break
    if used == 0:
        return unknown
    return Sampled(tuple(bool(r) for r in rows), rank, n)


def _sampled_proportional(hand, derived, variables: set, seed: int) -> Sampled:
    """Row i agrees when it is c·D_j for some j with c free of ``variables``: at points
    that share the parameters' values and differ in the variables, H_i and D_j are
    proportional as vectors. (Only rows that are each one derived equation up to a
    factor agree so; a recombination needs the unknowns.)"""
    H, D = sp.Matrix(list(hand)), sp.Matrix(list(derived))
    symbols = sorted(H.free_symbols | D.free_symbols, key=str)
    varying = [s in variables for s in symbols]
    f = _compiled(symbols, H.col_join(D))
    if f is None:
        return Sampled(tuple(None for _ in hand))
    shared = _points(symbols, seed + 1, 1)[0]
    points = [[v if vary else c for v, c, vary in zip(p, shared, varying)]
              for p in _points(symbols, seed, 2 * POINTS)]
    values = [v for v in (_evaluated(f, p) for p in points) if v is not None][:POINTS]
    if len(values) < 2:
        return Sampled(tuple(None for _ in hand))
    m = len(hand)
    V = np.array(values)
    Hv, Dv = V[:, :m], V[:, m:]
    rows, pairs = [], []
    for i in range(m):
        match = None
        for j in range(Dv.shape[1]):
            # H_i and D_j proportional on all points as vectors: rank of [H_i, D_j] is 1
            pair = np.column_stack([Hv[:, i], Dv[:, j]])
            size = np.abs(pair).max(initial=0.0)
            if size > 0 and np.linalg.matrix_rank(pair, tol=1e-9 * size) == 1 \
                    and np.abs(Dv[:, j]).max() > 0:
                match = j
                break
        rows.append(match is not None)
        pairs.append(match)
    return Sampled(tuple(rows), pairs=tuple(pairs))


def sampled_values(hand: Sequence[sp.Expr], derived: Sequence[sp.Expr],
                   seed: int = 20261121) -> Sampled:
    """The verdict on ``hand`` = ``derived`` value by value (``mode="value"``)."""
    H, D = sp.Matrix(list(hand)), sp.Matrix(list(derived))
    symbols = sorted(H.free_symbols | D.free_symbols, key=str)
    f = _compiled(symbols, H.col_join(D))
    if f is None:
        return Sampled(tuple(None for _ in hand))
    values = [v for v in (_evaluated(f, p) for p in _points(symbols, seed, 2 * POINTS))
              if v is not None][:POINTS]
    if not values:
        return Sampled(tuple(None for _ in hand))
    m = len(hand)
    V = np.array(values)
    scale = np.maximum(np.abs(V[:, :m]), np.abs(V[:, m:]))
    rows = (np.abs(V[:, :m] - V[:, m:]) <= TOLERANCE * np.maximum(scale, 1e-300)).all(axis=0)
    return Sampled(tuple(bool(r) for r in rows))
