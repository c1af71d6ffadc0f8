"""Second-order optimality and inertia correction for optimal-control solves (issue 20,
item 3).

Newton finds KKT points of the discrete cost S = Σ L_d subject to the discrete
constraints Φ_d = 0 (paper §3.2, eq. ``constrainedso``); a KKT point is a strict local
minimum when the Hessian W of S + λ·Φ_d is positive definite on the constraints' tangent
space ker A, A = ∂Φ_d/∂η (second-order sufficient conditions, Nocedal & Wright Thm 12.6),
and a saddle when it has negative curvature there (Thm 12.5).

The test (Debreu's lemma; Bertsekas, *Constrained Optimization and Lagrange Multiplier
Methods*, Lemma 1.25): ZᵀWZ is positive definite iff W + ρAᵀA is for every ρ above some
ρ̄. A Cholesky factorisation that succeeds for some ρ proves the minimum — for d ∈ ker A,
dᵀWd = dᵀ(W + ρAᵀA)d > 0 — so a SUCCESS never rests on a saddle. Both matrices are banded
in the node ordering, so each factorisation costs O(N b²) with LAPACK's band Cholesky
(LAPACK has no band LDLᵀ that would give the KKT matrix's inertia directly). ρ grows
geometrically from the ratio of the two matrices' scales; the largest is limited by
rounding (ρ‖AᵀA‖ε must stay below W's smallest curvature on ker A), so a verdict "not a
minimum" reports the most negative pivot met.

Rounding decides the test where it is not guarded: a factorisation of W + ρAᵀA carries
errors of the size τ = (b + 1)·ε·max|diag| (b its bandwidth), and at ρ = 10⁶ times the
scale ratio that τ exceeds small negative curvatures on ker A — a hunt shifted the
cart-pole's minimum at N = 150 (smallest reduced eigenvalue +2.5) down by σI and the
plain test accepted reduced minima as negative as −2.5e-4. So ρ is accepted only where
W + ρAᵀA − τI factorises: that rejected every such shifted saddle and all 200 saddles
met in 3944 solves, and accepted all 3129 verified minima at the same ρ as before.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Multiples of the scale ratio ‖W‖/‖AᵀA‖ tried as the penalty ρ.
PENALTIES = (0.0, 1.0, 1e2, 1e4, 1e6)


@dataclass(frozen=True)
class Curvature:
    """Outcome of the second-order test: ``minimum`` when W + ρAᵀA was factorised (at
    ``rho``), else the first non-positive Cholesky pivot met at the largest ρ."""

    minimum: bool
    rho: float
    pivot: float


def second_order(ab: np.ndarray, bw: int, constraint_rows: np.ndarray,
                 pivot=None, gram: list | None = None) -> Curvature:
    """The second-order test at a KKT point, from the Newton matrix in the band storage of
    ``assembly.Problem.assemble`` (ab[2 bw + row − col, col] = J[row, col]) and the mask of its
    constraint rows (= multiplier columns). ``pivot``: without constraints, a function
    giving the first non-positive Cholesky pivot of sym(J), or None when there is none
    (:func:`.band.cholesky_pivot`, in C); by default LAPACK's. ``gram``: the caller's
    memo of AᵀA (:func:`_gram`), for tests repeated on the same constraint rows."""
    if pivot is not None and not constraint_rows.any():
        bad = pivot()
        return Curvature(bad is None, 0.0, 0.0 if bad is None else bad)
    W, Ab, ratio = _blocks(ab, bw, constraint_rows, gram)
    pivot = -np.inf
    for k, band in _penalised(W, Ab, ratio):
        pivot = _first_bad_pivot(_rounding_shifted(band))
        if pivot is None:
            return Curvature(True, k, 0.0)
    return Curvature(False, PENALTIES[-1] * ratio, pivot)   # ratio is 0 without constraints


def _penalised(W, Ab, ratio: float):
    """(ρ, W + ρAᵀA in lower band storage) for ρ = PENALTIES × ``ratio``: W's band and
    AᵀA's (from :func:`_blocks`), combined per ρ as band arrays (a sparse sum and
    conversion per ρ, with :func:`_blocks`' sparse selections, cost the cart-pole
    swing-up at N = 100 three quarters of its solve)."""
    yield 0.0, W
    if Ab is None:
        return
    width = max(len(W), len(Ab))
    Wp, Ap = np.zeros((width, W.shape[1])), np.zeros((width, Ab.shape[1]))
    Wp[:len(W)], Ap[:len(Ab)] = W, Ab
    for k in PENALTIES[1:]:
        yield k * ratio, Wp + (k * ratio) * Ap


def _rounding_shifted(band: np.ndarray) -> np.ndarray:
    """band − τI, τ = (b + 1)·ε·max|diag| the rounding of its Cholesky factorisation
    (module docstring): definite only with a margin above rounding. Pinned rows (fixed
    nodes in the block layout: an identity row and column) keep their 1."""
    width, n = band.shape
    tau = width * np.finfo(float).eps * float(np.abs(band[0]).max(initial=0.0))
    coupled = band[1:].any(axis=0)              # entries below the diagonal, then beside it
    for k in range(1, width):
        coupled[k:] |= band[k, :n - k] != 0.0
    shifted = band.copy()
    shifted[0] -= np.where((band[0] == 1.0) & ~coupled, 0.0, tau)
    return shifted


#: The inertia correction's shifts δ, relative to W's largest diagonal entry: from
#: FIRST_SHIFT by ×100 up to 1e-8, then by ×10 up to MAX_SHIFT (:func:`next_shift`).
#: Small first: W is a discrete fourth derivative whose smooth modes' eigenvalues are
#: ≈ max|diag| / N⁴ (1e-12 at N = 1000), and a shift far above them cuts the step along
#: exactly the modes a solve must travel. From a first shift of 1e-8 the cart-pole
#: swing-up without bounds took 112 Newton iterations at N = 1000 and 73 at N = 10⁴,
#: each step cut to α ≈ 0.005 by a shift of 1e-10 left over; from 1e-16, 36 at both.
FIRST_SHIFT, MAX_SHIFT = 1e-16, 1e3


#: The first shift of issue 21's interior point, which an interior point from a start
#: near a solution keeps (:class:`.bounded.interior.InteriorPoint`'s ``near``): from
#: FIRST_SHIFT, one of ten perturbed starts of the cart-pole swing-up at N = 1000 ran
#: out of iterations on that route, where all ten succeed from this one.
NEAR_FIRST_SHIFT = 1e-8


def next_shift(shift: float, first: float = FIRST_SHIFT) -> float:
    """The inertia correction's next shift after ``shift`` (0: none yet), from ``first``."""
    if shift < first:
        return first
    return 100.0 * shift if shift < 1e-8 else 10.0 * shift


