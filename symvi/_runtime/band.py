"""Banded linear algebra in LAPACK's storage (ab[2 bw + row − col, col] = A[row, col],
kl = ku = bw): products and condition estimates for the Newton systems of
:mod:`.assembly` and :mod:`.lifted`."""
from __future__ import annotations

import numpy as np


def product(model, band: np.ndarray, bw: int, x: np.ndarray,
            absolute: bool = False) -> np.ndarray:
    """A x, or |A| |x| when ``absolute``, in C (``symvi_band_product``), A in full LAPACK
    storage (3 bw + 1 rows, Fortran order): a NumPy loop over the diagonals strides through
    memory, 0.3 s for the lifted system at N = 10⁵ against 10 ms."""
    x = np.ascontiguousarray(x, dtype=float)
    out = np.empty_like(x)
    model.lib.symvi_band_product(model.ptr(band.T), x.size, bw, model.ptr(x), int(absolute),
                                 model.ptr(out))
    return out


#: Matrices up to this many unknowns have their condition estimated by LAPACK's dgbcon:
#: deterministic, but O(size²) on an ill-conditioned factor (0.16 s at 12 000 unknowns,
#: 90 s at 3·10⁵). Larger ones by SciPy's randomised ``onenormest``, O(size).
DGBCON_UP_TO = 10_000


def reciprocal_condition(work: np.ndarray, bw: int) -> float:
    """1/κ₁ of the band matrix in ``work`` (LAPACK storage, kl = ku = bw; overwritten by
    its LU): LAPACK's estimate (dgbcon) up to :data:`DGBCON_UP_TO` unknowns, beyond it
    ‖A⁻¹‖₁ by Higham and Tisseur's block estimator (SciPy's ``onenormest``) on solves
    with the banded LU. The latter starts from random vectors (NumPy's global generator),
    so two runs may differ by some ten per cent."""
    from scipy.linalg.lapack import dgbcon, dgbtrf, dgbtrs
    from scipy.sparse.linalg import LinearOperator, onenormest

    norm = float(np.abs(work[bw:]).sum(axis=0).max(initial=0.0))
    lu, pivots, info = dgbtrf(work, bw, bw, overwrite_ab=True)
    if info != 0 or norm == 0.0:
        return 0.0
    size = lu.shape[1]
    if size <= DGBCON_UP_TO:
        rcond, info = dgbcon(bw, bw, lu, pivots, norm)
        return float(rcond) if info == 0 else 0.0

    def solve(v, trans=0):
        return dgbtrs(lu, bw, bw, np.asarray(v, dtype=float), pivots, trans=trans)[0]
    inverse = LinearOperator((size, size), matvec=solve, rmatvec=lambda v: solve(v, 1),
                             dtype=float)
    estimate = onenormest(inverse, t=8)
    return 1.0 / (norm * estimate) if np.isfinite(estimate) and estimate > 0 else 0.0
