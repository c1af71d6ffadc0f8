"""Action groupoids Q×H, matrix Lie groups with both retractions, and a product groupoid.

1. Variational oracle with the group's own variations (DESIGN.md §5) on every bundled model
   on a Lie group or an action groupoid, Cayley and exp. Node j of a path (q_k, ξ_k),
   w_k = τ(hξ_k), is shared by w_{j−1} and w_j; its variation along E_a is
   w_{j−1} → w_{j−1}·τ(εE_a), w_j → τ(−εE_a)·w_j and, on an action groupoid,
   q_j → φ(q_j, τ(εE_a)) (so q_{j+1} = φ(q_j, w_j) is unchanged), applied in NumPy with the
   model's own retraction and its inverse (Cayley: 2(W − I)(W + I)⁻¹; exp: the logarithm,
   see ``log_near_identity``), read back in the basis. The action sum S = Σ_k L_d(q_k, ξ_k)
   is evaluated with the compiled ``lagrangian`` kernel (windows of r elements for order
   r); ∂S/∂ε at every node the step map enforced (r … E − r) must vanish relative to the
   size of the individual window terms. The oracle knows nothing of the engine's residual,
   its signs, its trivialisation or the infinitesimal action.
   Negative control: one increment moved by 1e-3 (and the base points after it recomputed,
   so the path is still a path of the groupoid) is detected at its two nodes.
2. Heavy top: |Γ_k| = 1, discrete Noether momentum about the vertical Γ_k·μ_k, bounded
   energy error, over 10⁵ steps.
3. Spherical pendulum: second-order convergence of the bob −ℓR_ke₃ to a Cartesian
   constrained-pendulum reference, and conservation of Γ·μ.
4. Planar body (SE(2)): the discrete flow samples the exact motion (ω constant, centre of
   mass uniform on a straight line), converges at order 2 from continuous initial data,
   and conserves the spatial momenta Ad*_{g⁻¹}μ.
5. SE(3) body: bounded energy, the momentum about the vertical and the horizontal linear
   momentum (frame of g_0, Γ_0) conserved, |Γ| = 1.
6. A product groupoid SO(3) × pair (rigid body with a rotor): compiles, integrates,
   passes the oracle (group variations on SO(3), node variations on the rotor angle) and
   conserves its Noether momenta.
7. Errors: maps that are not right actions, products whose factors share names.

Oracle error analysis (as in test_lie_groups.py, which measured the same scheme on SO(3),
SE(2), SE(3) with Cayley): the five-point derivative at ε = 1e-3 has a truncation
ε⁴/30·|S⁽⁵⁾| far below round-off for these smooth S; its rounding is bounded by the
``noise`` computed below (≈ 6u/ε relative ≈ 1.5e-12, checked ≤ TOL/10). Newton (xtol
1e-12, quadratic) leaves the discrete Euler–Lagrange residual at round-off. Measured on
these models at h = 0.05: max relative gradient ≤ 3e-13, Cayley and exp alike. TOL = 1e-8
is four orders above; the negative control gives ≥ 1e-4 (measured 1.3e-4 heavy top,
3e-4 spherical pendulum, 4e-4 SE(3), 8e-4 SE(2)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp
from scipy.linalg import expm, logm
from scipy.spatial.transform import Rotation

from conftest import ACTION, LIE
from group_oracle import Algebra, assert_stationary, oracle
from symvi import (SO3, ActionGroupoid, Model, ModelError, PairGroupoid,
                   ProductGroupoid)
from symvi.build import compile_model
from symvi.models import get
from so3 import hat

U = np.finfo(float).eps
E3 = np.array([0.0, 0.0, 1.0])


# ---------------------------------------------------------------------------------------
# NumPy geometry of a model (independent of the generated code)
# ---------------------------------------------------------------------------------------
def log_near_identity(W):
    """log W = 2 artanh(Y), Y = (W − I)(W + I)⁻¹, summed as 2 Σ Y^{2k+1}/(2k+1).

    Y is half the Cayley inverse, so this is exp⁻¹ = 2 artanh(cay⁻¹/2). It converges when
    the spectral radius of Y is < 1 (rotation angles < π/2); the oracle's increments have
    |hξ| ≤ 0.4, where ‖Y‖ ≤ 0.2 and 14 terms reach 1e-20. scipy.linalg.logm, which takes
    5–50 ms per call here (the oracle makes thousands), checks it in
    test_log_series_matches_logm.
    """
    I = np.eye(len(W))
    Y = np.linalg.solve((W + I).T, (W - I).T).T
    assert np.linalg.norm(Y, 2) < 0.5, "increment too large for the artanh series"
    Y2, power, total = Y @ Y, Y.copy(), Y.copy()
    for k in range(1, 60):
        power = power @ Y2
        term = power / (2 * k + 1)
        total += term
        if np.abs(term).max() < 1e-20:
            return 2 * total
    raise AssertionError("artanh series did not converge")


class Geometry(Algebra):
    """Basis, retraction and (for action groupoids) action of a model's groupoid."""

    def __init__(self, groupoid):
        group = getattr(groupoid, "group", groupoid)
        super().__init__(group)
        self.retraction, self.label = group.retraction.name, group.label
        self.phi = None
        if isinstance(groupoid, ActionGroupoid):
            # the model's declared action φ (part of the model, not of the engine)
            W = sp.Matrix(self.d, self.d, lambda i, j: sp.Symbol(f"W_{i}_{j}", real=True))
            phi = sp.lambdify([list(groupoid.q), list(W)], list(groupoid.act(groupoid.q, W)),
                              "numpy")
            self.phi = lambda q, M: np.array(phi(q, M.reshape(-1)), dtype=float)

    def tau(self, X):
        return self.cay(X) if self.retraction == "cayley" else expm(X)

    def tau_inv(self, W):
        return self.cay_inv(W) if self.retraction == "cayley" else log_near_identity(W)

    def increment(self, xi, h):
        return self.tau(h * self.hat(xi))

    def fibre(self, W, h):
        return self.coords(self.tau_inv(W)) / h


