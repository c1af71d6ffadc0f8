"""The lifted Newton system of a second-order whole-trajectory solve (``templates/lifted.c.j2``).

The node formulation's Newton matrix J (:mod:`.assembly`) is a discrete fourth derivative:
its condition number grows like N⁴ and passes 1/ε near N = 10⁵, where its banded LU
returns corrections without a correct digit. The same correction J η = −R solves a system
with the node corrections η, the elements' increment changes u and their momentum
changes μ as unknowns (the discrete-mechanics analogue of multiple shooting), and with
constraints the windows' multipliers λ: its rows are the node residuals, the momenta's
definitions, the elements' composability and the windows' constraints, each a first or
second difference. Pair, matrix-group and action factors alike (an action's base point
moves with its node but is measured from no fibre). Its condition number after
equilibration grows like N² (measured exponents 2.0 on cubic_spline and cart_pole_oc,
1.8–1.9 on rigid_body_oc, against 4.0 for J; tests/test_lifted.py). It is factorised after Ruiz equilibration and a solve is
refined (at most :data:`REFINEMENTS` times) while its componentwise backward error
exceeds 4ε, so that at N = 10⁶ (κ ≈ 10¹³) the steps stay accurate: cubic_spline
converges within 2e-11 of the exact cubic at N = 10⁶ and 3e-12 at 10⁵, where J's LU
reached 4e-5. It has three times J's unknowns and a band of 5n − 1 diagonals on either
side instead of 3n − 1, so it is used where J loses accuracy (:data:`LIFT_FROM`). With
inequalities the windows carry z·c in their Hessians and the interior point's eliminated
slack and multiplier steps JᵀΣJ (``weights``), and its inertia is the interior point's
test (``bounded/interior.py``).
"""
from __future__ import annotations

import numpy as np

from .band import factor, lu_solve, reciprocal_condition, residual

#: Most steps of iterative refinement after a solve whose componentwise backward error
#: exceeds 4ε: at N = 10⁶ (κ ≈ 10¹³ equilibrated) one LU solve can leave errors in the
#: step's roughest components whose curvature ≈ h⁻³ turns them into residuals above the
#: path's own (cubic_spline: the line search STALLED without equilibration and refinement).
REFINEMENTS = 2

#: The multipliers' regularisations −δ tried in the second-order test with constraints
#: (:meth:`LiftedSystem.minimum`), in the symmetric scaling where entries are ≈ 1: the
#: penalty 1/δ on AᵀA grows until W + AᵀA/δ is positive definite, rounding permitting.
REGULARISATIONS = (1e-2, 1e-4, 1e-6, 1e-8)

#: Number of steps from which the lifted system solves the Newton steps: below it J's
#: conditioning (≈ N⁴ / 10) leaves at least six correct digits, and its LU is cheaper.
LIFT_FROM = 2000


