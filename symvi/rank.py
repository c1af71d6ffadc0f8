"""Generic rank of a symbolic matrix, sampled at random points.

The rank of an analytic matrix function at a random point equals its generic rank with
probability one, so a few samples decide "identically singular" without symbolic
determinants (which are slow and blow up for transcendental entries).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import sympy as sp


def generic_rank(matrix: sp.Matrix, symbols: Sequence[sp.Symbol],
                 fixed: dict[sp.Symbol, float] | None = None, samples: int = 4,
                 seed: int = 20261121) -> int | None:
    """Largest numerical rank of ``matrix`` over random points of ``symbols``.

    ``fixed`` gives values for the remaining symbols (parameters, the step). Returns
    None when no sample point gave finite entries.
    """
    fixed = dict(fixed or {})
    args = list(symbols) + list(fixed)
    f = sp.lambdify(args, matrix, modules="numpy")
    rng = np.random.default_rng(seed)
    best = None
    for _ in range(samples):
        values = list(rng.uniform(-0.7, 0.7, len(symbols))) + list(fixed.values())
        with np.errstate(all="ignore"):
            M = np.array(f(*values), dtype=float)
        if not np.all(np.isfinite(M)):
            continue
        rank = int(np.linalg.matrix_rank(M, tol=1e-10 * max(1.0, float(np.abs(M).max()))))
        best = rank if best is None else max(best, rank)
    return best