def vary_node(geo: Geometry, x, f, j, a, eps, h):
    """The path after the variation of node j along E_a by ε (see the module docstring)."""
    x, f = x.copy(), f.copy()
    sigma = geo.tau(eps * geo.E[a])
    if j >= 1:
        f[j - 1] = geo.fibre(geo.increment(f[j - 1], h) @ sigma, h)
    if j < f.shape[0]:
        f[j] = geo.fibre(geo.tau(-eps * geo.E[a]) @ geo.increment(f[j], h), h)
    if geo.phi is not None:
        x[j] = geo.phi(x[j], sigma)
    return x, f


def recompute_base_points(geo: Geometry, x, f, h, start):
    """q_{k+1} = φ(q_k, τ(hξ_k)) for k ≥ start (a path of the groupoid again)."""
    x = x.copy()
    if geo.phi is not None:
        for k in range(start, f.shape[0]):
            x[k + 1] = geo.phi(x[k], geo.increment(f[k], h))
    return x


# ---------------------------------------------------------------------------------------
# 1. Variational oracle
# ---------------------------------------------------------------------------------------
TOL = 1e-8
N_ORACLE = 20
H_ORACLE = 0.05
ORACLE_MODELS = LIE + ACTION




@dataclass(frozen=True)
class Case:
    mod: object
    geo: Geometry
    x: np.ndarray
    f: np.ndarray
    g: np.ndarray
    g0: np.ndarray

    def vary(self, x, f, j, a, eps):
        return vary_node(self.geo, x, f, j, a, eps, H_ORACLE)


def initial_configuration(geo: Geometry):
    """A non-trivial g_0 (the oracle does not depend on it; reconstruction does)."""
    rotation = Rotation.from_rotvec([0.3, -0.5, 0.2]).as_matrix()
    if geo.label == "SO3":
        return rotation
    if geo.label == "SE2":
        return se2(0.4, [0.2, -0.1])
    g0 = np.eye(4)
    g0[:3, :3], g0[:3, 3] = rotation, [0.3, -0.2, 0.5]
    return g0


@pytest.fixture(scope="module")
def cases(compiled):
    cache = {}

    def get_case(name):
        if name not in cache:
            model = get(name)
            mod, geo = compiled(name), Geometry(model.groupoid)
            xi = np.array(model.example.initial[-1], dtype=float)
            if mod.model.order == 2:
                # the example's increments barely change; make the cubic bend visibly
                xi = xi[0] + H_ORACLE * np.arange(3)[:, None] * np.array([1.0, -0.5, 0.4])
            g0 = initial_configuration(geo)
            initial = (g0, xi) if geo.phi is None else (model.example.initial[0], g0, xi)
            res = mod.integrate(initial, N_ORACLE, H_ORACLE)
            assert res.success, res.message
            assert res.f.shape[0] == N_ORACLE
            # the path really moves (the oracle is not trivial)
            assert np.ptp(res.f, axis=0).max() > 0.1
            cache[name] = Case(mod, geo, res.x, res.f, res.g, g0)
        return cache[name]
    return get_case


@pytest.mark.parametrize("name", ORACLE_MODELS)
def test_reconstruction(name, cases):
    """g_{k+1} = g_k τ(hξ_k) and q_{k+1} = φ(q_k, τ(hξ_k)), with NumPy's τ (expm or the
    Cayley solve) and the declared action: the generated code retracts as declared."""
    case = cases(name)
    geo, f = case.geo, case.f
    np.testing.assert_array_equal(case.g[0], case.g0)
    W = np.array([geo.increment(v, H_ORACLE) for v in f])
    np.testing.assert_allclose(case.g[1:], case.g[:-1] @ W, rtol=0, atol=1e-14)
    if geo.phi is not None:
        q_next = np.array([geo.phi(q, w) for q, w in zip(case.x[:-1], W)])
        np.testing.assert_allclose(case.x[1:], q_next, rtol=0, atol=1e-14)


