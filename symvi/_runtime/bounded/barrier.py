"""The inequalities c ≤ 0 of an interior-point whole-trajectory solve (issue 21).

Each window w of an optimal-control path carries inequalities c_w ≤ 0 (the controls'
bounds), written with slacks s_w > 0 as c_w + s_w = 0 and multipliers z_w > 0. The
primal–dual interior-point method is Newton's method on the perturbed KKT system

    ∇S + Φ_dᵀλ + Gᵀz = 0,   Φ_d = 0,   c + s = 0,   s_j z_j = μ,

G = ∂c/∂η. Per window, the linearised last two rows give the slack and multiplier steps

    Δs = −(c + s) − GΔη,    Δz = (μ + z c + z GΔη) / s,

so they are eliminated window by window (:meth:`Inequalities.add_barrier`, in C): the
reduced system is the equality-constrained Newton system with W + GᵀΣG, Σ = diag(z/s),
and the residual ∇ℒ + Gᵀ(z c + μ)/s — the same band, one iteration still O(N).
"""
from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from ..core.model_info import Kernel
from ..core.paths import Path

#: A SUCCESS holds every inequality at the returned path to this, relative to the
#: inequality's scale (:meth:`Inequalities.violation`), whatever xtol (issue 50, item 6):
#: xtol bounds the node corrections, and a control (a second difference over h²) moves
#: 10⁶ times more than its nodes at N = 1000 — the slew at xtol = 1e-2 once returned
#: SUCCESS with |τ| = 12.3 over its limit 11.
BOUND_TOLERANCE = 1e-9

#: Fraction-to-the-boundary parameter's floor: a step keeps s and z at least (1 − τ) of
#: their current values, τ = max(TAU_MIN, 1 − μ) (Wächter & Biegler 2006, eq. 15).
TAU_MIN = 0.99


