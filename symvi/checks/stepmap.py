"""The step map of a derived model, its Hamiltonian coordinates and their Poisson structure,
numerically — what the check ``structure`` measures (:mod:`symvi.checks.structure`; paper
§4.3, Theorem ``propositiongroupoids1``, and Appendix B).

:class:`StepMap` solves the step residual R(s, f_new) = 0 by Newton from the predictor,
differentiates the step map Φ: s ↦ s' by the implicit function theorem (kernels evaluated
with exact forward-mode Jacobians, :class:`~symvi.checks.tape.ForwardTape`), and builds the Hamiltonian
coordinates y = Λ(s) and the Poisson tensor they carry; :func:`poisson_defect` and
:func:`symplectic_defect` measure how far a map is from preserving a structure.

Coordinates and structures (sign convention: {q, p} = 1, Hamiltonian vector fields
ż = Π ∇H):

* **first order, every groupoid** — y = (x₀, μ₀) with μ₀ = F⁻L_d(g₀) ∈ A*_{x₀}G (symvi's
  node variations use the basis sections e_a of the algebroid, so μ₀ is in the dual
  basis) and Π the linear Poisson structure of A*G (:func:`linear_poisson`):
  {x^i, x^j} = 0, {x^i, μ_a} = ρ^i_a(x), {μ_a, μ_b} = −C^c_{ab}(x) μ_c. On the pair
  groupoid (ρ = I, C = 0) this is the canonical form of T*Q and the check is MᵀJM = J for
  (q_k, p_k) ↦ (q_{k+1}, p_{k+1}); on a Lie group it says that μ_k ↦ μ_{k+1} is a
  Lie–Poisson map. (For a Lie group alone the condition is invariant under Π → −Π, so
  the sign of the Lie–Poisson bracket cannot matter; for an action groupoid the relative
  sign of the anchor and bracket terms does, and the one above is the reduction of T*H by
  left translations — the heavy top's (Γ, Π) bracket.)
* **second order** — A*(P^αG) for G a Lie group is 𝔤* × T*G (paper §4.2, example: P^αG ≅
  3G, a Lie group times a pair groupoid), and for the pair groupoid it is T*(Q×Q). With
  P₀, P₁ = F⁻L_d(g₀, g₁, g₂) the momenta at the first two nodes, R and L the fibre rows
  of the node variations right(g₀), left(g₀) (kernel ``variations``), the coordinates are

      y = (x₀, ν, f₀, p),   p = R⁻ᵀ P₁,   ν = P₀ − Lᵀ p,

  with Π = (linear Poisson structure of A*G on (x₀, ν)) ⊕ (canonical on (f₀, p)). This
  is the reduction of the unreduced second-order flow on the pair groupoid of H (with
  L̄(h₀, h₁, h₂) = L_d(h₀⁻¹h₁, h₁⁻¹h₂), and q = q₀·h₀ for an action groupoid), which is
  symplectic for the canonical form pulled back by the second-order Legendre transform
  (Appendix B, and Benito, de León & Martín de Diego for higher order), by the left action
  of H: in coordinates (h₀, w₀ = h₀⁻¹h₁) the covector splits into the body momentum ν of
  h₀ (= P₀ + Ad*_{w₀⁻¹}P₁; Ad_{w₀⁻¹} = −R⁻¹L) — the minus Lie–Poisson bracket — and a
  covector p on T_{w₀}H in the chart f₀ (Rᵀp = P₁). On the pair groupoid R = I, L = 0
  and y = (q₀, p₀, q₁, p₁) with the canonical form of T*(Q×Q). The relative sign
  between the Lie–Poisson and the canonical block matters here; the one above is the
  reduction's, and the opposite sign fails on ``so3_cubic`` (tests).
* **order r ≥ 3** — the same reduction of the unreduced flow on T*(H^r) (the canonical
  form pulled back by F⁻L_d: Benito, de León & Martín de Diego), in the chart
  (h₀, w₀, …, w_{r−2}) of the first r nodes: with P₀ … P_{r−1} = F⁻L_d(g₀ … g_{2r−2})
  and R_j, L_j the fibre rows of right(g_j), left(g_j) (node i's variation moves
  f_{i−1} by R_{i−1} and f_i by L_i),

      P_{r−1} = R_{r−2}ᵀ p_{r−2},  P_i = R_{i−1}ᵀ p_{i−1} + L_iᵀ p_i,  ν = P₀ − L₀ᵀ p₀,

  solved from the last node back; y = (x₀, ν, f₀, …, f_{r−2}, p₀, …, p_{r−2}) and Π =
  (linear Poisson structure on (x₀, ν)) ⊕ (canonical on (f, p)). On the pair groupoid
  p_j = P_{j+1}, ν = P₀: the canonical form of T*(Q^r) in (q₀, …, q_{r−1}, p₀, …, p_{r−1}).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import sympy as sp

from ..derivation.derive import DerivedModel
from ..groupoids.base import Groupoid
from .tape import ForwardTape
from .._runtime.core.model_info import Kernel as KernelName

#: Default time step of a :class:`StepMap`.
STEP = 0.1


# -- defects ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Defect:
    """Size of the defect D of a structure identity, e.g. D = MΠMᵀ − Π'.

    ``relative`` is ‖D‖ / (‖M‖²‖Π‖ + ‖Π'‖) (Frobenius norms: the size of the rounding
    error of the identity), ``norm`` ‖D‖, ``worst`` the (i, j) of the largest entry of D
    and ``value`` that entry.
    """

    relative: float
    norm: float
    worst: tuple[int, int]
    value: float

    def describe(self, names: Sequence[str] | None = None) -> str:
        i, j = self.worst
        where = f"({names[i]}, {names[j]})" if names else f"({i}, {j})"
        return (f"relative defect {self.relative:.3e}, defect norm {self.norm:.3e}, "
                f"worst entry {where} = {self.value:.3e}")


def _defect(D: np.ndarray, scale: float) -> Defect:
    D = np.asarray(D, dtype=float)
    size = np.abs(np.where(np.isfinite(D), D, np.inf))
    i, j = np.unravel_index(int(np.argmax(size)), D.shape)
    norm = float(np.linalg.norm(D))
    relative = norm / scale if scale > 0 else (0.0 if norm == 0 else np.inf)
    return Defect(float(relative), norm, (int(i), int(j)), float(D[i, j]))


def canonical_poisson(n: int) -> np.ndarray:
    """J = [[0, I], [−I, 0]] of T*Rⁿ in coordinates (q, p): {q^i, p_j} = δ^i_j."""
    I, O = np.eye(n), np.zeros((n, n))
    return np.block([[O, I], [-I, O]])


def linear_poisson(mu: np.ndarray, anchor: np.ndarray, structure: Sequence[np.ndarray],
                   sign: float = -1.0) -> np.ndarray:
    """Linear Poisson structure of A* at (x, μ), coordinates (x, μ).

    ``anchor`` ρ (m×n) and ``structure`` C^c (n×n each, C^c[a, b] = C^c_{ab}) evaluated
    at x: {x^i, μ_a} = ρ^i_a, {μ_a, μ_b} = −C^c_{ab} μ_c, {x^i, x^j} = 0. ``sign`` is
    the sign of the bracket term (−1; +1 only to show that the other sign fails).
    """
    anchor = np.asarray(anchor, dtype=float)
    m, n = anchor.shape
    bracket = sign * sum((c * np.asarray(C, dtype=float) for c, C in zip(mu, structure)),
                         np.zeros((n, n)))
    return np.block([[np.zeros((m, m)), anchor], [-anchor.T, bracket]])


def poisson_defect(M: np.ndarray, before: np.ndarray, after: np.ndarray) -> Defect:
    """How far a map with Jacobian M is from being Poisson: D = M Π Mᵀ − Π'.

    ``before`` Π at the point, ``after`` Π' at its image (any coordinates). For a
    symplectic structure Π = Π' = J this is equivalent to MᵀJM = J.
    """
    M, P, Q = (np.asarray(a, dtype=float) for a in (M, before, after))
    scale = np.linalg.norm(M) ** 2 * np.linalg.norm(P) + np.linalg.norm(Q)
    return _defect(M @ P @ M.T - Q, scale)


def symplectic_defect(M: np.ndarray, form: np.ndarray | None = None,
                      form_after: np.ndarray | None = None) -> Defect:
    """How far a map with Jacobian M is from preserving a 2-form: D = MᵀΩ'M − Ω.

    ``form`` Ω at the point (default the canonical J of T*Rⁿ in coordinates (q, p)),
    ``form_after`` Ω' at the image (default Ω).
    """
    M = np.asarray(M, dtype=float)
    W = canonical_poisson(M.shape[0] // 2) if form is None else np.asarray(form, dtype=float)
    W2 = W if form_after is None else np.asarray(form_after, dtype=float)
    scale = np.linalg.norm(M) ** 2 * np.linalg.norm(W2) + np.linalg.norm(W)
    return _defect(M.T @ W2 @ M - W, scale)


# -- the step map and its Hamiltonian coordinates -----------------------------------------
class StepMap:
    """The step map of a derived model and its Hamiltonian coordinates, numerically.

    The state is s = (x₀, f₀, …, f_{2r−2}) — the 2r−1 elements before the unknown one.

    Parameters
    ----------
    derived:
        The derived model (kernels ``step``, ``predict``, ``momentum_minus``,
        ``variations``, ``target``). It may be tampered with: the check is meant to catch
        a step residual that is not the variational one.
    groupoid:
        Its groupoid (for the algebroid: anchor and structure functions, and sampling).
    h:
        Time step; the parameters take their defaults unless ``parameters`` is given.
    sign:
        Sign of the bracket term of the linear Poisson structure (:func:`linear_poisson`);
        −1 is the structure the flow preserves, +1 is there to show that it is pinned down.
    """

    def __init__(self, derived: DerivedModel, groupoid: Groupoid, h: float = STEP,
                 parameters: dict | None = None, sign: float = -1.0):
        self.derived, self.groupoid, self.h = derived, groupoid, float(h)
        self.sign = sign
        self.r, self.m, self.n = derived.order, derived.source_dim, derived.fibre_dim
        values = dict(zip(derived.parameters, derived.defaults)) | dict(parameters or {})
        fixed = {p: values[p] for p in derived.parameters} | {derived.step: self.h}
        self._residual = ForwardTape(derived.kernel(KernelName.STEP), "residual", fixed)
        self._predict = ForwardTape(derived.kernel(KernelName.PREDICT), "guess", fixed)
        self._momentum = ForwardTape(derived.kernel(KernelName.MOMENTUM_MINUS), "momentum", fixed)
        self._target = ForwardTape(derived.kernel(KernelName.TARGET), "target", fixed)
        self._right = ForwardTape(derived.kernel(KernelName.VARIATIONS), "right", fixed)
        self._left = ForwardTape(derived.kernel(KernelName.VARIATIONS), "left", fixed)
        A = groupoid.algebroid()
        self._anchor = sp.lambdify([A.q], A.anchor, "numpy")
        self._structure = sp.lambdify([A.q], list(A.structure), "numpy")
        self.state_dim = self.m + (2 * self.r - 1) * self.n

    # -- the step -----------------------------------------------------------------------
    def solve(self, s: np.ndarray, tol: float = 1e-14, max_iterations: int = 60
              ) -> np.ndarray | None:
        """The new element f_new with R(s, f_new) = 0 (Newton from the predictor)."""
        n = self.n
        f = self._predict(np.concatenate([s, np.zeros(n)]))[0]
        for _ in range(max_iterations):
            R, J = self._residual(np.concatenate([s, f]))
            if not np.all(np.isfinite(R)) or not np.all(np.isfinite(J)):
                return None
            try:
                delta = np.linalg.solve(J[:, -n:], R)
            except np.linalg.LinAlgError:
                return None
            f = f - delta
            if np.linalg.norm(delta) <= tol * (1.0 + np.linalg.norm(f)):
                return f
        return None

    def advance(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """(s', DΦ(s)): the state one element later and the step map's Jacobian."""
        m, n, d = self.m, self.n, self.state_dim
        f = self.solve(s)
        if f is None:
            return None
        R, J = self._residual(np.concatenate([s, f]))
        df = -np.linalg.solve(J[:, d:], J[:, :d])
        x1, T = self._target(s[:m + n])
        M = np.zeros((d, d))
        M[:m, :m + n] = T
        M[m:d - n, m + n:d] = np.eye(d - m - n)
        M[d - n:, :] = df
        return np.concatenate([x1, s[m + n:], f]), M

    # -- Hamiltonian coordinates --------------------------------------------------------
    def _element_variations(self, element: np.ndarray, Dg: np.ndarray):
        """Fibre rows of right(g), left(g) at ``element`` g = (x, f) and their derivatives
        along the state ((n, n) and (n, n, d)); ``Dg`` is d(x, f)/d(state), (m + n) × d."""
        m, n = self.m, self.n
        Rv, DR = self._right(element)
        Lv, DL = self._left(element)
        R = Rv.reshape(m + n, n)[m:]
        L = Lv.reshape(m + n, n)[m:]
        dR = DR.reshape(m + n, n, m + n)[m:] @ Dg
        dL = DL.reshape(m + n, n, m + n)[m:] @ Dg
        return R, L, dR, dL

    def legendre(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """y = Λ(s) and DΛ(s) (module docstring: (x₀, μ₀), (x₀, ν, f₀, p) or, of order
        r ≥ 3, (x₀, ν, f₀, …, f_{r−2}, p₀, …, p_{r−2}))."""
        m, n, d, r = self.m, self.n, self.state_dim, self.r
        P, DP = self._momentum(s)
        x0 = s[:m]
        Dx = np.eye(d)[:m]
        if r == 1:
            return np.concatenate([x0, P]), np.vstack([Dx, DP])
        # Order r ≥ 2: the chart (x₀, f₀, …, f_{r−2}) of the first r nodes. Node i's
        # variation η_i moves f_{i−1} by R_{i−1}η_i and f_i by L_iη_i (x₀ by node 0's
        # only), so Σ P_i·η_i = ν·η₀ + Σ_j p_j·df_j gives P_{r−1} = R_{r−2}ᵀp_{r−2},
        # P_i = R_{i−1}ᵀp_{i−1} + L_iᵀp_i (0 < i < r−1) and P₀ = ν + L₀ᵀp₀.
        Ps = [P[i * n:(i + 1) * n] for i in range(r)]
        DPs = [DP[i * n:(i + 1) * n] for i in range(r)]
        eye = np.eye(d)
        parts, x, Dxj = [], x0, Dx
        for j in range(r - 1):             # g_j = (x_j, f_j), x_{j+1} = β(g_j)
            f, Df = s[m + j * n:m + (j + 1) * n], eye[m + j * n:m + (j + 1) * n]
            element, Dg = np.concatenate([x, f]), np.vstack([Dxj, Df])
            parts.append(self._element_variations(element, Dg))
            if j < r - 2:
                x, T = self._target(element)
                Dxj = T @ Dg
        ps, Dps = [None] * (r - 1), [None] * (r - 1)
        rhs, Drhs = Ps[r - 1], DPs[r - 1]
        for j in reversed(range(r - 1)):
            R, L, dR, dL = parts[j]
            # R_jᵀ p_j = rhs  ⇒  R_jᵀ dp_j = d(rhs) − (dR_j)ᵀ p_j
            ps[j] = np.linalg.solve(R.T, rhs)
            Dps[j] = np.linalg.solve(R.T, Drhs - np.einsum("iak,i->ak", dR, ps[j]))
            # the next equation's right-hand side: P_j − L_jᵀ p_j (ν for j = 0)
            rhs = Ps[j] - L.T @ ps[j]
            Drhs = DPs[j] - np.einsum("iak,i->ak", dL, ps[j]) - L.T @ Dps[j]
        nu, Dnu = rhs, Drhs
        Df = np.eye(d)[m:m + (r - 1) * n]
        return (np.concatenate([x0, nu, s[m:m + (r - 1) * n]] + ps),
                np.vstack([Dx, Dnu, Df] + Dps))

    def poisson(self, y: np.ndarray) -> np.ndarray:
        """Π(y): the structure the Hamiltonian coordinates carry (module docstring)."""
        m, n = self.m, self.n
        x = y[:m]
        anchor = np.array(self._anchor(x), dtype=float).reshape(m, n)
        structure = [np.array(C, dtype=float).reshape(n, n) for C in self._structure(x)]
        P = linear_poisson(y[m:m + n], anchor, structure, self.sign)
        if self.r == 1:
            return P
        k = (self.r - 1) * n            # the elements f₀ … f_{r−2} and their momenta
        return np.block([[P, np.zeros((m + n, 2 * k))],
                         [np.zeros((2 * k, m + n)), canonical_poisson(k)]])

    def state_names(self) -> list[str]:
        """Names of the state coordinates: x0_i (source), f<k>_a (element k's fibre)."""
        return ([f"x0_{i}" for i in range(self.m)]
                + [f"f{k}_{a}" for k in range(2 * self.r - 1) for a in range(self.n)])

    def state_poisson(self, s: np.ndarray) -> np.ndarray:
        """The Poisson tensor in state coordinates, DΛ⁻¹ Π(Λ(s)) DΛ⁻ᵀ."""
        y, D = self.legendre(s)
        X = np.linalg.inv(D)
        return X @ self.poisson(y) @ X.T

    # -- sampling and the defect --------------------------------------------------------
    def sample(self, rng: np.random.Generator) -> np.ndarray:
        """A moderate state: smooth node paths on pair factors, slowly varying ξ on groups."""
        elements, h = 2 * self.r - 1, self.h
        xs, fs = [], [[] for _ in range(elements)]
        for factor in self.groupoid.factors:
            k = factor.fibre_dim
            if factor.elements_are_node_pairs:
                c, v, a = rng.uniform(-0.7, 0.7, k), rng.uniform(-1, 1, k), rng.uniform(-1, 1, k)
                nodes = [c + v * (j * h) + a * (j * h) ** 2 / 2 + 0.01 * rng.uniform(-1, 1, k)
                         for j in range(elements + 1)]
                xs.append(nodes[0])
                for j in range(elements):
                    fs[j].append(nodes[j + 1])
            else:
                xs.append(rng.uniform(-0.7, 0.7, factor.source_dim))
                c, a = rng.uniform(-1, 1, k), rng.uniform(-1, 1, k)
                for j in range(elements):
                    fs[j].append(c + a * (j * h) + 0.05 * rng.uniform(-1, 1, k))
        return np.concatenate(xs + [np.concatenate(f) for f in fs])

    def defect(self, s: np.ndarray) -> Defect | None:
        """Poisson defect of the step map at the state s (None if the step fails).

        In state coordinates, which are O(1) at the sample points (nodes, ξ): the
        Hamiltonian coordinates mix scales (momenta of second-order models are O(h⁻³)).
        """
        stepped = self.advance(s)
        if stepped is None:
            return None
        s1, M = stepped
        return poisson_defect(M, self.state_poisson(s), self.state_poisson(s1))