@pytest.mark.parametrize("name", [n for n in ORACLE_MODELS if n.endswith("_exp")])
def test_log_series_matches_logm(name, cases):
    """The oracle's exp⁻¹ (artanh series) agrees with scipy.linalg.logm on the path."""
    case = cases(name)
    for v in case.f:
        W = case.geo.increment(v, H_ORACLE)
        reference = logm(W)
        assert np.abs(np.imag(reference)).max() < 1e-14
        X = log_near_identity(W)
        assert np.abs(X - np.real(reference)).max() < 1e-14
        assert np.abs(case.geo.coords(X) - H_ORACLE * v).max() < 1e-14


def enforced_nodes(order, E):
    """Nodes whose discrete Euler–Lagrange equation the step map solved: r … E − r (for
    first order every interior node; the first and last r lack windows)."""
    return list(range(order, E - order + 1))


@pytest.mark.parametrize("name", ORACLE_MODELS)
def test_computed_path_is_stationary_under_group_variations(name, cases):
    case = cases(name)
    nodes = enforced_nodes(case.mod.model.order, case.f.shape[0])
    assert len(nodes) == N_ORACLE - 2 * case.mod.model.order + 1     # every interior node
    out = oracle(case.mod, case.vary, case.geo.n, case.x, case.f, H_ORACLE, nodes)
    assert_stationary(name, out, TOL)


@pytest.mark.parametrize("name", ORACLE_MODELS)
def test_oracle_detects_a_perturbed_path(name, cases):
    """Negative control: ξ_j moved by 1e-3 (base points after it recomputed) breaks
    stationarity at nodes j and j + 1, the nodes of element j; the nodes before the
    windows holding element j (< j − r + 1) are untouched. (On an action groupoid the
    later nodes are off too: their base points moved.)"""
    case = cases(name)
    r, E = case.mod.model.order, case.f.shape[0]
    nodes = enforced_nodes(r, E)
    j = E // 2
    f = case.f.copy()
    f[j] += 1e-3 * np.linspace(1.0, 0.5, f.shape[1])
    x = recompute_base_points(case.geo, case.x, f, H_ORACLE, j)
    out = oracle(case.mod, case.vary, case.geo.n, x, f, H_ORACLE, nodes)
    by_node = dict(zip(out.nodes.tolist(), out.relative))
    for k in (j, j + 1):
        assert by_node[k] > 1e3 * TOL, (name, k, by_node[k])
    assert max(by_node[k] for k in nodes if k < j - r + 1) < TOL


# ---------------------------------------------------------------------------------------
# 2. Heavy top
# ---------------------------------------------------------------------------------------
N_LONG = 100_000
H_LONG = 0.01


def drift_tenths(err):
    tenth = len(err) // 10
    return err[:tenth].max(), err[-tenth:].max()


@pytest.mark.parametrize("name", ["heavy_top", "heavy_top_exp"])
def test_heavy_top_invariants(name, compiled):
    """10⁵ steps (T = 1000) of the bundled example, g_0 = I (so Γ_0 is the spatial
    vertical and Γ_k = R_kᵀΓ_0).

    * |Γ_k| = 1 to round-off: Γ_{k+1} = R(hξ_k)ᵀΓ_k with R orthogonal to round-off.
    * Γ_k·μ_k — the vertical component Γ_0·(R_kμ_k) of the spatial angular momentum,
      Noether's quantity for rotations about the vertical — constant to 1e-12 relative
      to |μ|, while the horizontal components (torqued by gravity) and μ itself move by
      O(1).
    * Energy: the error is an O(h²) oscillation (≫ round-off) whose amplitude in the
      last tenth is no larger than in the first.
    """
    mod = compiled(name)
    model = get(name)
    q0, xi0 = model.example.initial
    res = mod.integrate((q0, xi0), N_LONG, H_LONG)
    assert res.success, res.message
    Gamma, mu, R = res.x, res.momenta, res.g
    assert Gamma.shape == mu.shape == (N_LONG + 1, 3)
    norm = np.abs(np.linalg.norm(Gamma, axis=1) - 1).max()
    np.testing.assert_allclose(Gamma, np.einsum("kji,j->ki", R, Gamma[0]), rtol=0, atol=1e-12)
    vertical = np.einsum("ki,ki->k", Gamma, mu)
    scale = np.linalg.norm(mu, axis=1).max()
    drift = np.abs(vertical - vertical[0]).max() / scale
    spatial = np.einsum("kij,kj->ki", R, mu)
    horizontal = spatial - np.outer(spatial @ Gamma[0], Gamma[0])
    np.testing.assert_allclose(spatial @ Gamma[0], vertical, rtol=0, atol=1e-12 * scale)
    first, last = drift_tenths(np.abs(res.energy - res.energy[0]))
    print(f"{name}: ||Γ|−1| {norm:.1e}, Γ·μ drift {drift:.1e} (Γ·μ = {vertical[0]:.6f}), "
          f"energy error first/last tenth {first:.3e}/{last:.3e}")
    assert norm < 1e-13
    assert drift < 1e-12
    assert np.ptp(mu, axis=0).max() > 1 and np.ptp(horizontal, axis=0).max() > 1
    assert first > 1e6 * U * abs(res.energy[0])
    assert last <= 1.1 * first