class Inequalities:
    """The compiled inequalities of one model along paths of ``n_nodes`` nodes: their
    values c (windows × I) and node Jacobians G (windows × I × (r + 1) n)."""

    def __init__(self, model, n_nodes: int):
        self.model, self.n_nodes = model, n_nodes
        self.names: tuple[str, ...] = model.info.inequalities
        r, n = model.order, model.n
        self.windows = n_nodes - r
        self.values = np.zeros((self.windows, len(self.names)))
        self.jacobian = np.zeros((self.windows, len(self.names), (r + 1) * n))

    def evaluate(self, path: Path, p, h: float, with_jacobian: bool = False) -> bool:
        """c (and G) at ``path`` into :attr:`values` (and :attr:`jacobian`); whether
        they are finite."""
        m = self.model
        jac = m.ptr(self.jacobian) if with_jacobian else m.ffi.NULL
        return m.lib.symvi_bvp_barrier(m.ptr(path.x), m.ptr(path.f), self.n_nodes, m.ptr(p),
                                       h, m.ffi.NULL, m.ffi.NULL, 0.0, m.ptr(self.values),
                                       jac, m.ffi.NULL, m.ffi.NULL) == 0

    def violation(self, values: np.ndarray | None = None,
                  among: np.ndarray | None = None) -> tuple[float, int, int]:
        """(v, w, j): the largest violation of c ≤ 0 relative to its inequality's scale,
        v = c_wj / (1 + max_w' |c_w'j|), of ``values`` (default: the last evaluated)
        among the rows ``among`` (default: all), and the window and inequality where it
        is; v ≤ 0 where every one holds."""
        if self.values.size == 0:
            return 0.0, 0, 0
        relative = self.relative(values)
        if among is not None:
            relative = np.where(among, relative, -np.inf)
        w, j = np.unravel_index(int(np.argmax(relative)), relative.shape)
        return float(relative[w, j]), int(w), int(j)

    def rounding(self, path: Path) -> np.ndarray:
        """Per window and inequality, the rounding of c relative to its scale (as
        :meth:`relative`): ε·Σ_i |∂c/∂η_i|·(1 + max |η|), c's change when every node
        coordinate η of ``path`` moves by its unit in the last place, with the last
        Jacobian evaluated. A control bound at N = 10⁴ on [0, 2] (u a second difference
        over h² = 4·10⁻⁸) rounds at 5·10⁻⁹, with nodes exact to 10⁻¹⁶: no evaluation of c
        resolves :data:`BOUND_TOLERANCE` there."""
        size = 1.0 + max(float(np.abs(path.x).max(initial=0.0)),
                         float(np.abs(path.f).max(initial=0.0)))
        spread = np.abs(self.jacobian).sum(axis=2) * size * np.finfo(float).eps
        return spread / (1.0 + np.abs(self.values).max(axis=0, initial=0.0))

    def holds(self, path: Path, among: np.ndarray | None = None) -> bool:
        """Whether every inequality (of the rows ``among``, default all) holds at
        ``path``, last evaluated, to :data:`BOUND_TOLERANCE` of its scale beyond its
        :meth:`rounding`: the condition of every SUCCESS."""
        if self.values.size == 0:
            return True
        excess = self.relative() - self.rounding(path)
        if among is not None:
            excess = np.where(among, excess, -np.inf)
        return float(excess.max()) <= BOUND_TOLERANCE

    def relative(self, values: np.ndarray | None = None) -> np.ndarray:
        """c_wj / (1 + max_w' |c_w'j|): ``values`` (default: the last evaluated) relative
        to each inequality's scale along the path."""
        c = self.values if values is None else values
        return c / (1.0 + np.abs(c).max(axis=0, initial=0.0))

    def describe_violation(self, h: float, values: np.ndarray | None = None) -> str:
        """Where the worst violated inequality of ``values`` is, and by how much."""
        c = self.values if values is None else values
        v, w, j = self.violation(c)
        return (f"inequality {self.names[j]!r} violated by {c[w, j]:.3g} ({v:.1e} of its "
                f"scale) at window {w} (t = {(w + 1) * h:.4g})")

    def add_barrier(self, path: Path, p, h: float, z: np.ndarray, s: np.ndarray, mu: float,
                    res: np.ndarray, ab: np.ndarray | None) -> bool:
        """Evaluate c and G at ``path`` and add the eliminated slack and multiplier steps
        to the residual and band (unless None) of :meth:`.assembly.Problem.assemble`
        (module docstring); whether everything is finite."""
        m = self.model
        z, s = np.ascontiguousarray(z), np.ascontiguousarray(s)
        return m.lib.symvi_bvp_barrier(m.ptr(path.x), m.ptr(path.f), self.n_nodes, m.ptr(p),
                                       h, m.ptr(z), m.ptr(s), mu, m.ptr(self.values),
                                       m.ptr(self.jacobian), m.ptr(res),
                                       m.ffi.NULL if ab is None else m.ptr(ab.T)) == 0

    def linearised(self, delta: np.ndarray, blocks: np.ndarray, width: int) -> np.ndarray:
        """GΔη per window (windows × I), Δη the node part of a correction in the block
        layout (``blocks``: the node of each block of ``width`` unknowns; the end
        conditions' multipliers ν follow them)."""
        n, r = self.model.n, self.model.order
        eta = np.zeros((self.n_nodes, n))
        eta[blocks] = delta[:len(blocks) * width].reshape(-1, width)[:, :n]
        last = self.n_nodes - 1 - (0 if self.model.end_free else r)
        eta[:r], eta[last + 1:] = 0.0, 0.0          # fixed nodes do not move
        windows = sliding_window_view(eta, r + 1, axis=0)      # (W, n, r + 1)
        stacked = windows.transpose(0, 2, 1).reshape(self.windows, -1)
        return np.einsum("wkj,wj->wk", self.jacobian, stacked)

    def transposed(self, v: np.ndarray, blocks: np.ndarray, width: int) -> np.ndarray:
        """Gᵀv in the block layout (the adjoint of :meth:`linearised`), v per window and
        inequality: node rows of free nodes only."""
        n, r = self.model.n, self.model.order
        weighted = np.einsum("wkj,wk->wj", self.jacobian, v)
        nodes = np.zeros((self.n_nodes, n))
        for j in range(r + 1):
            nodes[j:j + self.windows] += weighted[:, j * n:(j + 1) * n]
        nodes[:r] = 0.0                                   # fixed nodes do not move
        if not self.model.end_free:
            nodes[self.n_nodes - r:] = 0.0
        out = np.zeros((len(blocks), width))
        out[:, :n] = nodes[blocks]
        return np.concatenate([out.reshape(-1), np.zeros(self.model.end_count)])


#: A control-free inequality of a fixed boundary element may exceed 0 by this much,
#: relative to the size of its terms' scale 1 + |c|, before the data count as outside.
BOUNDARY_TOLERANCE = 1e-9


