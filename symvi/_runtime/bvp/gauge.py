"""Fixing the multipliers where the constraints are exactly dependent (:mod:`symvi.declaration.control`).

With variational controlled equations and a symmetry Z that has no actuated component,
Σ_k Z(x_k)·Φ_d^k depends on the fixed end elements only (the discrete Noether identity).
One combination of the constraint rows of the optimality system is then identically zero,
and λ^k → λ^k + c Z(x_k) leaves the stationarity rows unchanged at a feasible path: the
Newton matrix is singular. At one window w the constraint rows are replaced by

    (I − QQᵀ) Φ_d^w + QQᵀ λ^w = 0,

Q an orthonormal basis of the Z there (the compiled ``gauge`` kernel): the components of
Φ_d^w along Z are dropped, since the other constraints and the boundary data imply them,
and the multipliers' free components are set to zero. The rows are linear combinations
of rows with the same support, so the matrix stays banded. Their exact Jacobian would
also carry the derivative of Q times Φ_d^w, which vanishes at a feasible path; leaving it
out keeps Newton's local convergence.

The same identity makes boundary data inconsistent when the ends' discrete momenta
⟨p, Z⟩ differ: then no path satisfies Φ_d = 0, and :func:`check_boundary` says so.
"""
from __future__ import annotations

import numpy as np

from ..core.model_info import Kernel


class Gauge:
    """The gauge condition at the middle window of a path of ``n_nodes`` nodes."""

    def __init__(self, model, n_nodes: int):
        self.model, self.count = model, len(model.info.gauges)
        self.window = (n_nodes - 2) // 2
        n, s = model.n, model.constraints
        # window w's multipliers and constraint rows sit in block w + 1 of the layout
        # (the first block is node 1's, see assembly.Problem._blocks)
        self.rows = np.arange(s) + self.window * (n + s) + n
        self.projector = self.basis = self.lam = None

    def update(self, path, p, h) -> None:
        """Q and λ^w at ``path`` (the point where the Jacobian was assembled)."""
        w, s = self.window, self.model.constraints
        Z = self.model.along_vector(Kernel.GAUGE, path.x[w:w + 2], path.f[w:w + 2], h, p)
        Z = Z.reshape(self.count, s).T
        u, sigma, _ = np.linalg.svd(Z, full_matrices=False)
        self.basis = u[:, sigma > 1e-12 * max(sigma.max(initial=0.0), 1.0)]
        self.projector = np.eye(s) - self.basis @ self.basis.T
        self.lam = path.lam[w].copy()

    def apply(self, band: np.ndarray, bw: int, rhs: np.ndarray,
              lam: np.ndarray | None = None) -> np.ndarray:
        """Replace window w's rows of the Newton system (:meth:`replace_rows`) and of its
        right-hand side (:meth:`replace_rhs`) in the node layout; returns the new rhs."""
        self.replace_rows(band, bw, self.rows)
        return self.replace_rhs(rhs, self.rows, lam)

    def replace_rows(self, band: np.ndarray, bw: int, rows: np.ndarray) -> None:
        """Window w's constraint ``rows`` (its multipliers' columns have the same indices)
        of a matrix in LAPACK band storage (band[2 bw + row − col, col]) replaced in place
        by (I − QQᵀ) rows + QQᵀ on the multipliers."""
        cols = np.arange(max(0, rows[0] - bw), min(band.shape[1], rows[-1] + bw + 1))
        I, C = np.meshgrid(rows, cols, indexing="ij")
        inside = np.abs(I - C) <= bw
        diag = np.where(inside, 2 * bw + I - C, 0)
        M = np.where(inside, band[diag, C], 0.0)
        new = self.projector @ M
        new[:, rows - cols[0]] += self.basis @ self.basis.T
        if np.any(new[~inside]):
            raise RuntimeError("the gauge rows do not fit the band: constraint rows of one "
                               "window have different supports")
        band[diag[inside], C[inside]] = new[inside]

    def replace_rhs(self, rhs: np.ndarray, rows: np.ndarray,
                    lam: np.ndarray | None = None) -> np.ndarray:
        """The right-hand side with window w's ``rows`` replaced: (I − QQᵀ) rhs − QQᵀ λ^w.
        ``lam``: the multipliers λ^w of the path the correction starts from, when that is
        not the point of :meth:`update` (a simplified Newton correction at a trial point:
        with the old λ^w it would repeat the gauge component of the step just taken)."""
        rhs = rhs.copy()
        lam = self.lam if lam is None else lam
        rhs[rows] = self.projector @ rhs[rows] - self.basis @ (self.basis.T @ lam)
        return rhs


def _dependency_sums(model, path, h, p) -> tuple[np.ndarray, np.ndarray]:
    """(Σ_k Z(x_k)·Φ_d^k, Σ_k |Z(x_k)·Φ_d^k|) per gauge symmetry along ``path``."""
    names = model.info.gauges
    phi = model.along_vector(Kernel.CONSTRAINT, path.x, path.f, h, p)
    Z = model.along_vector(Kernel.GAUGE, path.x, path.f, h, p).reshape(phi.shape[0], len(names), -1)
    terms = np.einsum("wza,wa->zw", Z, phi)
    return terms.sum(axis=1), np.abs(terms).sum(axis=1)


def check_boundary(model, path, other, p, h, tol: float = 1e-9) -> None:
    """Raise ValueError unless Σ_k Z(x_k)·Φ_d^k is the same on ``path`` and ``other`` (two
    paths between the same ends: the declared symmetry is an exact dependency) and
    vanishes (the ends' discrete momenta agree, so that Φ_d = 0 has a solution). Both up to
    ``tol``·(1 + Σ_k |Z(x_k)·Φ_d^k|): below that the solve reaches a residual of the size
    of the mismatch, which it reports."""
    names = model.info.gauges
    (first, size), (second, size2) = _dependency_sums(model, path, h, p), \
        _dependency_sums(model, other, h, p)
    for k, name in enumerate(names):
        if abs(first[k] - second[k]) > tol * (1.0 + max(size[k], size2[k])):
            raise ValueError(
                f"the declared symmetry {name!r} is not an exact dependency of the discrete "
                f"constraints: Σ_k Z(x_k)·Φ_d^k is {first[k]:.6e} and {second[k]:.6e} on two "
                f"paths between the same ends (is L invariant under it? `symvi check` says). "
                f"Z is a section of the algebroid: on a Lie group constant coefficients Z^a, "
                f"which move every node as g ↦ g·exp(εZ) (a body-frame symmetry); a "
                f"world-frame (left) translation or rotation has Z = Ad_(g⁻¹) e, a function "
                f"of the configuration — declare the model on an action groupoid whose base "
                f"point carries it, as the heavy top's Γ = Rᵀe₃")
        if abs(first[k]) > tol * (1.0 + size[k]):
            raise ValueError(
                f"inconsistent boundary data: the constraints conserve {name!r} (a declared "
                f"symmetry), so Σ_k Z(x_k)·Φ_d^k = {first[k]:.3e} on every path between the "
                f"fixed ends and no path satisfies Φ_d = 0; the ends' discrete momenta "
                f"along Z must agree")