# ---------------------------------------------------------------------------------------
# 3. Spherical pendulum
# ---------------------------------------------------------------------------------------
ELL, GRAVITY = 1.0, 9.81                        # bundled defaults (m = 1)
GAMMA0 = np.array([0.0, 0.6, -0.8])
# R_0 with R_0ᵀe₃ = Γ_0: rows (e₁, Γ_0 × e₁, Γ_0), a right-handed orthonormal frame
R0_PENDULUM = np.array([[1.0, 0.0, 0.0], np.cross(GAMMA0, [1.0, 0.0, 0.0]), GAMMA0])
OMEGA0 = np.array([1.0, 0.5, 0.0])              # no spin about the rod
T_CONV = 2.0
N_CONV = [50, 100, 200, 400]


@pytest.fixture(scope="module")
def pendulum_reference():
    """Bob b, velocity v and the rod's spin-free frame R (Ṙ = RΩ̂, Ω₃ = 0, b = −ℓRe₃):
    b̈ = −g e₃ + κ b with κ = (g b₃ − |ḃ|²)/ℓ² keeping |b| = ℓ (DOP853, rtol 1e-12)."""
    assert np.allclose(R0_PENDULUM @ R0_PENDULUM.T, np.eye(3))
    assert np.isclose(np.linalg.det(R0_PENDULUM), 1) and np.allclose(R0_PENDULUM.T @ E3, GAMMA0)
    b0 = -ELL * R0_PENDULUM @ E3
    v0 = -ELL * R0_PENDULUM @ np.cross(OMEGA0, E3)

    def rhs(t, y):
        b, v, R = y[:3], y[3:6], y[6:].reshape(3, 3)
        kappa = (GRAVITY * b[2] - v @ v) / ELL**2
        body = R.T @ v                           # = −ℓ Ω × e₃ = −ℓ (Ω₂, −Ω₁, 0)
        Omega = np.array([body[1], -body[0], 0.0]) / ELL
        return np.concatenate([v, -GRAVITY * E3 + kappa * b, (R @ hat(Omega)).reshape(-1)])

    sol = solve_ivp(rhs, (0.0, T_CONV), np.concatenate([b0, v0, R0_PENDULUM.reshape(-1)]),
                    method="DOP853", rtol=1e-12, atol=1e-12, dense_output=True)
    assert sol.success
    assert np.abs(np.linalg.norm(sol.y[:3], axis=0) - ELL).max() < 1e-9
    return sol


@pytest.mark.parametrize("name", ["spherical_pendulum", "spherical_pendulum_exp"])
def test_spherical_pendulum_converges_at_order_two(name, compiled, pendulum_reference):
    """ξ_0 = τ⁻¹(R_0ᵀR(h))/h from the reference (the first step exact, consistent to any
    order); the bob −ℓR_Ne₃ at T = 2 converges at order 2. So does the conserved discrete
    Γ·μ to the continuous angular momentum about the vertical, m (b × ḃ)·e₃."""
    mod = compiled(name)
    geo = Geometry(get(name).groupoid)
    sol = pendulum_reference
    b0, v0 = sol.y[:3, 0], sol.y[3:6, 0]
    L_vertical = np.cross(b0, v0) @ E3
    hs, err_bob, err_L = [], [], []
    for N in N_CONV:
        h = T_CONV / N
        Rh = sol.sol(h)[6:].reshape(3, 3)
        xi0 = geo.fibre(R0_PENDULUM.T @ Rh, h)
        res = mod.integrate((GAMMA0, R0_PENDULUM, [xi0]), N, h)
        assert res.success, res.message
        assert res.t[-1] == pytest.approx(T_CONV)
        bob = -ELL * res.g[-1] @ E3
        vertical = np.einsum("ki,ki->k", res.x, res.momenta)
        hs.append(h)
        err_bob.append(np.abs(bob - sol.sol(T_CONV)[:3]).max())
        err_L.append(abs(vertical[0] - L_vertical))
    slope = float(np.polyfit(np.log(hs), np.log(err_bob), 1)[0])
    slope_L = float(np.polyfit(np.log(hs), np.log(err_L), 1)[0])
    print(f"{name}: bob errors {np.array(err_bob)}, slope {slope:.3f}; "
          f"Γ·μ − L_z {np.array(err_L)}, slope {slope_L:.3f}")
    assert min(err_bob) > 1e3 * 1e-9                 # far above the reference's error
    assert abs(slope - 2) < 0.1
    assert abs(slope_L - 2) < 0.1