def convexifying_shift(definite, start: float, first: float = FIRST_SHIFT) -> float:
    """For a problem without constraints: the smallest μ in start, then
    :func:`next_shift`'s ladder (up to 1e3; relative to W's largest diagonal entry) for
    which ``definite(μ)``,
    W + μ·max|diag W|·I positive definite, else inf — the inertia correction of a
    modified Newton step (Nocedal & Wright §3.4, Algorithm 3.3), so that every step is a
    descent direction of S that no saddle or maximum attracts. (From the zero guess:
    rigid_body_oc at N = 1000 in 17 iterations instead of 353; double_pendulum_oc at
    N = 1000 from a perturbed guess to the minimum instead of a saddle of 65× its
    cost.)"""
    mu = start
    while mu <= MAX_SHIFT:
        if definite(mu):
            return mu
        mu = next_shift(mu, first)
    return np.inf


def _blocks(ab, bw, constraint_rows, gram: list | None = None):
    """(W, AᵀA, ‖W‖/‖AᵀA‖) of the Newton matrix: W symmetrised (symmetric at a KKT point,
    off it by rounding) and AᵀA (None without constraints), both in lower band storage
    in the node ordering. Read from the band's entries directly: a sparse copy of J and
    its row and column selections cost the cart-pole swing-up at N = 100 half its solve
    (the interior point's inertia tests call this on every iteration). AᵀA is kept for
    the same A in ``gram`` (:func:`_gram`): the inertia tests of one iteration share it."""
    if not constraint_rows.any():
        return _node_band(ab, bw), None, 0.0
    n = ab.shape[1]
    d = np.arange(-bw, bw + 1)[:, None]               # row − column
    c = np.broadcast_to(np.arange(n), (2 * bw + 1, n))
    r = c + d
    vals = ab[bw:3 * bw + 1]                          # ab[2 bw + d, c] = J[c + d, c]
    keep = (r >= 0) & (r < n) & (vals != 0.0)
    r, c, vals = r[keep], c[keep], vals[keep]
    nodes = ~constraint_rows
    position = np.cumsum(nodes) - 1                   # index among the nodes
    both = nodes[r] & nodes[c]
    i, j = position[r[both]], position[c[both]]
    w = np.where(i == j, 1.0, 0.5) * vals[both]
    low = i >= j                                      # (W + Wᵀ)/2: each entry, and mirrored
    size = int(nodes.sum())
    width = int(np.abs(i - j).max(initial=0))
    W = np.bincount(np.where(low, i - j, j - i) * size + np.where(low, j, i), weights=w,
                    minlength=(width + 1) * size).reshape(width + 1, size)
    rows = constraint_rows[r] & nodes[c]
    Ab = _gram(vals[rows], np.cumsum(constraint_rows)[r[rows]] - 1, position[c[rows]],
               (int(constraint_rows.sum()), size), gram)
    scale_a = float(np.abs(Ab[0]).max(initial=0.0))
    ratio = float(np.abs(W[0]).max(initial=0.0)) / scale_a if scale_a > 0 else 0.0
    return W, Ab, ratio


