"""The lifted Newton system of a second-order whole-trajectory solve (``templates/lifted.c.j2``).

The node formulation's Newton matrix J (:mod:`.assembly`) is a discrete fourth derivative:
its condition number grows like N⁴ and passes 1/ε near N = 10⁵, where its banded LU
returns corrections without a correct digit. The same correction J η = −R solves a system
with the node corrections η, the elements' increment changes u and their momentum
changes μ as unknowns (the discrete-mechanics analogue of multiple shooting): its rows
are the node residuals, the momenta's definitions and the elements' composability, each
a first or second difference. Its condition number after equilibration grows like N²
(measured exponents 2.0 on cubic_spline and 1.8–1.9 on rigid_body_oc, against 4.0 for
J; tests/test_lifted.py). It is factorised after Ruiz equilibration and a solve is
refined (at most :data:`REFINEMENTS` times) while its componentwise backward error
exceeds 4ε, so that at N = 10⁶ (κ ≈ 10¹³) the steps stay accurate: cubic_spline
converges within 2e-11 of the exact cubic at N = 10⁶ and 3e-12 at 10⁵, where J's LU
reached 4e-5. It has three times J's unknowns and a band of 5n − 1 diagonals on either
side instead of 3n − 1, so it is used where J loses accuracy (:data:`LIFT_FROM`).
"""
from __future__ import annotations

import numpy as np

from .band import factor, lu_solve, residual

#: Most steps of iterative refinement after a solve whose componentwise backward error
#: exceeds 4ε: at N = 10⁶ (κ ≈ 10¹³ equilibrated) one LU solve can leave errors in the
#: step's roughest components whose curvature ≈ h⁻³ turns them into residuals above the
#: path's own (cubic_spline: the line search STALLED without equilibration and refinement).
REFINEMENTS = 2

#: Number of steps from which the lifted system solves the Newton steps: below it J's
#: conditioning (≈ N⁴ / 10) leaves at least six correct digits, and its LU is cheaper.
LIFT_FROM = 2000