@pytest.mark.parametrize("name", ["spherical_pendulum", "spherical_pendulum_exp"])
def test_spherical_pendulum_vertical_momentum(name, compiled):
    """10⁴ steps of the bundled example: Γ_k = R_kᵀe₃ (g_0 = R_0 consistent with Γ_0) and
    the angular momentum about the vertical Γ_k·μ_k = e₃·R_kμ_k conserved to round-off."""
    mod = compiled(name)
    xi0 = get(name).example.initial[-1]
    res = mod.integrate((GAMMA0, R0_PENDULUM, xi0), 10_000, 0.01)
    assert res.success, res.message
    Gamma, mu = res.x, res.momenta
    np.testing.assert_allclose(Gamma, np.einsum("kji,j->ki", res.g, E3), rtol=0, atol=1e-13)
    vertical = np.einsum("ki,ki->k", Gamma, mu)
    drift = np.abs(vertical - vertical[0]).max() / np.linalg.norm(mu, axis=1).max()
    print(f"{name}: Γ·μ = {vertical[0]:.6f}, drift {drift:.1e}")
    assert np.ptp(mu, axis=0).max() > 1
    assert drift < 1e-12


# ---------------------------------------------------------------------------------------
# 4. Planar body on SE(2)
# ---------------------------------------------------------------------------------------
MASS, INERTIA_PB, OFFSET = 1.0, 0.5, 0.3          # bundled defaults
QUARTER = np.array([[0.0, -1.0], [1.0, 0.0]])
C_BODY = np.array([OFFSET, 0.0])                  # centre of mass in the body frame
THETA0, P0 = 0.4, np.array([0.2, -0.1])
XI_CONT = np.array([1.0, 0.5, -0.2])              # body velocity (ω, v) at t = 0


def se2(theta, p):
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, p[0]], [s, c, p[1]], [0.0, 0.0, 1.0]])


class PlanarExact:
    """ω constant; centre of mass p + Rc moving uniformly on a straight line."""

    omega = XI_CONT[0]
    R0 = se2(THETA0, [0, 0])[:2, :2]
    com0 = P0 + R0 @ C_BODY
    velocity = R0 @ (XI_CONT[1:] + XI_CONT[0] * QUARTER @ C_BODY)

    @classmethod
    def g(cls, t):
        R = se2(THETA0 + cls.omega * t, [0, 0])[:2, :2]
        return se2(THETA0 + cls.omega * t, cls.com0 + cls.velocity * t - R @ C_BODY)

    @classmethod
    def xi(cls, t):
        """Body velocity (ω, Rᵀṗ)."""
        g = cls.g(t)
        pdot = cls.velocity - cls.omega * g[:2, :2] @ QUARTER @ C_BODY
        return np.concatenate([[cls.omega], g[:2, :2].T @ pdot])


def centre_of_mass(g):
    return g[:, :2, 2] + np.einsum("kij,j->ki", g[:, :2, :2], C_BODY)


def spatial_momenta(geo: Geometry, g, mu):
    """π_k = Ad*_{g_k⁻¹} μ_k: π(η) = μ(g⁻¹ η g), the left action's Noether momentum.
    (g⁻¹ = [[Rᵀ, −Rᵀp], [0, 1]] written out: a numerical inverse would lose u·|p|².)"""
    out = np.empty_like(mu)
    for k, (gk, m) in enumerate(zip(g, mu)):
        gi = np.eye(len(gk))
        gi[:-1, :-1] = gk[:-1, :-1].T
        gi[:-1, -1] = -gk[:-1, :-1].T @ gk[:-1, -1]
        out[k] = [m @ geo.coords(gi @ E @ gk) for E in geo.E]
    return out


@pytest.mark.parametrize("name", ["planar_body", "planar_body_exp"])
def test_planar_body_samples_the_exact_motion(name, compiled):
    """From the exact first step (ξ_0 = τ⁻¹(g(0)⁻¹g(h))/h) the discrete path is the exact
    motion sampled at t_k, to round-off, for both retractions (measured ≤ 3e-14 over 400
    steps). Why this can be: in the centre-of-mass frame the exact motions are relative
    equilibria g(t) = T(Vt)·g_c·Rot(ωt), so the sampled increments w_k = Rot(−ωt_k) w_0
    Rot(ωt_k) form one Ad-orbit; L_d(w) = h l(τ⁻¹(w)/h) inherits the rotation invariance
    of l (τ is Ad-equivariant), so the discrete Euler–Poincaré equation at every node is
    the one at node 1 — and that one holds (measured; a discrete relative equilibrium).
    As any two nodes fix one such motion, from any start ω_k is constant and the centre
    of mass has zero second differences."""
    mod = compiled(name)
    geo = Geometry(get(name).groupoid)
    N, h = 400, 0.005
    xi0 = geo.fibre(np.linalg.solve(PlanarExact.g(0), PlanarExact.g(h)), h)
    res = mod.integrate((PlanarExact.g(0), [xi0]), N, h)
    assert res.success, res.message
    exact = np.array([PlanarExact.g(t) for t in res.t])
    err = np.abs(res.g - exact).max()
    com = centre_of_mass(res.g)
    second = np.abs(com[2:] - 2 * com[1:-1] + com[:-2]).max()
    print(f"{name}: |g_k − g(t_k)| ≤ {err:.1e}, ω spread {np.ptp(res.f[:, 0]):.1e}, "
          f"centre-of-mass second differences {second:.1e}")
    assert err < 1e-12
    assert np.ptp(res.f[:, 0]) < 1e-12
    assert second < 1e-13
    np.testing.assert_allclose((com[1:] - com[:-1]) / h, np.tile(PlanarExact.velocity, (N, 1)),
                               rtol=0, atol=1e-10)
    # the body velocity itself turns (the motion is not a one-parameter subgroup)
    assert np.ptp(res.f[:, 1:], axis=0).max() > 0.5