def _gram(values: np.ndarray, rows: np.ndarray, cols: np.ndarray, shape,
          last: list | None) -> np.ndarray:
    """AᵀA in lower band storage for the sparse A of entries ``values`` at (``rows``,
    ``cols``); ``last``, the caller's one-entry memo ([(key, band)] or [None]): the last
    one's again where A is the same (the inertia correction's shifts and the minimum
    test's penalties change W only; the cart-pole swing-up at N = 100 spent 40 % of its
    solve forming AᵀA)."""
    key = (shape, values.tobytes(), rows.tobytes(), cols.tobytes())
    if last is not None and last[0] is not None and last[0][0] == key:
        return last[0][1]
    band = _gram_band(values, rows, cols, shape)
    if last is not None:
        last[0] = (key, band)
    return band


def _gram_band(values: np.ndarray, rows: np.ndarray, cols: np.ndarray, shape) -> np.ndarray:
    """AᵀA in lower band storage from A's entries, as the sum over A's rows of their
    outer products, each row's entries padded to the longest row's count: NumPy alone,
    where SciPy's sparse product and conversions cost the cart-pole swing-up at N = 100
    a quarter of its solve (0.46 ms per interior-point iteration)."""
    size = shape[1]
    if values.size == 0:
        return np.zeros((1, size))
    order = np.argsort(rows, kind="stable")
    rows, cols, values = rows[order], cols[order], values[order]
    counts = np.bincount(rows, minlength=shape[0])
    first = np.cumsum(counts) - counts
    slot = np.arange(rows.size) - first[rows]          # index within its row
    padded_cols = np.zeros((shape[0], int(counts.max())), dtype=np.intp)
    padded = np.zeros(padded_cols.shape)
    padded_cols[rows, slot], padded[rows, slot] = cols, values
    i, j = padded_cols[:, :, None], padded_cols[:, None, :]
    products = padded[:, :, None] * padded[:, None, :]
    low = (i >= j) & (products != 0.0)
    offsets, columns = (i - j)[low], np.broadcast_to(j, low.shape)[low]
    width = int(offsets.max(initial=0))
    return np.bincount(offsets * size + columns, weights=products[low],
                       minlength=(width + 1) * size).reshape(width + 1, size)


def _node_band(ab: np.ndarray, bw: int) -> np.ndarray:
    """The symmetric part of J (all of it node rows) in lower band storage, straight from
    the general band: lower[k, j] = (J[j+k, j] + J[j, j+k]) / 2."""
    n = ab.shape[1]
    lower = np.zeros((bw + 1, n))
    lower[0] = ab[2 * bw]
    for k in range(1, min(bw, n - 1) + 1):
        lower[k, :n - k] = 0.5 * (ab[2 * bw + k, :n - k] + ab[2 * bw - k, k:])
    return lower


def _sparse(ab: np.ndarray, bw: int):
    from scipy.sparse import dia_matrix

    n = ab.shape[1]
    return dia_matrix((ab[bw:], bw - np.arange(2 * bw + 1)), shape=(n, n)).tocsr()


def _first_bad_pivot(band: np.ndarray) -> float | None:
    """None when the band Cholesky factorisation (LAPACK dpbtrf) succeeds, else the first
    non-positive pivot (its size tells negative curvature from rounding)."""
    from scipy.linalg.lapack import dpbtrf

    if not np.isfinite(band).all():
        return -np.inf
    factor, info = dpbtrf(band, lower=1)
    if info == 0:
        return None
    return float(factor[0, info - 1]) if info > 0 else -np.inf
