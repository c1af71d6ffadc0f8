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
    if x.size != band.shape[1]:     # C reads the band's width of numbers
        raise ValueError(f"a band of {band.shape[1]} columns times {x.size} numbers")
    out = np.empty_like(x)
    model.lib.symvi_band_product(model.ptr(band.T), x.size, bw, model.ptr(x), int(absolute),
                                 model.ptr(out))
    return out


def residual(model, band: np.ndarray, bw: int, x: np.ndarray, b: np.ndarray,
             out: tuple[np.ndarray, np.ndarray], diagonal: np.ndarray | None = None) -> float:
    """r = b − (A + D) x and s = |A| |x| + |D x| + |b| into ``out`` = (r, s), D the optional
    ``diagonal``, in one pass over the band (``symvi_band_residual``); returns the
    componentwise backward error of x, max |r| / s."""
    r, s = out
    return float(model.lib.symvi_band_residual(
        model.ptr(band.T), x.size, bw, model.ffi.NULL if diagonal is None else model.ptr(diagonal),
        model.ptr(x), model.ptr(b), model.ptr(r), model.ptr(s)))


def factor(model, work: np.ndarray, bw: int, what: str,
           pivots: np.ndarray | None = None) -> np.ndarray:
    """LU of the band matrix in ``work`` (LAPACK storage, 3 bw + 1 rows, Fortran order), in
    place, by ``symvi_band_factor`` (LAPACK's dgbtf2 without its per-column BLAS calls:
    rigid_body_oc at N = 1000, 0.29 ms against 0.64 ms for dgbsv's factorisation and
    solve); returns the pivots
    (written into ``pivots``, C ints, when given). Raises LinAlgError naming ``what`` and
    the column of a zero pivot."""
    from scipy.linalg import LinAlgError

    if pivots is None:
        pivots = np.empty(work.shape[1], dtype=np.intc)
    info = model.lib.symvi_band_factor(model.ptr(work.T), work.shape[1], bw,
                                       model.ffi.from_buffer("int[]", pivots))
    if info != 0:
        raise LinAlgError(f"{what}: singular at column {info}")
    return pivots


def positive_definite(model, ab: np.ndarray, bw: int, shift: float) -> bool:
    """Whether sym(A) + shift·I is positive definite, A in full LAPACK storage."""
    return cholesky_pivot(model, ab, bw, shift) is None


def cholesky_pivot(model, ab: np.ndarray, bw: int, shift: float = 0.0) -> float | None:
    """None when sym(A) + shift·I is positive definite, else the first pivot of its band
    Cholesky factorisation that is not positive (A in full LAPACK storage; the symmetric
    part assembled and factorised in C, ``symvi_band_cholesky``)."""
    size = ab.shape[1]
    lower = np.empty((bw + 1) * size)
    column = int(model.lib.symvi_band_cholesky(model.ptr(ab.T), size, bw, float(shift),
                                               model.ptr(lower)))
    return None if column < 0 else float(lower[column * (bw + 1)])


def lu_solve(model, lu: np.ndarray, bw: int, pivots: np.ndarray, b: np.ndarray) -> np.ndarray:
    """b ← A⁻¹ b in place (a C-contiguous float64 vector), from the LU of A in LAPACK's
    layout (``lu``, ``pivots``: from :func:`factor`, or dgbtrf), in C
    (``symvi_band_solve``): the arithmetic of ``dgbtrs`` without its per-column BLAS calls
    on vectors of bw entries (9·10⁵ unknowns, bw = 14: 79 ms against 168 ms)."""
    model.lib.symvi_band_solve(model.ptr(lu.T), b.size, bw,
                               model.ffi.from_buffer("int[]", pivots), model.ptr(b))
    return b


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


def rounding_level(model, ab: np.ndarray, bw: int, u: np.ndarray) -> float:
    """Attainable residual: 16 ε ‖ |J| u ‖∞, u the unknowns' magnitudes (first order);
    ``ab`` holds J in LAPACK band storage, ab[2 bw + row − col, col] = J[row, col].

    When the line search finds no descent from a residual below it, Newton has converged
    as far as floating point allows, even if its update, amplified by the condition
    number (∝ N⁴ for fourth differences), still exceeds xtol.
    """
    scale = product(model, ab, bw, u, absolute=True)
    return 16 * np.finfo(float).eps * float(scale.max(initial=0.0))