@pytest.mark.parametrize("name", ["planar_body", "planar_body_exp"])
def test_planar_body_converges_at_order_two(name, compiled):
    """From continuous initial data, ξ_0 = ξ(h/2) (the body velocity at the first
    midpoint, consistent to second order), the configuration at T = 2 converges at order
    2 to the exact motion; ω_k stays constant and the centre of mass uniform."""
    mod = compiled(name)
    hs, errs = [], []
    for N in N_CONV:
        h = T_CONV / N
        res = mod.integrate((PlanarExact.g(0), [PlanarExact.xi(h / 2)]), N, h)
        assert res.success, res.message
        com = centre_of_mass(res.g)
        assert np.ptp(res.f[:, 0]) < 1e-12
        assert np.abs(com[2:] - 2 * com[1:-1] + com[:-2]).max() < 1e-13
        hs.append(h)
        errs.append(np.abs(res.g[-1] - PlanarExact.g(T_CONV)).max())
    slope = float(np.polyfit(np.log(hs), np.log(errs), 1)[0])
    print(f"{name}: errors {np.array(errs)}, slope {slope:.3f}")
    assert min(errs) > 1e-8
    assert abs(slope - 2) < 0.1


@pytest.mark.parametrize("name", ["planar_body", "planar_body_exp"])
def test_planar_body_noether_momenta(name, compiled):
    """10⁴ steps: π_k = Ad*_{g_k⁻¹}μ_k — angular momentum about the origin π_ω and the
    spatial linear momentum (π_v1, π_v2) = R_k μ_v — conserved to round-off; the body
    momenta μ_k themselves turn by O(1)."""
    mod = compiled(name)
    geo = Geometry(get(name).groupoid)
    res = mod.integrate((PlanarExact.g(0), [XI_CONT]), 10_000, 0.01)
    assert res.success, res.message
    mu = res.momenta
    pi = spatial_momenta(geo, res.g, mu)
    np.testing.assert_allclose(pi[:, 1:], np.einsum("kij,kj->ki", res.g[:, :2, :2], mu[:, 1:]),
                               rtol=0, atol=1e-13)
    # the scale of π_ω = μ_ω + p × Rμ_v is its terms' size, which grows with |p|
    scale = np.abs(mu).max() * (1 + np.linalg.norm(res.g[:, :2, 2], axis=1).max())
    drift = np.abs(pi - pi[0]).max() / scale
    print(f"{name}: π_0 = {pi[0]}, drift {drift:.1e} (scale {scale:.1f})")
    assert np.ptp(mu, axis=0).max() > 0.5
    assert drift < 1e-12


# ---------------------------------------------------------------------------------------
# 5. SE(3) body
# ---------------------------------------------------------------------------------------
SE3_G0 = np.eye(4)
SE3_G0[:3, :3] = Rotation.from_rotvec([0.7, -0.4, 1.1]).as_matrix()
SE3_G0[:3, 3] = [0.3, -0.2, 0.5]
SE3_Q0 = np.array([0.1, 0.0, 0.6, 0.8])          # (z, Γ)