class LiftedSystem:
    """The lifted matrix at one path, its LU, and Newton corrections from it."""

    def __init__(self, model, n_nodes: int, gauge=None):
        self.model, self.n_nodes = model, n_nodes
        #: The gauge condition of exactly dependent constraints (:mod:`.gauge`), if any.
        self.gauge = gauge
        self.bw = int(model.lib.symvi_lifted_bandwidth())
        size = int(model.lib.symvi_lifted_unknowns(n_nodes))
        # both written whole before they are read (the assembly zeroes the band)
        self.band = np.empty((3 * self.bw + 1, size), order="F")
        self.work = np.empty_like(self.band, order="F")
        self.node, self.lifted = _layouts(model, n_nodes)
        if gauge is not None:   # window w's multipliers and constraint rows
            block = 3 * model.n + model.constraints
            self.gauge_rows = gauge.window * block + np.arange(model.constraints)
        self._factored = self._scaling = self._at = self._inertia_scale = None
        # Kept: right-hand side, solution, residual and its scale; R, C and the
        # equilibration's scratch; the pivots. Fresh vectors of this size are fresh pages:
        # faulting them in cost a quarter of a solve at N = 10⁵.
        self._vectors = tuple(np.zeros(size) for _ in range(4))
        self._scales = tuple(np.zeros(size) for _ in range(4))
        self._pivots = np.zeros(size, dtype=np.intc)

    def assemble(self, path, p, h: float, gauged: bool = True,
                 weights: np.ndarray | None = None) -> bool:
        """The lifted matrix at ``path``, with the gauge rows (:meth:`.gauge.Gauge.
        replace_rows`, the gauge updated at ``path``) unless not ``gauged``, and with
        an interior point's barrier weights z/s (windows × inequalities, unless None):
        the eliminated slack and multiplier steps GᵀΣG, added to the window Hessians in
        the windows' coordinates, become J + GᵀΣG once u and μ are eliminated, as the
        node system's ``symvi_bvp_barrier`` adds them to J. False on a non-finite
        entry."""
        m = self.model
        self._factored = self._scaling = None
        if weights is not None:
            weights = np.ascontiguousarray(weights, dtype=float)
        code = m.lib.symvi_lifted_assemble(m.ptr(path.x), m.ptr(path.f), m.ptr(path.lam),
                                           m.ffi.NULL if weights is None else m.ptr(weights),
                                           self.n_nodes, m.ptr(p), h, m.ptr(self.band.T))
        self._at = (path, p, h, gauged and self.gauge is not None, weights)
        if self._at[3]:
            self.gauge.replace_rows(self.band, self.bw, self.gauge_rows)
        return code == 0

    def weigh(self, weights: np.ndarray | None) -> bool:
        """The lifted matrix at the last assembly's path with the barrier ``weights``
        instead (assembled again only where they differ): an interior point's inertia
        test weighs the inequalities otherwise than its step. False on a non-finite
        entry."""
        path, p, h, gauged, old = self._at
        if old is weights or (old is not None and weights is not None
                              and np.array_equal(old, weights)):
            return True
        return self.assemble(path, p, h, gauged, weights)

    def solve(self, rhs: np.ndarray, shift: float = 0.0,
              shifted: np.ndarray | None = None, lam: np.ndarray | None = None) -> np.ndarray:
        """The correction (η, λ) in the node layout of :mod:`.assembly` with
        (J + shift·D) (η, λ) = rhs, D the identity on the unknowns ``shifted`` (a mask in
        the node layout; default all), the gauge rows posed with the
        multipliers ``lam`` (:meth:`.gauge.Gauge.replace_rhs`). The LU is kept for further
        solves with the same shift until the next assembly (a simplified Newton step
        reuses it)."""
        key = (shift, None if shifted is None or not shift else shifted.tobytes())
        if self._factored is None or self._factored[0] != key:
            self._factor(key, shift, shifted)
        _, pivots, diagonal = self._factored
        b, x, r, s = self._vectors
        b.fill(0.0)
        b[self.lifted] = rhs[self.node]
        if self.gauge is not None:
            b[:] = self.gauge.replace_rhs(b, self.gauge_rows, lam)
        self._lu_solve(pivots, b, x)
        for _ in range(REFINEMENTS):
            error = residual(self.model, self.band, self.bw, x, b, (r, s), diagonal)
            if error <= 4 * np.finfo(float).eps:
                break       # backward stable already (N ≤ 10⁵ after equilibration)
            x += self._lu_solve(pivots, r, r)
        out = np.zeros(len(rhs))
        out[self.node] = x[self.lifted]
        return out

    def _factor(self, key, shift: float, shifted: np.ndarray | None) -> None:
        """LU of the equilibrated (and shifted) lifted matrix in the work band."""
        self._factored = None
        np.copyto(self.work, self.band)
        diagonal = None
        if shift:
            diagonal = np.zeros(self.band.shape[1])
            diagonal[self.lifted] = shift if shifted is None else shift * shifted[self.node]
            self.work[2 * self.bw] += diagonal
        if self._scaling is None:
            self._scaling = self._equilibrate()
        else:
            _scale(self.work, self.bw, *self._scaling)
        pivots = factor(self.model, self.work, self.bw, "band LU of the lifted system",
                        self._pivots)
        self._factored = (key, pivots, diagonal)

    def reciprocal_condition(self) -> float:
        """An estimate of 1/κ₁ of the equilibrated lifted matrix, the one factorised (the
        raw matrix's is meaningless: its u columns carry curvatures ≈ h⁻³ beside unit
        entries; the heavy top with rotors at N = 10⁴: 6e-20 raw)."""
        np.copyto(self.work, self.band)
        self._factored, self._scaling = None, self._equilibrate()
        rcond = reciprocal_condition(self.work, self.bw)
        self._scaling = None        # the work band now holds an LU
        return rcond

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
        """Whether J + shift·I (on the node corrections) is positive definite on the
        constraints' tangent space, from the inertia of the lifted matrix: (verdict,
        negative eigenvalues beyond the momenta's and multipliers', −1 when a pivot
        vanished and the count is incomplete).

        With the momenta's sign flipped the lifted matrix is the KKT matrix
        [[W, Aᵀ], [A, 0]] of the quadratic model in (η, u) under composability (A of
        full row rank), whose inertia is that of the reduced Hessian plus one positive
        and one negative eigenvalue per constraint (Gould 1985): without constraints J
        is positive definite iff there is exactly one negative eigenvalue per momentum.
        The constraints Φ_d may be dependent (exactly, by a declared symmetry; nearly,
        as the vertical momentum's multiplier of a planar heavy-top motion, whose
        eigenvalue falls like N⁻⁵ below rounding), so their multipliers' block gets
        −δ·I (:data:`REGULARISATIONS`, in the symmetric scaling of the C, entries ≈ 1):
        then the count is one per momentum and multiplier exactly when W + AᵀA/δ is
        positive definite on (η, u), which proves dᵀWd > 0 on ker A (Debreu's lemma, as
        :func:`.optimality.second_order`). LAPACK has no band LDLᵀ, so the C
        (``symvi_lifted_inertia``) eliminates it block by block with Bunch–Parlett
        pivoting inside each block, in blocks (μ_{t−1}, λ_{t−1}, η_t, u_t) where no
        block is a near-singular saddle. J itself cannot answer at large N: its smallest
        eigenvalue (≈ h π⁴) is below the rounding of its largest entries (≈ ε 16/h³)
        from N ≈ 10⁴·⁵ on (rigid_body_oc at N = 10⁵: a false SADDLE by band Cholesky of
        J).
        """
        if self._at is not None and self._at[3]:    # the KKT matrix, without gauge rows
            path, p, h, _, weights = self._at
            self.assemble(path, p, h, gauged=False, weights=weights)
            try:
                return self._count(shift)
            finally:        # the gauge rows back, for the solves
                self.gauge.replace_rows(self.band, self.bw, self.gauge_rows)
                self._at = (path, p, h, True, weights)
        return self._count(shift)

    def _count(self, shift: float) -> tuple[bool, int]:
        """:meth:`minimum` on the band as it is (symmetric up to the momenta's sign)."""
        m, s = self.model, self.model.constraints
        if self._inertia_scale is None:       # D and its sweeps' scratch
            self._inertia_scale = np.zeros((2, self.band.shape[1] + 3 * m.n))
        blocks = self.n_nodes - 3
        expected = blocks * m.n + (blocks + 1) * s
        negative, zero = m.ffi.new("long *"), m.ffi.new("long *")
        for delta in REGULARISATIONS if s else (0.0,):
            m.lib.symvi_lifted_inertia(m.ptr(self.band.T), self.n_nodes, shift, delta,
                                       m.ptr(self._inertia_scale[0]),
                                       m.ptr(self._inertia_scale[1]), negative, zero)
            excess = -1 if zero[0] else int(negative[0]) - expected
            if excess == 0:
                return True, 0
        return False, excess


