"""Active-set Newton on the interior point's identified active set (issue 21).

Near the end of an interior-point solve the barrier's reduced matrix W + GᵀΣG carries
Σ = z/s ≈ 10¹² on the active rows beside W's curvature, and its solves are rounding in
the directions along the active constraints: the planar flyer at N = 400 and 1000
hovered at KKT corrections of 10⁻⁸–10⁻⁵ (tolerance 3·10⁻⁹) and ended ILL_CONDITIONED. The
same optimum solves the KKT system of the equality-constrained problem in which the
active rows 𝒜 (z > s) are equalities and the others are dropped (z = 0),

    [ J    G_𝒜ᵀ ] [Δ ]     [ ∇ℒ  ]
    [ G_𝒜   0   ] [Δz] = − [ c_𝒜 ],

J the equality solver's Newton matrix (W with the multipliers z in the augmented window
Lagrangian, A, the pinned rows) and ∇ℒ its residual. This saddle-point matrix is
well conditioned where the active constraints are independent and the Hessian is
positive definite on their tangent space (the second-order sufficient conditions
:meth:`.interior.InteriorPoint.minimum` tests), so Newton converges quadratically from
the interior point's iterate: the flyer at N = 1000 from corrections 1.7e-8 (nodes) and
4.2e-6 (z) to 5.6e-14 and 7.0e-11 in three steps. It is not the banded system of the
iteration — its unknowns add a multiplier per window and inequality — so it is
assembled sparse and factorised by SuperLU (SciPy), and used only to finish.

The result is accepted only where it is a KKT point of the inequality-constrained
problem within the tolerance: the last Newton correction plus its rounding floor (the
change of that correction when every unknown moves by one unit in the last place) within
xtol·(1 + size), every active multiplier z ≥ 0 and every dropped inequality c ≤ that
tolerance. Anything else — a wrong active set, dependent active constraints — returns
None and leaves the interior point's verdict.
"""
from __future__ import annotations

import numpy as np

from .paths import Path

#: Most Newton steps per active set, and most active sets tried: as in a primal
#: active-set method, one inequality changes at a time — the most negative multiplier
#: leaves, else the most violated dropped inequality joins — and Newton starts from the
#: last converged point (the cart-pole swing-up at N = 700: three track windows active at
#: the interior point's iterate, of which one leaves; the flyer at N = 1000: one joins).
STEPS, ROUNDS = 6, 8


def polish(ip, path: Path, tolerance: float):
    """(path, slacks, message) of the active-set Newton from the interior point ``ip``'s
    ``path`` (module docstring), or None where it does not end at a KKT point within
    ``tolerance``. ``ip``'s state is left as it was."""
    if ip.problem.gauge is not None:
        return None     # replaced rows of exactly dependent constraints: not this system
    active, total = ip.z(path) > ip.s, 0
    for _ in range(ROUNDS):
        converged = _newton(ip, path, active, tolerance)
        if converged is None:
            return None
        path, steps, correction, floor = converged
        total += steps
        ineq = ip.inequalities
        if not ineq.evaluate(path, ip.problem.p, ip.problem.h):
            return None
        z, c = ip.z(path), ineq.values
        negative = np.where(active, z, np.inf)
        violated = np.where(active, -np.inf, c)
        if negative.min() < 0.0:
            active = active.copy()
            active[np.unravel_index(int(np.argmin(negative)), active.shape)] = False
        elif violated.max() > tolerance:
            active = active.copy()
            active[np.unravel_index(int(np.argmax(violated)), active.shape)] = True
        else:
            return _accepted(ip, path, active, tolerance, total, correction, floor)
    return None


def _newton(ip, path: Path, active: np.ndarray, tolerance: float):
    """(path, steps, correction, floor) where Newton on the KKT system of the active set
    ``active`` (as equalities, the other multipliers 0) from ``path`` converged within
    ``tolerance`` with its rounding floor; else None."""
    problem = ip.problem
    path = path.copy()
    path.lam[:, ip.s_count:] = np.where(active, ip.z(path), 0.0)
    for step in range(STEPS):
        newton = _correction(ip, path, active)
        if newton is None:
            return None
        delta, dz = newton
        correction = max(float(np.abs(delta).max(initial=0.0)),
                         float(np.abs(dz).max(initial=0.0)))
        if correction <= tolerance:
            floor = _floor(ip, path, active, delta, dz)
            if correction + floor <= tolerance:
                return path, step, correction, floor
        moved = problem.moved(path, delta, 1.0)
        if moved is None:
            return None
        moved.lam[:, ip.s_count:][active] += dz
        path = moved
    return None