@pytest.mark.parametrize("name", ["se3_body", "se3_body_exp"])
def test_se3_body_invariants(name, compiled):
    """10⁵ steps from (z_0, Γ_0), g_0 = (R_0, p_0). The spatial vertical is n = R_0Γ_0 and
    the reconstruction keeps Γ_k = R_kᵀn, z_k − n·p_k constant. Spatial momenta
    P = R μ_V and L = R μ_Ω + p × P (π = Ad*_{g⁻¹}μ): the potential depends on z and Γ
    only, so n·L (rotations about the vertical) and P − (n·P)n (horizontal translations)
    are Noether momenta, conserved to round-off relative to their terms' size
    (|Rμ_Ω| + |p||P|: the body drifts horizontally, so |p| grows to ≈ 300); n·P and the
    horizontal part of L vary. Energy error bounded; |Γ| = 1."""
    mod = compiled(name)
    xi0 = get(name).example.initial[-1]
    res = mod.integrate((SE3_Q0, SE3_G0, xi0), N_LONG, H_LONG)
    assert res.success, res.message
    R, p, mu = res.g[:, :3, :3], res.g[:, :3, 3], res.momenta
    z, Gamma = res.x[:, 0], res.x[:, 1:]
    n = SE3_G0[:3, :3] @ SE3_Q0[1:]
    np.testing.assert_allclose(Gamma, np.einsum("kji,j->ki", R, n), rtol=0, atol=1e-12)
    assert np.ptp(z - p @ n) < 1e-10 * (1 + np.abs(p).max())
    norm = np.abs(np.linalg.norm(Gamma, axis=1) - 1).max()
    P = np.einsum("kij,kj->ki", R, mu[:, 3:])
    L = np.einsum("kij,kj->ki", R, mu[:, :3]) + np.cross(p, P)
    Ln, Pn = L @ n, P @ n
    P_horizontal = P - np.outer(Pn, n)
    scale_L = (np.linalg.norm(mu[:, :3], axis=1) + np.linalg.norm(p, axis=1)
               * np.linalg.norm(P, axis=1)).max()
    scale_P = np.linalg.norm(P, axis=1).max()
    drift_L = np.abs(Ln - Ln[0]).max() / scale_L
    drift_P = np.abs(P_horizontal - P_horizontal[0]).max() / scale_P
    first, last = drift_tenths(np.abs(res.energy - res.energy[0]))
    print(f"{name}: n·L drift {drift_L:.1e} (scale {scale_L:.0f}), horizontal P drift "
          f"{drift_P:.1e}, ||Γ|−1| {norm:.1e}, energy error first/last tenth "
          f"{first:.3e}/{last:.3e}")
    assert norm < 1e-13
    assert drift_L < 1e-12 and drift_P < 1e-12
    assert np.ptp(Pn) > 1 and np.ptp(L - np.outer(Ln, n), axis=0).max() > 1
    assert np.linalg.norm(P_horizontal[0]) > 0.1       # the horizontal momentum is not 0
    assert first > 1e6 * U * abs(res.energy[0])
    assert last <= 1.1 * first


# ---------------------------------------------------------------------------------------
# 6. Product groupoid: rigid body with a rotor on its third axis
# ---------------------------------------------------------------------------------------
ROTOR_PARAMS = {"I1": 1.0, "I2": 2.0, "I3": 3.0, "J": 0.5}


def rotor_model():
    G = ProductGroupoid(SO3(), PairGroupoid("phi"))
    body, rotor = G.factors
    Omega, phidot = sp.Matrix(body.xi), rotor.qdot[0]
    I1, I2, I3, J = sp.symbols("I1 I2 I3 J", positive=True)
    L = (Omega.T * sp.diag(I1, I2, I3) * Omega)[0] / 2 + J * (phidot + Omega[2]) ** 2 / 2
    model = Model("test_rotor_body", G, lagrangian=L,
                  parameters={I1: 1.0, I2: 2.0, I3: 3.0, J: 0.5})
    assert model.order == 1 and model.discretisation == "product"
    return model


@pytest.fixture(scope="module")
def rotor(build_dir):
    model = rotor_model()
    mod = compile_model(model, build_dir)
    assert mod.INFO.source_dim == 1 and mod.INFO.fibre_dim == 4
    return mod, Geometry(model.groupoid.factors[0])


def rotor_variation(geo: Geometry, h):
    """SO(3) part: the group variation of node j on ξ (columns 0–2); rotor: node
    variation φ_j → φ_j + ε, which is x[j] and the fibre f[j−1, 3] (= φ_j)."""
    def vary(x, f, j, a, eps):
        if a < 3:
            xx, ff = vary_node(geo, x[:, :0], f[:, :3], j, a, eps, h)
            f = f.copy()
            f[:, :3] = ff
            return x, f
        x, f = x.copy(), f.copy()
        x[j, 0] += eps
        if j >= 1:
            f[j - 1, 3] += eps
        return x, f
    return vary


def test_product_groupoid_rotor(rotor):
    mod, geo = rotor
    h = H_ORACLE
    res = mod.integrate(([0.1], [[0.3, 1.0, 0.2, 0.1 + h * 5.0]]), N_ORACLE, h)
    assert res.success, res.message
    E = res.f.shape[0]
    assert res.x.shape == (E + 1, 1) and res.g.shape == (E + 1, 3, 3)
    np.testing.assert_array_equal(res.x[1:, 0], res.f[:, 3])     # pair: x_{k+1} = f_k
    W = np.array([geo.increment(v, h) for v in res.f[:, :3]])
    np.testing.assert_allclose(res.g[1:], res.g[:-1] @ W, rtol=0, atol=1e-14)
    assert np.ptp(res.f[:, :3], axis=0).max() > 0.1
    vary = rotor_variation(geo, h)
    out = oracle(mod, vary, 4, res.x, res.f, h, list(range(1, E)))
    print(f"rotor: max relative gradient {out.relative.max():.2e} "
          f"(noise bound {out.noise.max():.1e})")
    assert out.noise.max() < TOL / 10
    assert out.relative.max() < TOL
    # negative control: the rotor angle of node j moved by 1e-3 (x[j] and f[j−1] agree)
    j = E // 2
    x, f = vary(res.x, res.f, j, 3, 1e-3)
    bad = dict(zip(range(1, E), oracle(mod, vary, 4, x, f, h, list(range(1, E))).relative))
    assert min(bad[k] for k in (j - 1, j, j + 1)) > 1e3 * TOL
    assert max(v for k, v in bad.items() if abs(k - j) > 1) < TOL