class LiftedSystem:
    """The lifted matrix at one path, its LU, and Newton corrections from it."""

    def __init__(self, model, n_nodes: int):
        self.model, self.n_nodes = model, n_nodes
        self.bw = int(model.lib.symvi_lifted_bandwidth())
        size = int(model.lib.symvi_lifted_unknowns(n_nodes))
        # both written whole before they are read (the assembly zeroes the band)
        self.band = np.empty((3 * self.bw + 1, size), order="F")
        self.work = np.empty_like(self.band, order="F")
        n = model.n
        # η_t of the node layout's block t − 2 sits at (t − 1)·3n in the lifted layout
        nodes = np.arange(2, n_nodes - 2)
        self.eta = ((nodes[:, None] - 1) * 3 * n + np.arange(n)).reshape(-1)
        self._factored = self._scaling = None
        # Kept: right-hand side, solution, residual and its scale; R, C and the
        # equilibration's scratch; the pivots. Fresh vectors of this size are fresh pages:
        # faulting them in cost a quarter of a solve at N = 10⁵.
        self._vectors = tuple(np.zeros(size) for _ in range(4))
        self._scales = tuple(np.zeros(size) for _ in range(4))
        self._pivots = np.zeros(size, dtype=np.intc)

    def assemble(self, path, p, h: float) -> bool:
        """The lifted matrix at ``path``; False on a non-finite entry."""
        m = self.model
        self._factored = self._scaling = None
        code = m.lib.symvi_lifted_assemble(m.ptr(path.x), m.ptr(path.f), self.n_nodes,
                                           m.ptr(p), h, m.ptr(self.band.T))
        return code == 0

    def solve(self, rhs: np.ndarray, shift: float = 0.0,
              shifted: np.ndarray | None = None) -> np.ndarray:
        """η with (J + shift·D) η = rhs, D the identity on the node unknowns ``shifted``
        (a mask in the node layout; default all). The LU is kept for further solves with
        the same shift until the next assembly (a simplified Newton step reuses it)."""
        key = (shift, None if shifted is None or not shift else shifted.tobytes())
        if self._factored is None or self._factored[0] != key:
            self._factor(key, shift, shifted)
        _, pivots, diagonal = self._factored
        b, x, r, s = self._vectors
        b.fill(0.0)
        b[self.eta] = rhs
        self._lu_solve(pivots, b, x)
        for _ in range(REFINEMENTS):
            error = residual(self.model, self.band, self.bw, x, b, (r, s), diagonal)
            if error <= 4 * np.finfo(float).eps:
                break       # backward stable already (N ≤ 10⁵ after equilibration)
            x += self._lu_solve(pivots, r, r)
        return x[self.eta]

    def _factor(self, key, shift: float, shifted: np.ndarray | None) -> None:
        """LU of the equilibrated (and shifted) lifted matrix in the work band."""
        self._factored = None
        np.copyto(self.work, self.band)
        diagonal = None
        if shift:
            diagonal = np.zeros(self.band.shape[1])
            diagonal[self.eta] = shift if shifted is None else shift * shifted
            self.work[2 * self.bw] += diagonal
        if self._scaling is None:
            self._scaling = self._equilibrate()
        else:
            _scale(self.work, self.bw, *self._scaling)
        pivots = factor(self.model, self.work, self.bw, "band LU of the lifted system",
                        self._pivots)
        self._factored = (key, pivots, diagonal)

    def _lu_solve(self, pivots, b: np.ndarray, out: np.ndarray) -> np.ndarray:
        """out = C (R A C)⁻¹ R b = A⁻¹ b from the equilibrated LU in the work band (``out``
        may be ``b``)."""
        rows, cols = self._scaling
        np.multiply(rows, b, out=out)
        lu_solve(self.model, self.work, self.bw, pivots, out)
        out *= cols
        return out

    def _equilibrate(self, sweeps: int = 2) -> tuple[np.ndarray, np.ndarray]:
        """Scale the work band in place to R A C by Ruiz's iteration (C:
        ``symvi_lifted_equilibrate``); returns (R, C). The u columns carry the momenta's
        curvature ≈ 1/h³ beside composability's unit entries: unscaled, partial pivoting's
        backward error ε·max|column| erases those at N = 10⁶ (h⁻³ = 10¹⁸; cubic_spline
        STALLED there)."""
        m, (rows, cols, big, following) = self.model, self._scales
        m.lib.symvi_lifted_equilibrate(m.ptr(self.work.T), self.n_nodes, sweeps, m.ptr(rows),
                                       m.ptr(cols), m.ptr(big), m.ptr(following))
        return rows, cols

    def minimum(self, shift: float = 0.0) -> tuple[bool, int]:
        """Whether J + shift·I is positive definite, from the inertia of the lifted
        matrix: (verdict, negative eigenvalues beyond the momenta's, −1 when a pivot
        vanished and the count is incomplete).

        With the momenta's sign flipped the lifted matrix is the KKT matrix
        [[W, Aᵀ], [A, 0]] of the quadratic model in (η, u) under composability (A of full
        row rank), whose inertia is that of J = ZᵀWZ plus one positive and one negative
        eigenvalue per constraint (Gould 1985): J is positive definite iff there is
        exactly one negative eigenvalue per momentum. LAPACK has no band LDLᵀ, so the C
        (``symvi_lifted_inertia``) eliminates it block by block with Bunch–Parlett
        pivoting inside each block, in blocks (μ_{t−1}, η_t, u_t) where no block is a
        near-singular saddle. J itself cannot answer at large N: its smallest eigenvalue
        (≈ h π⁴) is below the rounding of its largest entries (≈ ε 16/h³) from
        N ≈ 10⁴·⁵ on (rigid_body_oc at N = 10⁵: a false SADDLE by band Cholesky of J).
        """
        m = self.model
        negative, zero = m.ffi.new("long *"), m.ffi.new("long *")
        m.lib.symvi_lifted_inertia(m.ptr(self.band.T), self.n_nodes, shift, negative, zero)
        if zero[0]:
            return False, -1
        excess = int(negative[0]) - self.band.shape[1] // 3
        return excess == 0, excess



def _scale(band: np.ndarray, bw: int, rows: np.ndarray, cols: np.ndarray) -> None:
    """band ← R · band · C in place (LAPACK storage, kl = ku = bw): a matrix equilibrated
    once per assembly, factorised again with another shift."""
    from numpy.lib.stride_tricks import sliding_window_view

    size = band.shape[1]
    padded = np.concatenate([np.ones(2 * bw), rows, np.ones(bw)])
    band.T[:] *= sliding_window_view(padded, 3 * bw + 1)[:size]   # ab[k, j]: row j + k − 2 bw
    band *= cols
