"""The second-order test at a vertex (issue 50): where the equalities and the active
inequalities fix every unknown, a KKT point with positive multipliers on them is a strict
local minimum whatever the Hessian — its critical cone is {0} (the first-order sufficient
conditions; Nocedal & Wright, Theorem 12.6 with an empty tangent space).

Pure minimum time ends on such points: T and every node are fixed by the controls' bounds,
one per window. There Debreu's test of :meth:`.interior.InteriorPoint.minimum`, W + ρG_𝒜ᵀG_𝒜
positive definite for a bounded ρ, fails where W is indefinite (the torque-limited
pendulum's z·∇²c, g·sin θ): G_𝒜 is a second difference whose smallest singular value is
N² times below its largest, so no ρ of the ladder reaches it — a false SADDLE at the
minimum IPOPT finds too.
"""
from __future__ import annotations

import numpy as np

from .polish import block_jacobian, both_sides, sparse_lu

#: The largest 1-norm condition number of the rows fixing the unknowns at a vertex
#: (estimated: Hager–Higham) beyond which they count as dependent: 10⁻³/ε. The pendulum's
#: second differences: 2.1·10³ at N = 60, 5.3·10³ at N = 100.
CONDITION = 1e-3 / np.finfo(float).eps


def fixes_every_unknown(ip, ab, bw: int, active: np.ndarray,
                        rates: np.ndarray | None) -> bool:
    """Whether the equality rows and the ``active`` inequalities have full rank in the
    free unknowns (the node corrections not pinned, and σ = log T where the horizon is
    free: ``rates`` its g_σ, else None) and at least as many rows as those: their
    tangent space is {0}. ``ab`` is the Newton matrix in band storage at the point."""
    from scipy.sparse import csc_matrix, dia_matrix, hstack, vstack
    from scipy.sparse.linalg import LinearOperator, onenormest

    if both_sides(ip.model, active):
        return False
    size = ab.shape[1]
    J = csc_matrix(dia_matrix((ab[bw:], bw - np.arange(2 * bw + 1)), shape=(size, size)))
    equality = ip.rows[:size]
    free = ~equality & ~_pinned(J)
    G = block_jacobian(ip, active)
    A = J[np.flatnonzero(equality)][:, np.flatnonzero(free)]
    G = G.tocsc()[:, np.flatnonzero(free)]
    if rates is not None:
        b, _ = ip.problem.raw
        A = hstack([A, csc_matrix(b[:size][equality][:, None])])
        G = hstack([G, csc_matrix(rates[active][:, None])])
    M = vstack([A, G]).tocsr()
    M = M[np.flatnonzero(np.diff(M.indptr))]       # pinned multipliers' rows are empty
    if M.shape[0] < M.shape[1]:
        return False
    square = csc_matrix(M if M.shape[0] == M.shape[1] else M.T @ M)
    lu = sparse_lu(square)
    if lu is None:              # singular: a direction no row fixes
        return False
    # and not singular up to rounding (a dependence that rounding hides from the pivots)
    inverse = LinearOperator(square.shape, matvec=lu.solve, rmatvec=lambda v: lu.solve(v, "T"),
                             dtype=float)
    return onenormest(square) * onenormest(inverse) <= CONDITION


def _pinned(J) -> np.ndarray:
    """Columns of J that are a pinned unknown's: an identity row and column (a fixed
    node's correction, a multiplier past the last window)."""
    nonzero = J.copy()
    nonzero.data = (nonzero.data != 0).astype(float)
    diagonal = J.diagonal()
    return (np.asarray(nonzero.sum(axis=0)).ravel() == 1) & \
        (np.asarray(nonzero.sum(axis=1)).ravel() == 1) & (diagonal == 1.0)