def check_intervals(model, path: Path, p, h: float) -> None:
    """Raise ValueError naming the bound where the parameters leave its interval empty
    (lower ≥ upper): its two sides c_i + c_j = lower − upper, the same on every window
    (``ModelInfo.intervals``), evaluated on the first window of ``path``. The declaration
    refuses such bounds at the parameters' defaults; this is the same rule for the values
    a solve is given, before any iteration (an interior point would only find them
    INFEASIBLE after a full solve)."""
    pairs = model.info.intervals
    if not pairs:
        return
    c = Inequalities(model, path.x.shape[0])
    c.evaluate(path, p, h)
    names, eps = model.info.inequalities, np.finfo(float).eps
    for i, j in pairs:
        # on the window where c_i + c_j rounds least: far-off guesses (nodes scaled by
        # 1e10) make every term huge, and the sum of the sides is then rounding
        size = np.abs(c.values[:, i]) + np.abs(c.values[:, j])
        w = int(np.argmin(size))
        gap, rounding = c.values[w, i] + c.values[w, j], 64 * eps * size[w]  # lower − upper
        if gap > rounding or (gap >= 0.0 and rounding <= 1e-12):
            raise ValueError(
                f"the bounds {names[i]!r} and {names[j]!r} leave an empty interval with "
                f"these parameters: the lower side exceeds the upper by {gap:.6g}; give "
                f"parameters with lower < upper")


def check_boundary_data(model, path: Path, p, h: float) -> None:
    """Raise ValueError naming the end, the element and the inequality when a fixed
    element of the boundary data (elements 0 … r−2 and N−r+1 … N−1, between fixed
    nodes) violates a control-free inequality — a coordinate's or a rate's bound, a
    keep-out zone — evaluated on that element by the first-order rule (the ``boundary``
    kernel): no path from such ends satisfies the bounds where they start, and the
    interior point would only stall on them."""
    names = model.info.boundary_inequalities
    if not names:
        return
    r, N = model.order, path.f.shape[0]
    final = range(N, N) if model.end_free else range(N - r + 1, N)   # an unknown end: a guess
    for end, elements in (("start", range(0, r - 1)), ("end", final)):
        for e in elements:
            c = model.along_vector(Kernel.BOUNDARY, path.x[e:e + 2], path.f[e:e + 1], h, p)[0]
            k = int(np.argmax(c))
            if c[k] > BOUNDARY_TOLERANCE * (1.0 + abs(c[k])):
                raise ValueError(
                    f"{end}: the fixed element {e} (nodes {e} and {e + 1}) lies outside the "
                    f"bounds: {names[k]!r} is violated by {c[k]:.3g} on it (first-order rule); "
                    f"boundary data must satisfy the inequalities that involve no control")


def boundary_step(values: np.ndarray, step: np.ndarray, tau: float) -> float:
    """The largest α ≤ 1 with values + α·step ≥ (1 − τ)·values (values > 0): the
    fraction-to-the-boundary rule."""
    shrinking = step < 0.0
    if not shrinking.any():
        return 1.0
    return float(min(1.0, (-tau * values[shrinking] / step[shrinking]).min()))


def next_barrier(mu: float, floor: float, kappa: float = 0.2) -> float:
    """The monotone (Fiacco–McCormick) decrease μ ← max(floor, κμ). Linear throughout,
    not IPOPT's min(κμ, μ^1.5) (Wächter & Biegler 2006, eq. 7): μ here is per unit time
    and much smaller than IPOPT's near the end, where the superlinear rule jumped from
    2.5e-9 to the floor 1e-12 in one step — Σ = z/s then rose a thousandfold on the
    active rows, the steps became rounding, and the cart-pole swing-up STALLED next to
    its optimum; with κμ it converges in 12 interior-point iterations."""
    return max(floor, kappa * mu)


def safeguarded(z: np.ndarray, s: np.ndarray, mu: float, kappa: float = 1e10) -> np.ndarray:
    """z projected into [μ/(κ s), κμ/s]: the primal–dual Σ = z/s may not stray from the
    primal barrier's μ/s² by more than κ (Wächter & Biegler 2006, eq. 16), which keeps
    the reduced Newton matrix from losing the barrier's curvature."""
    return np.clip(z, mu / (kappa * s), kappa * mu / s)