def _layouts(model, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """(indices in the node layout, their indices in the lifted layout) of the unknowns
    the two layouts share. The node layout
    (:meth:`.assembly.Problem._blocks`) has blocks (η_t, λ_{t−1}) of the nodes t from
    T0 = 1 with constraints (else 2) to n_nodes − 1 − T0; the lifted one holds η_t at
    s + (t − 1)(3n + s) for t = 1 … n_nodes − 3 and λ_w at w (3n + s). The node layout's
    η_{n_nodes−2} with constraints is a fixed node's, pinned to 0: not shared."""
    n, s = model.n, model.constraints
    t0, lb = (1 if s else 2), 3 * n + s
    t = np.arange(t0, n_nodes - t0)
    node = (t - t0)[:, None] * (n + s) + np.arange(n + s)
    lifted = np.concatenate([s + (t - 1)[:, None] * lb + np.arange(n),
                             (t - 1)[:, None] * lb + np.arange(s)], axis=1)
    is_eta = np.arange(n + s) < n
    shared = (t <= n_nodes - 3)[:, None] | ~is_eta
    return node[shared], lifted[shared]


def _scale(band: np.ndarray, bw: int, rows: np.ndarray, cols: np.ndarray) -> None:
    """band ← R · band · C in place (LAPACK storage, kl = ku = bw): a matrix equilibrated
    once per assembly, factorised again with another shift."""
    from numpy.lib.stride_tricks import sliding_window_view

    size = band.shape[1]
    padded = np.concatenate([np.ones(2 * bw), rows, np.ones(bw)])
    band.T[:] *= sliding_window_view(padded, 3 * bw + 1)[:size]   # ab[k, j]: row j + k − 2 bw
    band *= cols
