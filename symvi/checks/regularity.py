"""Check ``regularity``: the matrix defining the step map is generically non-singular
(paper §4.3; D₁₂L_d for first-order and D₁₃L_d for second-order pair-groupoid Lagrangians,
D₁,ₖ₊₁L_d for order k (D₁₄L_d … D₁₇L_d for k = 3 … 6: ∂R/∂q_{2k} of the residual at the
middle node, which only the last window's first slot sees), their group analogues, the
bordered matrix of a constrained problem; named by the groupoid's ``step_matrix_name``).

The generic rank is measured at random points (:func:`symvi.declaration.rank.generic_rank`: an analytic
matrix has its generic rank at a random point with probability one). When the matrix is
small and its entries short, its determinant is also computed and factored symbolically,
and the factors that can vanish are reported as the singular locus.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import sympy as sp

from ..derivation.derive import step_jacobian
from ..errors import ModelError
from ..declaration.rank import generic_rank, sequential_lambdify
from ..derivation.differentiate import engine_function
from .budget import SKIPPED
from .noether import readable
from .report import CheckResult
from .._runtime.core.model_info import Kernel as KernelName

NAME = "regularity"
#: Of the Lagrangian's step map: skipped in pure minimum time (:mod:`.runner`).
OF_THE_LAGRANGIAN = True
#: Largest matrix (rows) and total operation count for which the determinant is factored.
_DETERMINANT_SIZE, _DETERMINANT_OPS = 4, 600
_STEP = 0.1
_SUMMARY = 160


def singular_locus(J: sp.Matrix, names: dict) -> list[sp.Expr] | None:
    """Non-constant factors of det J (None when the determinant is too costly)."""
    if J.shape[0] > _DETERMINANT_SIZE or sum(sp.count_ops(e) for e in J) > _DETERMINANT_OPS:
        return None
    # factored once: factor_list of the cancelled numerator (not of factor()'s result,
    # which would factor the same polynomial twice)
    numerator, _ = sp.fraction(sp.cancel(J.det(method="berkowitz")))
    _, factors = sp.factor_list(numerator)
    return [f.xreplace(names) for f, _ in factors if f.free_symbols]


def _null_direction(J, st, fixed, names) -> str:
    """The fibre coordinates spanning the numerical null space at one sample point."""
    f = sequential_lambdify(list(st.z) + list(fixed), st.definitions, J)
    z = np.random.default_rng(3).uniform(-0.7, 0.7, len(st.z))
    M = np.array(f(*z, *fixed.values()), dtype=float)
    _, s, vt = np.linalg.svd(M)
    v = vt[-1]
    unknowns = [names.get(u, u) for u in st.fs[-1]] + [f"λ{a}" for a in range(len(v) - len(st.fs[-1]))]
    parts = [f"{c:+.3g}·{u}" for c, u in zip(v, unknowns) if abs(c) > 1e-8]
    return f"null direction of the step matrix: {' '.join(parts)} (σ_min/σ_max = {s[-1] / s[0]:.1e})"


def _matrix(ctx):
    """The step matrix and its stencil: the derived ``step`` kernel's Jacobian when the
    derivation succeeds (shared with the other checks), else derived here."""
    dm = ctx.discrete
    if not dm.constraints:
        try:
            kernel = ctx.derived.kernel(KernelName.STEP)
        except ModelError:          # derive refuses singular models; measure it here
            return step_jacobian(dm)
        m, n, K = dm.groupoid.source_dim, dm.groupoid.fibre_dim, 2 * dm.order
        x0 = kernel.z[:m]
        fs = tuple(kernel.z[m + k * n:m + (k + 1) * n] for k in range(K))
        stencil = SimpleNamespace(z=kernel.z, xs=(x0,) * K, fs=fs, definitions=kernel.definitions)
        return dict(kernel.outputs)["jacobian"], stencil
    return step_jacobian(dm)


def run(ctx) -> CheckResult:
    dm = ctx.discrete
    J, st = _matrix(ctx)
    fixed = dict(zip(dm.parameters, dm.defaults)) | {dm.step: _STEP}
    n = J.shape[0]
    rank = generic_rank(J, st.z, fixed, definitions=st.definitions, seed=ctx.seed,
                        engine=engine_function)
    what = "bordered step matrix" if dm.constraints else \
        dm.groupoid.step_matrix_name(dm.order)
    names = readable(st, dm.groupoid)
    if rank is None:
        return CheckResult.failed(NAME, f"the {what} is not finite at any sample point")
    if rank < n:
        return CheckResult.failed(
            NAME, f"the {what} has rank {rank} < {n} at every sample point: L_d does not "
                  f"define a step map (degenerate Lagrangian?)",
            [_null_direction(J, st, fixed, names)], rank=rank, size=n)
    locus = ctx.budget.attempt("singular locus", singular_locus, J, names) \
        if not st.definitions else None
    if locus is SKIPPED:
        locus, where = None, ctx.budget.note("singular locus")
    elif locus is None:
        where = "singular locus not computed (matrix too large)"
    elif not locus:
        where = "its determinant never vanishes"
    else:
        where = "singular where " + " or ".join(f"{f} = 0" for f in locus)
        if len(where) > _SUMMARY:
            where = f"singular locus: {len(locus)} factor(s) of det, in data['singular_locus']"
    return CheckResult.passed(NAME, f"{what} ({n}×{n}) has full rank {rank}; {where}",
                              rank=rank, size=n, singular_locus=[str(f) for f in locus or []])