def test_product_groupoid_rotor_noether(rotor):
    """2000 steps: the rotor momentum p_φ = J(φ̇ + Ω₃) (φ cyclic) and the body's spatial
    angular momentum R_k μ_Ω are conserved. Their error is round-off of the pair
    representation: φ_k grows (to ≈ 100) and φ̇ = (φ_{k+1} − φ_k)/h carries u|φ|/h each
    step, a random walk of ~√N·J·u·max|φ|/h (measured 0.1–0.3 of that for N = 10³…1.6·10⁴)."""
    mod, geo = rotor
    N, h = 2000, 0.01
    res = mod.integrate(([0.1], [[0.3, 1.0, 0.2, 0.1 + h * 5.0]]), N, h)
    assert res.success, res.message
    mu = res.momenta
    p_phi, spatial = mu[:, 3], np.einsum("kij,kj->ki", res.g, mu[:, :3])
    J = ROTOR_PARAMS["J"]
    bound = math.sqrt(N) * J * U * np.abs(res.x).max() / h
    drift_phi = np.ptp(p_phi)
    drift_spatial = np.abs(spatial - spatial[0]).max()
    print(f"rotor: p_φ = {p_phi[0]:.6f} drift {drift_phi:.1e}, spatial drift "
          f"{drift_spatial:.1e}, bound {bound:.1e}")
    assert np.ptp(mu[:, :3], axis=0).max() > 0.5 and np.ptp(res.f[:, 3] - res.x[:-1, 0]) > 1e-3
    assert drift_phi < bound and drift_spatial < bound


# ---------------------------------------------------------------------------------------
# 7. Errors
# ---------------------------------------------------------------------------------------
def test_left_action_is_refused_with_a_hint():
    with pytest.raises(ModelError) as info:
        ActionGroupoid(SO3(), "q1 q2 q3", lambda q, W: W * q, label="R3xSO3")
    message = str(info.value)
    assert "R3xSO3" in message and "not a right action" in message
    assert "left action" in message and "W⁻¹" in message
    # the right action Wᵀq (= W⁻¹q) is accepted
    ActionGroupoid(SO3(), "q1 q2 q3", lambda q, W: W.T * q)


def test_map_that_is_no_action_at_all_has_no_left_action_hint():
    with pytest.raises(ModelError) as info:
        ActionGroupoid(SO3(), "q1 q2 q3", lambda q, W: W.T * W.T * q)
    message = str(info.value)
    assert "not a right action" in message and "left action" not in message


def test_identity_must_act_trivially():
    with pytest.raises(ModelError) as info:
        ActionGroupoid(SO3(), "q1 q2 q3", lambda q, W: W.T * q + sp.Matrix([1, 0, 0]))
    message = str(info.value)
    assert "not an action" in message and "φ(q, I)" in message and "q1 + 1" in message


def test_product_factors_sharing_names_are_refused():
    with pytest.raises(ModelError) as info:
        ProductGroupoid(SO3(), SO3())
    message = str(info.value)
    assert "share coordinate names" in message and "Omega1" in message and "rename" in message
    with pytest.raises(ModelError, match=r"share coordinate names \['Omega1', 'Omega1_dot'\]"):
        ProductGroupoid(SO3(), PairGroupoid("Omega1"))
    # renamed, the same product is fine
    ProductGroupoid(SO3(), SO3(names="a b c"))


@pytest.mark.parametrize("name", ["heavy_top", "heavy_top_exp", "se3_body"])
def test_whole_trajectory_solve_recovers_the_stepped_path(compiled, name):
    """Issue 3, item 5: the whole-trajectory solve on an action groupoid. The path of the
    step map from (Γ_0, R_0, ξ_0) solves the discrete Euler–Lagrange equations with its own
    end nodes fixed, so solve_bvp, started from the chord between the ends, must return it:
    configurations, base points and increments, to the rounding level of the step map."""
    mod = compiled(name)
    ex = get(name).example
    N, h = 60, ex.h
    path = mod.integrate(ex.initial, N, h)
    assert path.success, path.message
    x, g, f = path.x, path.g, path.f
    result = mod.solve_bvp((x[:1], g[:1]), (x[-1:], g[-1:]), N, h)
    assert result.success, result.message
    print(f"{name}: {result.message}; |Δg| {np.abs(result.g - g).max():.1e}, "
          f"|Δx| {np.abs(result.x - x).max():.1e}, |Δξ| {np.abs(result.f - f).max():.1e}")
    np.testing.assert_allclose(result.g, g, rtol=0, atol=1e-12)
    np.testing.assert_allclose(result.x, x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(result.f, f, rtol=0, atol=1e-12 * (1 + np.abs(f).max()))
    # a genuinely nonlinear solve: the chord guess is not the path
    assert result.iterations >= 2