def _correction(ip, path: Path, active: np.ndarray):
    """(Δ in the block layout, Δz of the active rows) of the active-set Newton step at
    ``path``, or None where something is not finite or the matrix is singular."""
    from scipy.sparse import bmat, csr_matrix, dia_matrix
    from scipy.sparse.linalg import splu

    problem, ineq = ip.problem, ip.inequalities
    res, ab, bw, finite = problem.assemble(path, True)
    if not (finite and ineq.evaluate(path, problem.p, problem.h, with_jacobian=True)):
        return None
    size = ab.shape[1]
    J = dia_matrix((ab[bw:], bw - np.arange(2 * bw + 1)), shape=(size, size))
    G = _block_jacobian(ip, active)
    rows = G.shape[0]
    K = bmat([[J, G.T], [G, csr_matrix((rows, rows))]], format="csc")
    rhs = -np.concatenate([res, ineq.values[active]])
    try:
        lu = splu(K)
    except RuntimeError:        # exactly singular: dependent active constraints
        return None
    x = lu.solve(rhs)
    x += lu.solve(rhs - K @ x)      # one refinement: SuperLU's pivoting is threshold-based
    if not np.isfinite(x).all():
        return None
    return x[:size], x[size:]


def _block_jacobian(ip, active: np.ndarray):
    """G_𝒜 in the block layout of the reduced system: the active rows' gradients with
    respect to the free nodes' corrections (:attr:`.barrier.Inequalities.jacobian`)."""
    from scipy.sparse import csr_matrix

    model, ineq = ip.model, ip.inequalities
    n, r = model.n, model.order
    position = np.full(ineq.n_nodes, -1)
    position[ip.blocks] = np.arange(len(ip.blocks)) * ip.width
    position[:r], position[ineq.n_nodes - r:] = -1, -1     # fixed nodes do not move
    windows, which = np.nonzero(active)
    row_of = np.arange(len(windows))
    rows, cols, vals = [], [], []
    for j in range(r + 1):
        at = position[windows + j]
        free = at >= 0
        rows.append(np.repeat(row_of[free], n))
        cols.append((at[free][:, None] + np.arange(n)).ravel())
        vals.append(ineq.jacobian[windows[free], which[free], j * n:(j + 1) * n].ravel())
    size = len(ip.blocks) * ip.width
    return csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(len(windows), size))


def _floor(ip, path: Path, active: np.ndarray, delta: np.ndarray, dz: np.ndarray) -> float:
    """‖·‖∞ of the change in the active-set correction when every node, λ and active z
    moves by one unit in the last place in a fixed random direction: the noise under it
    (as :meth:`.interior.InteriorPoint.rounding_floor`)."""
    problem, eps = ip.problem, np.finfo(float).eps
    rng = np.random.default_rng(0)
    rounded = problem.moved(path, eps * rng.choice((-1.0, 1.0), delta.size)
                            * problem.magnitudes(path), 1.0)
    if rounded is None:
        return np.inf
    rounded.lam[:, ip.s_count:][active] *= 1.0 + eps * rng.choice((-1.0, 1.0), dz.size)
    other = _correction(ip, rounded, active)
    if other is None:
        return np.inf
    return max(float(np.abs(other[0] - delta).max(initial=0.0)),
               float(np.abs(other[1] - dz).max(initial=0.0)))


def _accepted(ip, path: Path, active: np.ndarray, tolerance: float, steps: int,
              correction: float, floor: float):
    """(path, slacks, message) at ``path``, a KKT point of the bounded problem within
    ``tolerance`` (z ≥ 0 on the active rows, c ≤ tolerance on the others, the
    inequalities evaluated there)."""
    c, z = ip.inequalities.values, ip.z(path)
    # slacks consistent with the active set, for the result's `active` (z > s)
    slacks = np.where(active, np.minimum(np.maximum(-c, 0.0), 0.5 * z), np.maximum(-c, 0.0))
    primal = float(np.maximum(c, 0.0).max(initial=0.0))
    return path, slacks, (
        f"; finished by {steps} active-set Newton step{'s' if steps != 1 else ''} on the "
        f"{int(active.sum())} active inequalities: Newton correction of the KKT system "
        f"(μ = 0) {correction:.1e}, rounding floor {floor:.1e}, within xtol·(1 + size) = "
        f"{tolerance:.1e}, primal infeasibility {primal:.1e}")
