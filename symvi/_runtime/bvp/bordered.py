"""A free final time inside Newton (issue 50, item 2): the horizon T as one more unknown
of the whole-trajectory system, bordering its band.

With h = T/N, the stationarity of ℒ = Σ_w [L_d + λ·Φ_d] + ν·ψ + ρT in T is one more
equation, G = ∂ℒ/∂T = (1/N) Σ_w ∂ℒ_w/∂h + ρ = 0, the derivatives at fixed groupoid
elements (the compiled ``horizon`` kernel, by the envelope theorem the dJ*/dT + ρ of the
outer iteration, :mod:`.horizon`, now an option and a fallback). Its Newton system borders
the band,

    [ J   b ] [Δ ]     [ R ]
    [ bᵀ  d ] [ΔT] = − [ G ],

b = ∂R/∂T and d = ∂G/∂T at fixed elements. The row is bᵀ because R is the gradient of ℒ
in the node variations and multipliers and G its derivative in T, whose mixed second
derivatives agree (measured: 1e-10 relative on the double integrator, the cart-pole and
the slew on SO(3), with their multipliers). b and d are central differences of the
compiled residual and of G in T at the cube root of ε (relative error ~1e-10: Newton's
rate is unchanged, and the SUCCESS rule reads the correction the bordered system gives):
the kernels' derivatives in h are not compiled. The band's factorisation serves both
solves of the Schur complement, s = d − bᵀJ⁻¹b, ΔT = −(G − bᵀJ⁻¹R)/s, Δ = −J⁻¹(R + bΔT):
one iteration stays O(N). By Haynsworth's inertia additivity the bordered matrix has
the band's inertia plus the sign of s, so a minimum asks the band's second-order test
and s > 0 (:meth:`HorizonProblem.curvature_beyond_band`).

The unknown is σ = log T (the row and column above times T, the corner d_σ = T G +
T² d): its correction is T's relative one, which the SUCCESS rule reads beside the nodes'
— with T itself an unknown, a hunt had T = 0.025 returned for T* = 0.21 at xtol = 1e-2,
its absolute correction within xtol·(1 + size) of nodes of size 1 — and T = e^σ stays
positive. An update moves the elements by the node corrections at the old step and then
T, the elements held (a group fibre ξ = τ⁻¹(w)/h rescaled by T_old/T_new), as the
derivatives are taken.

With inequalities the interior point (:mod:`.bounded.interior`) eliminates their slacks
and multipliers into the border too — GᵀΣg_σ into b, g_σᵀΣg_σ into d, g_σ = ∂c/∂σ
(:meth:`HorizonProblem.inequality_rates`) — and the active-set Newton
(:mod:`.bounded.polish`) borders its sparse KKT matrix the same way. The minimum-time
slew on SO(3) finds the outer secant's horizon to 12 digits, 2.4× faster at N = 400; the
double integrator with |u| ≤ 1 converges from first horizons T*/10 to 3T* alike, for
time weights ρ/ε to 10⁴.

With States as boundary data (:mod:`.boundary_states`) the fixed end elements are the
ones whose midpoints the States are, at h = T/N: they move with T (unless the States are
at rest). The differences of R in T move them too, and G gains ∂ℒ/∂T through them — a
central difference of the Lagrangian of the two windows at each end, where only the end
nodes move (its rounding is that of a few windows' terms, not of the whole sum). The
horizon then converges at order 2 in h, as the cost does.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .assembly import Problem
from . import boundary_states
from .band import factor, lu_solve, rounding_level
from ..core.model_info import Kernel
from ..core.paths import Path, fibres

#: Central differences in T at this relative step (ε^⅓: truncation and rounding balanced).
DIFFERENCE = np.finfo(float).eps ** (1.0 / 3.0)


class HorizonProblem(Problem):
    """:class:`.assembly.Problem` with the horizon ``path.T`` as its last unknown (module
    docstring). The step ``h`` follows the path: T/N at the path last given."""

    BORDER = 1

    def __init__(self, model, p, N: int, states=None, lifted: bool | None = None):
        super().__init__(model, p, None, lifted)
        #: h = T/N; with ``states`` (the (start, end) States) the path has N + 2 nodes
        self.N, self.states = N, states
        self.border = None      # (b, d) at the last assembly with a Jacobian
        #: the border of W itself at that assembly, before an interior point adds its
        #: barrier's (:meth:`add_to_border`)
        self.raw = None
        self._column = None     # (shift, J⁻¹b) of the last factorisation
        #: The inertia correction's shift on σ relative to the band's: σ's curvature is
        #: in its own units (the interior point sets it to the corner's size over W's)
        self.corner_weight = 1.0

    def _at(self, path: Path) -> None:
        self.h = path.T / self.N

    def step(self, path: Path) -> float:
        return path.T / self.N

    def inequality_rates(self, path: Path) -> np.ndarray:
        """∂c/∂σ = T ∂c/∂T (σ = log T, the unknown) per window and inequality, the
        elements held (the ``horizon`` kernel) but the end elements States fix, which
        move with T (central differences on the two windows at each end)."""
        m, h = self.model, path.T / self.N
        values = m.along_vector(Kernel.HORIZON, path.x, path.f, h, self.p)
        first = 1 + m.constraints
        rates = values[:, first:first + len(m.inequalities)] / self.N
        if self.states is None:
            return path.T * rates
        step, sides = DIFFERENCE * path.T, []
        for T in (path.T + step, path.T - step):
            ends = self._with_ends(path, T / self.N, h)
            if ends is None:
                return np.full_like(rates, np.nan)
            sides.append([self._inequalities(ends, first_window, h)
                          for first_window in self._end_windows(path)])
        for k, first_window in enumerate(self._end_windows(path)):
            rates[first_window:first_window + 2] += (sides[0][k] - sides[1][k]) / (2 * step)
        return path.T * rates

    def _end_windows(self, path: Path) -> tuple[int, int]:
        """The first of the two windows at each end that hold an end node."""
        return 0, path.x.shape[0] - self.model.order - 2

    def _inequalities(self, path: Path, first_window: int, h: float) -> np.ndarray:
        """c on windows ``first_window`` and the next (in C, as the barrier evaluates
        them)."""
        m, r = self.model, self.model.order
        x = np.ascontiguousarray(path.x[first_window:first_window + r + 2])
        f = np.ascontiguousarray(path.f[first_window:first_window + r + 1])
        out = np.zeros((2, len(m.inequalities)))
        null = m.ffi.NULL
        if m.lib.symvi_bvp_barrier(m.ptr(x), m.ptr(f), len(x), m.ptr(self.p), h, null, null,
                                   0.0, m.ptr(out), null, null, null):
            out[:] = np.nan
        return out

    def add_to_border(self, column: np.ndarray, corner: float) -> None:
        """Add to the border of the last assembly (an interior point's eliminated
        inequalities: :mod:`.bounded.interior`)."""
        b, d = self.border
        self.border, self._column = (b + column, d + corner), None

    # -- the horizon equation ------------------------------------------------------------
    def horizon_gradient(self, path: Path) -> float:
        """G = ∂ℒ/∂T at ``path`` (the elements fixed), ρ included."""
        m, h = self.model, path.T / self.N
        values = m.along_vector(Kernel.HORIZON, path.x, path.f, h, self.p)
        weights = np.ones((len(values), 1 + path.lam.shape[1]))
        weights[:, 1:] = path.lam[:len(values)] if path.lam.shape[0] else 0.0
        total = float((values[:, :weights.shape[1]] * weights).sum())
        if m.end_count:        # ν·∂ψ/∂h of the end conditions
            last = np.concatenate([path.x[-2], path.f[-1]])
            total += float(m.kernel_outputs(Kernel.END_HORIZON, last, self.p, h)[0]
                           @ path.nu[:m.end_count])
        return (total + self._through_ends(path)) / self.N + float(values[0, -1])

    def _through_ends(self, path: Path) -> float:
        """N ∂ℒ/∂T through the end elements that States fix at h = T/N (0 without
        States): the central difference of the end windows' L_d + λ·Φ_d, h held."""
        if self.states is None or self.model.order + 2 > path.x.shape[0] - 2:
            return 0.0
        h, step = path.T / self.N, DIFFERENCE * path.T
        sides = []
        for T in (path.T + step, path.T - step):
            ends = self._with_ends(path, T / self.N, h)
            if ends is None:
                return np.nan
            sides.append(self._end_lagrangian(ends, h))
        return self.N * (sides[0] - sides[1]) / (2 * step)

    def _end_lagrangian(self, path: Path, h: float) -> float:
        """Σ L_d + λ·Φ_d + z·c over the windows that hold an end node (two at each end)."""
        m, r, s, total = self.model, self.model.order, self.model.constraints, 0.0
        for first in self._end_windows(path):
            x, f = path.x[first:first + 2 + r], path.f[first:first + 1 + r]
            lam = path.lam[first:first + 2]
            total += float(m.along_vector(Kernel.LAGRANGIAN, x, f, h, self.p).sum())
            if s:
                phi = m.along_vector(Kernel.CONSTRAINT, x, f, h, self.p)
                total += float((phi * lam[:, :s]).sum())
            if m.inequalities:
                total += float((self._inequalities(path, first, h) * lam[:, s:]).sum())
        return total

    def _with_ends(self, path: Path, h_ends: float, h: float) -> Path | None:
        """``path`` (at step h) with its two end elements those of the States at step
        ``h_ends``, their neighbours' fibres recomputed; None off a retraction's chart."""
        moved = path.copy()
        for state, which, nodes in ((self.states[0], "start", slice(0, 2)),
                                    (self.states[1], "end", slice(-2, None))):
            try:
                moved.x[nodes], moved.g[nodes] = boundary_states.element(
                    self.model, state, h_ends, self.p, which)
            except ValueError:
                return None
        for nodes, elements in ((slice(0, 3), slice(0, 2)), (slice(-3, None), slice(-2, None))):
            f = fibres(self.model, np.ascontiguousarray(moved.x[nodes]),
                       np.ascontiguousarray(moved.g[nodes]), self.p, h, lambda k: "an end element")
            if not isinstance(f, np.ndarray):
                return None
            moved.f[elements] = f
        return moved

    def time_cost(self, path: Path) -> float:
        """ρ, the time cost's weight (the ``horizon`` kernel's last output)."""
        return float(self.model.along_vector(Kernel.HORIZON, path.x[:self.model.order + 1],
                                             path.f[:self.model.order], path.T / self.N,
                                             self.p)[0, -1])

    def at_horizon(self, path: Path, T: float) -> Path | None:
        """``path`` at the horizon T, its elements held (group fibres rescaled), the end
        elements the States' at T/N where States fix them; None off a chart."""
        moved = replace(path.copy(), T=T)
        moved.f[:, self.model.step_scaled] *= path.T / T
        if self.states is None:
            return moved
        return self._with_ends(moved, T / self.N, T / self.N)

    # -- Problem's interface, the horizon appended -----------------------------------------
    def merit(self, path: Path) -> tuple[float, float]:
        self._at(path)
        cost, noise = super().merit(path)
        timed = self.time_cost(path) * path.T
        return cost + timed, noise + 64 * np.finfo(float).eps * abs(timed)

    def assemble(self, path: Path, with_jacobian: bool, weights: np.ndarray | None = None):
        self._at(path)
        res, ab, bw, finite = super().assemble(path, with_jacobian, weights)
        G = self.horizon_gradient(path) if finite else np.nan
        res = np.append(res, path.T * G)        # the equation in σ = log T
        finite = finite and bool(np.isfinite(res[-1]))
        if with_jacobian:
            border = self._differences(path, res) if finite else None
            if border is not None:      # ∂/∂σ = T ∂/∂T: b_σ = T b, d_σ = T G + T² d
                border = (path.T * border[0], path.T * G + path.T ** 2 * border[1])
            self.border = self.raw = border
            self._column = None
            finite = finite and self.border is not None
            self._last = (path, (res, ab, bw, finite))
        return res, ab, bw, finite

    def _differences(self, path: Path, res: np.ndarray):
        """(b, d): the central differences in T of R and G at fixed elements; None where
        they are not finite (a wild trial path)."""
        step = DIFFERENCE * path.T
        sides = []
        for T in (path.T + step, path.T - step):
            moved = self.at_horizon(path, T)
            if moved is None:
                return None
            self._at(moved)
            other, _, _, _ = Problem.assemble(self, moved, False)
            sides.append(np.append(other, self.horizon_gradient(moved)))
        self._at(path)
        with np.errstate(over="ignore", invalid="ignore"):
            column = (sides[0] - sides[1]) / (2 * step)
        if not np.isfinite(column).all():
            return None
        return column[:-1], float(column[-1])

    def solve(self, ab, bw: int, rhs: np.ndarray, shift: float = 0.0,
              shifted: np.ndarray | None = None, at: Path | None = None) -> np.ndarray:
        """The bordered system's solution through the band's Schur complement (module
        docstring); ``shifted`` masks the band's unknowns and T (default all)."""
        from scipy.linalg import LinAlgError

        band = None if shifted is None else shifted[:-1]
        corner = shift * self.corner_weight if shifted is None or shifted[-1] else 0.0
        y = super().solve(ab, bw, rhs[:-1], shift, band, at)
        b, d = self.border
        w = self._solved_column(ab, bw, shift, band, at)
        schur = d + corner - float(b @ w)
        if not np.isfinite(schur):
            raise LinAlgError(f"the bordered Newton matrix is not finite in the horizon "
                              f"(Schur complement {schur})")
        # a path at rest: nothing moves with T (b = 0, d = 0 on the spin-up's first
        # guess), and the step holds T; no SUCCESS on such a correction (newton.py)
        self.held = abs(schur) <= 64 * np.finfo(float).eps * (
            abs(d) + float(np.abs(b) @ np.abs(w)))
        dT = 0.0 if self.held else (float(rhs[-1]) - float(b @ y)) / schur
        return np.append(y - w * dT, dT)

    def _solved_column(self, ab, bw: int, shift: float, band, at) -> np.ndarray:
        key = (shift, None if band is None else band.tobytes())
        if self._column is None or self._column[0] != key:
            self._column = (key, super().solve(ab, bw, self.border[0], shift, band, at))
        return self._column[1]

    def curvature_beyond_band(self, ab, bw: int, shift: float = 0.0) -> float:
        """The Schur complement d + w·shift − bᵀ(J + shift)⁻¹b (w the
        :attr:`corner_weight`): with the band's inertia right, the bordered matrix's is
        right iff it is positive (Haynsworth)."""
        b, d = self.border
        column = self._solved_column(ab, bw, shift, None, None)
        return d + shift * self.corner_weight - float(b @ column)

    def schur_with(self, work: np.ndarray, bw: int, column: np.ndarray, corner: float) -> float:
        """corner − columnᵀ M⁻¹ column, M the band matrix in ``work`` (left intact): the
        Schur complement of another bordered matrix (the interior point's inertia tests)."""
        from scipy.linalg import LinAlgError

        lu = np.array(work, order="F")
        try:
            pivots = factor(self.model, lu, bw, "the bordered inertia test's band")
        except LinAlgError:
            return -np.inf
        solved = lu_solve(self.model, lu, bw, pivots, np.array(column, dtype=float))
        return corner - float(column @ solved)

    def definite(self, ab, bw: int, shift: float) -> bool:
        return super().definite(ab, bw, shift) and self.curvature_beyond_band(ab, bw, shift) > 0

    def curvature(self, ab, bw: int, delta: np.ndarray, nodes: np.ndarray,
                  shift: float) -> float:
        """dᵀ(H + shift)d on the node part of ``delta`` and ΔT, H the bordered Hessian."""
        b, d = self.border
        dT, band = float(delta[-1]), nodes[:-1]
        inner = super().curvature(ab, bw, delta[:-1], band, shift)
        return inner + 2 * dT * float(b[band] @ delta[:-1][band]) + \
            (d + shift * self.corner_weight) * dT * dT

    def correction_norm(self, delta: np.ndarray, path: Path) -> float:
        """‖Δ‖∞ with Δσ weighed by 1 + size: Δσ is T's relative correction, and the
        tolerance xtol·(1 + size) the nodes' — a path translated to x ≈ 10⁵ once let
        T = 10 pass for T* = 2 at xtol = 1e-4 (a hunt: Δσ = 2.2 within 10)."""
        return max(super().correction_norm(delta[:-1], path),
                   abs(float(delta[-1])) * (1.0 + self.size(path)))

    def moved(self, path: Path, delta, alpha):
        self._at(path)
        trial = super().moved(path, delta[:-1], alpha)
        with np.errstate(over="ignore"):
            T = path.T * float(np.exp(alpha * float(delta[-1])))       # σ = log T
        if trial is None or not (T > 0 and np.isfinite(T)):
            return None
        return self.at_horizon(trial, T) if T != path.T else trial

    def rounding_level(self, ab, bw: int, path: Path) -> float:
        """The band's level with σ's column, and T·G's: 16 ε (|J||u| + |b_σ|), and
        16 ε (T Σ |∂ℒ_w/∂h| / N + |b_σ|·|u| + |d_σ|) (σ = log T, of magnitude 1: T's
        rounding is relative)."""
        self._at(path)
        u = self.magnitudes(path)
        b, d = self.border
        eps = np.finfo(float).eps
        band = rounding_level(self.model, ab, bw, u[:-1]) + 16 * eps * \
            float(np.abs(b).max(initial=0.0))
        values = self.model.along_vector(Kernel.HORIZON, path.x, path.f, self.h, self.p)
        terms = path.T * float(np.abs(values).sum()) / self.N + float(np.abs(b) @ u[:-1]) \
            + abs(d)
        return max(band, 16 * eps * terms)

    def magnitudes(self, path: Path) -> np.ndarray:
        """The band's unknowns' magnitudes, and σ = log T's: 1 (a unit in T's last place
        moves σ by ε)."""
        self._at(path)
        return np.append(super().magnitudes(path), 1.0)

    def constraint_rows(self, path: Path) -> np.ndarray:
        return np.append(super().constraint_rows(path), False)
