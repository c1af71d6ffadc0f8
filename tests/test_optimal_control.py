"""Optimal control as constrained second-order variational problems (paper §3.3, DESIGN.md §4, §5).

Every bundled problem of ``symvi.models.CONTROL`` is solved as a whole trajectory and the
result is checked with NumPy alone (hat map, Cayley map and its inverse, Rodrigues' exp,
SciPy's rotation vector as exp⁻¹, and the controlled equations EL(L) written out by hand):

1. Variational oracle: along the solution, every free node j (2 … N−2) is varied by the
   groupoid's own variation (pair: q_j + εe_a; group: g_j τ(εe_a) with ξ_{j−1}, ξ_j recomputed
   from the configurations and, on the action factor, Γ_j → τ(εe_a)ᵀΓ_j), and five-point
   differences show that the augmented action S_aug = Σ_w [L_d(w) + λ^w·Φ_d(w)] is
   stationary relative to the size of its individual terms; ∂S_aug/∂λ^w = Φ_d(w) vanishes.
   Negative controls: zeroed multipliers and a perturbed path are not stationary.
2. Discrete controlled equations: the controls returned are EL(L)_a at every window's
   quadrature point (Ω = mean of ξ, Ω̇ = Δξ/h, Γ at the middle node; q = mean of three
   nodes, q̇ and q̈ central differences), the unactuated equations EL(L)_A = 0 hold there,
   and the cost is Σ_w h·C(u_w). With variational equations (``*_variational``) they are
   the forced discrete Euler–Lagrange equations of :mod:`top_equations` instead.
3. The optimal rigid-body cost converges at order 2 to the continuous optimum of the
   horizon [h/2, T − h/2] that the discrete rest conditions impose (order 1 to that of T).
4. Bad input and failures are reported (ValueError, ModelError, statuses, NewtonError).
"""
from __future__ import annotations

import math
import importlib

import numpy as np
import pytest
import sympy as sp
from scipy.optimize import fsolve
from scipy.spatial.transform import Rotation

from symvi import ModelError, PairGroupoid, optimal_control
from symvi.models import CONTROL, get
from so3 import I3, cay, cay_inv, hat, vee
from top_equations import variational_terms

U = np.finfo(float).eps
N_ORACLE = 48          # steps of the oracle's and the equations' solutions
EPS_FD = 1e-3          # five-point difference step of the oracle
TOL_ORACLE = 1e-8      # relative gradient of S_aug accepted as stationary
TOL_EQ = 1e-9          # relative residual of the controlled equations


# ---------------------------------------------------------------------------------------
# NumPy geometry and physics, independent of the generated code
# ---------------------------------------------------------------------------------------
def tau(retraction: str, v) -> np.ndarray:
    """cay(v̂) = (I − v̂/2)⁻¹(I + v̂/2), resp. exp(v̂) by Rodrigues' formula
    I + (sin θ/θ) v̂ + ½ (sin(θ/2)/(θ/2))² v̂², θ = |v| (scipy's expm is ~1000× slower)."""
    X = hat(v)
    if retraction == "cayley":
        return cay(X)
    angle = np.linalg.norm(v)
    return I3 + np.sinc(angle / np.pi) * X + 0.5 * np.sinc(angle / (2 * np.pi)) ** 2 * X @ X


def tau_inv(retraction: str, W) -> np.ndarray:
    """Coordinates of τ⁻¹(W): 2(W − I)(W + I)⁻¹, resp. the rotation vector of W."""
    if retraction == "cayley":
        return vee(cay_inv(W))
    return Rotation.from_matrix(W).as_rotvec()


def kind(name: str) -> str:
    """The groupoid: "lie" (SO(3)), "top" (R³×SO(3) × pair of rotor angles) or "pair"."""
    return "lie" if name.startswith("rigid_body") else \
        "top" if name.startswith("heavy_top") else "pair"


def retraction(name: str) -> str:
    return "exp" if name.endswith("_exp") else "cayley"


def quadrature_points(name, r, h) -> dict:
    """The window quadrature points of the rule of DESIGN.md §3 (window w: elements w, w+1)."""
    pts = {}
    if kind(name) != "pair":
        xi = r.f[:, :3]
        pts["Om"], pts["dOm"] = (xi[:-1] + xi[1:]) / 2, (xi[1:] - xi[:-1]) / h
    if kind(name) != "lie":
        q = r.x[:, 3:] if kind(name) == "top" else r.x
        pts["q"] = (q[:-2] + q[1:-1] + q[2:]) / 3
        pts["dq"], pts["ddq"] = (q[2:] - q[:-2]) / (2 * h), (q[2:] - 2 * q[1:-1] + q[:-2]) / h**2
    if kind(name) == "top":
        pts["Gam"] = r.x[1:-1, :3]
    pts["h"] = h
    return pts


def physics(name, p, pts):
    """(control terms, constraint terms, cost density as a function of u): each control
    u_a and constraint Φ^A as the list of the terms of EL(L) whose sum it is, written out
    by hand from the model's Lagrangian."""
    if kind(name) == "lie":                      # τ = IΩ̇ + Ω×IΩ, cost ½Σ(τ_i/I_i)²
        I = np.array([p["I1"], p["I2"], p["I3"]])
        Om, IOm = pts["Om"], pts["Om"] * I
        c1, c2 = [1, 2, 0], [2, 0, 1]
        plus, minus = Om[:, c1] * IOm[:, c2], Om[:, c2] * IOm[:, c1]
        u = [[I[i] * pts["dOm"][:, i], plus[:, i], -minus[:, i]] for i in range(3)]
        return u, None, lambda tq: 0.5 * ((tq / I) ** 2).sum(axis=1)
    if kind(name) == "top" and name.endswith("_variational"):
        h = pts["h"]                             # the window's two elements from the point
        xi0, xi1 = pts["Om"] - h * pts["dOm"] / 2, pts["Om"] + h * pts["dOm"] / 2
        rate0, rate1 = pts["dq"] - h * pts["ddq"] / 2, pts["dq"] + h * pts["ddq"] / 2
        u, phi = variational_terms(p, xi0, xi1, rate0, rate1, pts["Gam"], h)
        return u, phi, lambda uq: 0.5 * (uq**2).sum(axis=1)
    if kind(name) == "top":
        g1, g2, I3b, J1, J2, Mgh = (p[k] for k in ("gamma1", "gamma2", "I3bar", "J1", "J2", "Mgh"))
        (O1, O2, O3), (dO1, dO2, dO3) = pts["Om"].T, pts["dOm"].T
        (t1, t2), (tt1, tt2), G = pts["dq"].T, pts["ddq"].T, pts["Gam"].T
        u = [[J1 * dO1, J1 * tt1], [J2 * dO2, J2 * tt2]]
        phi = [[g1 * dO1, J1 * tt1, -g2 * O2 * O3, I3b * O2 * O3, -J2 * t2 * O3, -Mgh * G[1]],
               [g2 * dO2, J2 * tt2, g1 * O1 * O3, J1 * t1 * O3, -I3b * O1 * O3, Mgh * G[0]],
               [I3b * dO3, -g1 * O1 * O2, -J1 * t1 * O2, g2 * O2 * O1, J2 * t2 * O1]]
        return u, phi, lambda uq: 0.5 * (uq**2).sum(axis=1)
    # pair groupoid: EL(L) = d/dt ∂L/∂q̇ − ∂L/∂q of the model's L = T − V, by hand
    (a1, a2), (w1, w2), (b1, b2) = pts["q"].T, pts["dq"].T, pts["ddq"].T
    if name == "double_pendulum_oc":
        m1, m2, l1, l2, g = (p[k] for k in ("m1", "m2", "l1", "l2", "g"))
        c, s = np.cos(a1 - a2), np.sin(a1 - a2)
        u = [[(m1 + m2) * l1**2 * b1, m2 * l1 * l2 * c * b2, m2 * l1 * l2 * s * w2**2,
              (m1 + m2) * g * l1 * np.sin(a1)],
             [m2 * l2**2 * b2, m2 * l1 * l2 * c * b1, -m2 * l1 * l2 * s * w1**2,
              m2 * g * l2 * np.sin(a2)]]
        return u, None, lambda uq: 0.5 * (uq**2).sum(axis=1)
    M, m, ell, g = (p[k] for k in ("M", "m", "ell", "g"))   # cart-pole: (x, θ)
    u = [[(M + m) * b1, m * ell * np.cos(a2) * b2, -m * ell * np.sin(a2) * w2**2]]
    phi = [[m * ell * np.cos(a2) * b1, m * ell**2 * b2, -m * g * ell * np.sin(a2)]]
    return u, phi, lambda uq: 0.5 * (uq**2).sum(axis=1)


def path_scale(factor, terms):
    """factor × the largest Σ|terms| of each equation along the path: the size an error of
    the global solve is measured against (at single windows all terms may vanish)."""
    return factor * magnitude(terms).max(axis=0)


def total(terms):
    return np.stack([sum(t) for t in terms], axis=1)


def magnitude(terms):
    return np.stack([sum(map(np.abs, t)) for t in terms], axis=1)


def top_path(name, p, N, h):
    """Nodes (x, g) of a feasible non-planar heavy-top path: the rotor angles are prescribed,
    θ(t) = (0.8 sin²(πt/T) − t/2, 0.6 sin(2πt/T)), and each window's Φ(ξ_{w+1}) = 0 is solved
    in turn from g_0 = I, Γ_0 = e₃, ξ_0 = (0.05, −0.02, 0.03), with Γ_{k+1} = τ(hξ_k)ᵀΓ_k.

    The bundled example (a tilt about e₁) is planar (Ω₂ = Ω₃ = θ₂ = λ² = λ³ = 0), so three of
    the five variations would be stationary by symmetry alone; and from the default chord
    guess Newton stalls on every non-planar rest-to-rest problem tried. Here the end nodes
    of this path are the boundary data and the path itself the guess.
    """
    t, T = h * np.arange(N + 1), h * N
    theta = np.c_[0.8 * np.sin(np.pi * t / T) ** 2 - t / 2, 0.6 * np.sin(2 * np.pi * t / T)]
    xi, G, g = np.zeros((N, 3)), np.zeros((N + 1, 3)), np.zeros((N + 1, 3, 3))
    xi[0], G[0], g[0] = [0.05, -0.02, 0.03], I3[2], I3

    def window(w, z):            # quadrature point of window w − 1 with ξ_w = z
        q = theta[w - 1:w + 2]
        return dict(h=h, Om=(xi[w - 1] + z)[None] / 2, dOm=(z - xi[w - 1])[None] / h,
                    Gam=G[w][None],
                    q=q.mean(axis=0)[None], dq=(q[2] - q[0])[None] / (2 * h),
                    ddq=(q[2] - 2 * q[1] + q[0])[None] / h**2)

    for w in range(N):
        if w > 0:
            xi[w] = fsolve(lambda z: total(physics(name, p, window(w, z))[1])[0], xi[w - 1])
        W = tau(retraction(name), h * xi[w])
        g[w + 1], G[w + 1] = g[w] @ W, W.T @ G[w]
    return np.c_[G, theta], g


@pytest.fixture(scope="module")
def solved(compiled):
    """solved(name) -> (module, result, h, parameters): the optimum at N_ORACLE steps over the
    example's horizon T, from the example's boundary data (heavy top: see top_path)."""
    cache = {}

    def get_solved(name):
        if name not in cache:
            mod, ex = compiled(name), get(name).example
            h, N = ex.n_steps * ex.h / N_ORACLE, N_ORACLE
            p = dict(zip(mod.model.parameter_names, mod.model.parameter_defaults))
            if kind(name) == "top":
                x, g = top_path(name, p, N, h)
                r = mod.solve_bvp((x[:2], g[:2]), (x[-2:], g[-2:]), N, h,
                                  guess=(x[2:N - 1], g[2:N - 1]))
            else:
                r = mod.solve_bvp(ex.start, ex.end, N, h)
            assert r.success, r.message
            cache[name] = (mod, r, h, p)
        return cache[name]
    return get_solved


# ---------------------------------------------------------------------------------------
# 1. Variational oracle on the augmented action
# ---------------------------------------------------------------------------------------
def base_points(r):  # none on a Lie group over a point
    return r.x if r.x is not None else np.zeros((r.f.shape[0] + 1, 0))


def augmented_terms(mod, x, f, lam, h):
    """(windows, 1 + s): L_d(w) and each λ^w_A Φ^A_d(w), the terms of S_aug."""
    L = mod.model.along("lagrangian", x, f, h)
    return L if lam is None else np.hstack([L, lam * mod.model.along("constraint", x, f, h)])


def vary(name, x, g, f, j, a, eps, h):
    """(x, g, f) after varying node j by ε along direction a (see the module docstring)."""
    x, f = x.copy(), f.copy()
    if kind(name) == "pair" or a >= 3:           # a node coordinate q_j (x_j and f_{j−1})
        x[j, a] += eps
        f[j - 1, a] += eps
        return x, g, f
    sigma = tau(retraction(name), eps * I3[a])
    g = g.copy()
    g[j] = g[j] @ sigma
    f[j - 1, :3] = tau_inv(retraction(name), g[j - 1].T @ g[j]) / h
    f[j, :3] = tau_inv(retraction(name), g[j].T @ g[j + 1]) / h
    if kind(name) == "top":
        x[j, :3] = sigma.T @ x[j, :3]
    return x, g, f


def oracle(name, mod, x, g, f, lam, h, nodes, eps=EPS_FD):
    """Per node j: max over directions a of |∂S_aug/∂ε_a| / Σ_terms |∂term/∂ε_a| (five-point
    differences), and the rounding bound of that ratio."""
    base = augmented_terms(mod, x, f, lam, h)
    rel, noise = [], []
    for j in nodes:
        worst, floor = 0.0, 0.0
        for a in range(mod.model.n):
            T = {}
            for s in (-2, -1, 1, 2):
                xs, _, fs = vary(name, x, g, f, j, a, s * eps, h)
                T[s] = augmented_terms(mod, xs, fs, lam, h)
            d = (-T[2] + 8 * T[1] - 8 * T[-1] + T[-2]) / (12 * eps)
            scale = np.abs(d).sum()
            assert scale > 0, f"node {j}, direction {a}: S_aug does not depend on it"
            worst = max(worst, abs(math.fsum(d.ravel())) / scale)
            touched = np.any(d != 0, axis=1)
            floor = max(floor, 18 / (12 * eps) * 4 * U
                        * (np.abs(base[touched]).sum() + scale) / scale)
        rel.append(worst)
        noise.append(floor)
    return np.array(rel), np.array(noise)


@pytest.mark.parametrize("name", CONTROL)
def test_solution_is_stationary_for_the_augmented_action(name, solved):
    """∂S_aug/∂ε_a = 0 at every free node and direction, ∂S_aug/∂λ = Φ_d = 0."""
    mod, r, h, p = solved(name)
    x = base_points(r)
    nodes = range(2, N_ORACLE - 1)
    rel, noise = oracle(name, mod, x, r.g, r.f, r.multipliers, h, nodes)
    print(f"\n{name}: max relative gradient of S_aug {rel.max():.2e} (noise {noise.max():.1e})")
    assert noise.max() < TOL_ORACLE / 10
    assert rel.max() < TOL_ORACLE, f"not stationary at node {2 + int(np.argmax(rel))}"
    if r.multipliers is not None:
        _, phi, _ = physics(name, p, quadrature_points(name, r, h))
        residual = np.abs(mod.model.along("constraint", x, r.f, h)) / path_scale(h, phi)
        print(f"{name}: max relative Φ_d {residual.max():.2e}")
        assert residual.max() < TOL_EQ


@pytest.mark.parametrize("name", CONTROL)
def test_oracle_detects_broken_stationarity(name, solved):
    """Negative controls: one free node moved by 1e-3 (every direction) breaks stationarity
    at that node, not at nodes ≥ 5 away (their windows do not touch it); on constrained
    problems, dropping the multipliers (λ = 0) breaks it everywhere the constraint forces act."""
    mod, r, h, p = solved(name)
    x, j = base_points(r), N_ORACLE // 2
    moved = (x, r.g, r.f)
    for a in range(mod.model.n):
        moved = vary(name, *moved, j, a, 1e-3, h)
    far = [2, 3, 4, j - 5, j + 5, N_ORACLE - 2]
    rel, _ = oracle(name, mod, *moved, r.multipliers, h, [j] + far)
    print(f"\n{name}: perturbed node {rel[0]:.1e}, far nodes ≤ {rel[1:].max():.1e}")
    assert rel[0] > 1e3 * TOL_ORACLE and rel[1:].max() < TOL_ORACLE
    if r.multipliers is not None:
        rel, _ = oracle(name, mod, x, r.g, r.f, np.zeros_like(r.multipliers), h,
                        range(2, N_ORACLE - 1, 5))
        print(f"{name}: zeroed multipliers: min relative gradient {rel.min():.1e}")
        assert rel.min() > 1e3 * TOL_ORACLE


# ---------------------------------------------------------------------------------------
# 2. The discrete controlled equations, controls and cost
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", CONTROL)
def test_controls_constraints_and_cost_satisfy_the_controlled_equations(name, solved):
    """u_w = EL(L)_a and Φ_w = EL(L)_A = 0 at every window's quadrature point, recomputed
    from the returned nodes and fibres (which must be one path: f_k = q_{k+1}, resp.
    ξ_k = τ⁻¹(g_k⁻¹g_{k+1})/h and Γ_{k+1} = τ(hξ_k)ᵀΓ_k); the cost is Σ_w h·C(u_w)."""
    mod, r, h, p = solved(name)
    if kind(name) == "pair":
        np.testing.assert_array_equal(r.f, r.x[1:])
    else:
        W = r.g[:-1].transpose(0, 2, 1) @ r.g[1:]
        xi = np.array([tau_inv(retraction(name), w) for w in W]) / h
        # the solver updates ξ and g separately, each by products of increments: hξ and
        # τ⁻¹(g_k⁻¹g_{k+1}) agree to the rounding of those products (≲ N ulp), divided by h
        print(f"\n{name}: |ξ − τ⁻¹(g_k⁻¹g_(k+1))/h| ≤ {np.abs(xi - r.f[:, :3]).max():.1e}")
        assert np.abs(xi - r.f[:, :3]).max() < 4 * N_ORACLE * U / h
        if kind(name) == "top":
            Gamma = np.einsum("kji,kj->ki", W, r.x[:-1, :3])
            np.testing.assert_allclose(r.x[1:, :3], Gamma, rtol=0, atol=1e-14)
            np.testing.assert_array_equal(r.f[:, 3:], r.x[1:, 3:])
    u_terms, phi_terms, cost = physics(name, p, quadrature_points(name, r, h))
    u = total(u_terms)
    control_error = (np.abs(r.controls - u) / path_scale(1.0, u_terms)).max()
    print(f"\n{name}: controls vs EL(L)_a: max relative difference {control_error:.1e}")
    assert control_error < TOL_EQ
    if phi_terms is not None:
        phi = total(phi_terms)
        residual = (np.abs(phi) / path_scale(1.0, phi_terms)).max()
        print(f"{name}: unactuated EL(L)_A: max relative residual {residual:.1e}")
        assert residual < TOL_EQ
        # the compiled Φ_d is h·Φ at the same quadrature point
        compiled_phi = mod.model.along("constraint", base_points(r), r.f, h)
        assert (np.abs(compiled_phi - h * phi) / path_scale(h, phi_terms)).max() < 1e-12
    reference = math.fsum(h * cost(u))
    print(f"{name}: cost {r.cost:.12g}, relative difference {abs(r.cost / reference - 1):.1e}")
    assert abs(r.cost - reference) <= 1e-12 * reference


# ---------------------------------------------------------------------------------------
# 3. Convergence of the optimal rigid-body cost
# ---------------------------------------------------------------------------------------
def test_rigid_body_optimal_cost_converges_at_order_two_on_its_horizon(compiled):
    """J_N, the optimal discrete cost of the example (R_0 = I, R_N a quarter-turn about
    (1,1,1)/√3, at rest at both ends, T = 1), for N = 50 … 800.

    The rest condition is imposed as g_0 = g_1 and g_{N−1} = g_N: ξ_0 = ξ_{N−1} = 0 pins the
    velocity at t = h/2 and T − h/2, and the windows' quadrature points are the nodes
    t_1 … t_{N−1}, a midpoint rule on [h/2, T − h/2]. So J_N approximates the continuous
    optimum J(T − h) of the shorter horizon, and J(T) only to first order (J_N − J(T) ≈
    −h J'(T), J ∝ T⁻³ for small turns). Measured: order 1 against J(T), order 2 against
    J(T − h). Each J(τ) is the N_REF-step optimum with effective horizon τ, i.e. with
    T_ref = τ N_REF/(N_REF − 1).
    """
    mod, ex = compiled("rigid_body_oc"), get("rigid_body_oc").example
    T, Ns, N_REF = ex.n_steps * ex.h, np.array([50, 100, 200, 400, 800]), 12800

    def optimum(N, horizon):
        r = mod.solve_bvp(ex.start, ex.end, N, horizon / N)
        assert r.success, r.message
        return r.cost

    def continuous(tau_):
        return optimum(N_REF, tau_ * N_REF / (N_REF - 1))

    J = np.array([optimum(N, T) for N in Ns])
    shifted = J - np.array([continuous(T - T / N) for N in Ns])
    fixed = J - continuous(T)
    order_fixed = -np.polyfit(np.log(Ns), np.log(np.abs(fixed)), 1)[0]
    order_shifted = -np.polyfit(np.log(Ns), np.log(np.abs(shifted)), 1)[0]
    print(f"\nJ_N = {J}\nerrors vs J(T): {fixed} (order {order_fixed:.3f})\n"
          f"errors vs J(T − h): {shifted} (order {order_shifted:.3f})")
    assert abs(order_shifted - 2) < 0.2
    assert np.all(np.abs(np.log2(shifted[:-1] / shifted[1:]) - 2) < 0.2)
    assert abs(order_fixed - 1) < 0.2


# ---------------------------------------------------------------------------------------
# 4. Bad input and failures
# ---------------------------------------------------------------------------------------
def test_inconsistent_heavy_top_boundary_data_is_refused(compiled):
    """Γ must follow the attitudes (Γ_{k+1} = (g_k⁻¹g_{k+1})ᵀΓ_k): the end's Γ left at e₃
    while the end attitude is tilted is refused before any Newton step."""
    mod, ex = compiled("heavy_top_rotors_oc"), get("heavy_top_rotors_oc").example
    (xs, gs), (xe, ge) = ex.start, ex.end
    mod.solve_bvp((xs, gs), (xe, ge), 40, 0.05, maxiter=1)    # the example itself is fine
    with pytest.raises(ValueError, match="inconsistent"):
        mod.solve_bvp((xs, gs), (np.c_[np.tile(I3[2], (2, 1)), xe[:, 3:]], ge), 40, 0.05)


def test_newton_out_of_iterations_reports_its_history(compiled):
    """maxiter = 1 on a problem needing more: MAX_ITERATIONS, never success, with the
    residual history; raise_on_failure raises NewtonError carrying that result."""
    mod, ex = compiled("double_pendulum_oc"), get("double_pendulum_oc").example
    r = mod.solve_bvp(ex.start, ex.end, 40, 0.05, maxiter=1)
    assert not r.success and r.status == mod.Status.MAX_ITERATIONS == 1
    assert r.iterations == 1 and r.residual_norms[0] > 0 and "converge" in r.message
    with pytest.raises(mod.NewtonError) as info:
        mod.solve_bvp(ex.start, ex.end, 40, 0.05, maxiter=1, raise_on_failure=True)
    assert info.value.result.status == mod.Status.MAX_ITERATIONS
    np.testing.assert_array_equal(info.value.result.residual_norms, r.residual_norms)


def test_newton_matrix_conditioning_and_its_limit(compiled):
    """The whole-trajectory Newton matrix of a second-order problem is a fourth-difference
    operator: the estimate of 1/κ₁ (LAPACK's dgbcon at these sizes: deterministic, where
    SciPy's randomised ``onenormest`` once measured an order of 3.7) falls like N⁻⁴
    (measured at the chord guess). Past ε its solves are rounding noise — at N = 60 000 for the rigid body — and
    a failed solve there names that cause; an ordinary failure (out of iterations at
    N = 200) does not. By default such N are solved with the lifted system (κ ∝ N²,
    tests/test_lifted.py), which converges at N = 10⁵ (tests/test_false_success.py)."""
    from symvi._runtime.bvp.assembly import Problem as _Problem
    from symvi._runtime.core.paths import initial_path

    mod, ex = compiled("rigid_body_oc"), get("rigid_body_oc").example
    p, rcond = mod.model.params(), {}
    for N in (250, 500, 1000):
        problem = _Problem(mod.model, p, 1.0 / N)
        path = initial_path(mod.model, ex.start, ex.end, N, None, p, 1.0 / N)
        _, ab, bw, _ = problem.assemble(path, True)
        rcond[N] = problem.reciprocal_condition(ab, bw)
    orders = [math.log2(rcond[N] / rcond[2 * N]) for N in (250, 500)]
    print(f"\n1/κ at N = 250, 500, 1000: {list(rcond.values())}; orders {orders}")
    np.testing.assert_allclose(orders, 4.0, atol=0.3)
    ordinary = mod.solve_bvp(ex.start, ex.end, 200, 1.0 / 200, maxiter=1)
    assert not ordinary.success and "working precision" not in ordinary.message
    N, assembly = 60_000, importlib.import_module(f"{mod.__name__}._runtime.bvp.assembly")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(assembly, "LIFT_FROM", 10**9)         # the node formulation
        exhausted = mod.solve_bvp(ex.start, ex.end, N, 1.0 / N, maxiter=2)
    assert exhausted.status == mod.Status.MAX_ITERATIONS
    assert "singular to working precision" in exhausted.message, exhausted.message
    assert "N^4" in exhausted.message


def test_failed_newton_records_the_residual_of_the_returned_path(compiled):
    """BVPResult documents residual_norms as "before each iteration and at the end": after
    k = 1, 2 iterations that end in MAX_ITERATIONS, the last entry (and the message) must be
    the residual of the path returned. Re-solving from that path (an unconstrained problem:
    the guess is the whole state) gives its residual independently."""
    mod, ex = compiled("double_pendulum_oc"), get("double_pendulum_oc").example
    N, h = 40, 0.05
    for k in (1, 2):
        r = mod.solve_bvp(ex.start, ex.end, N, h, maxiter=k)
        again = mod.solve_bvp(ex.start, ex.end, N, h, guess=r.x[2:N - 1], maxiter=1)
        assert r.status == mod.Status.MAX_ITERATIONS
        assert len(r.residual_norms) == r.iterations + 1, (
            f"maxiter={k}: residual_norms {r.residual_norms} lacks the returned path's "
            f"residual {again.residual_norms[0]:.6e}; message: {r.message}")
        assert r.residual_norms[-1] == pytest.approx(again.residual_norms[0], rel=1e-12)


@pytest.mark.parametrize("params", [{"m": 0.0}, {"ell": 0.0}])
def test_singular_cart_pole_is_a_failure_with_a_message(compiled, build_dir, params):
    """Without a pole (m = 0 or ℓ = 0) the constraint EL(L)_θ vanishes identically: its
    multipliers and the pole angle are undetermined, the Jacobian is singular. The
    bundled cart-pole declares m and ℓ positive and refuses those values by name; the
    same problem with real parameters reaches the solver."""
    from symvi import optimal_control
    from symvi.build import compile_model
    from symvi.models import cart_pole_oc as bundled

    ex = get("cart_pole_oc").example
    name = next(iter(params))
    with pytest.raises(ValueError, match=f"parameter {name} is declared positive"):
        compiled("cart_pole_oc").solve_bvp(ex.start, ex.end, 40, 0.05, params=params)
    real = {s: sp.Symbol(str(s), real=True) for s in bundled.PARAMETERS}
    model = optimal_control(
        "cart_pole_unsigned", bundled.G, bundled.LAGRANGIAN.xreplace(real), bundled.u**2 / 2,
        [bundled.u], actuated=[0], parameters={real[s]: v for s, v in bundled.PARAMETERS.items()})
    mod = compile_model(model, build_dir)
    r = mod.solve_bvp(ex.start, ex.end, 40, 0.05, params=params)
    assert not r.success
    assert r.status in (mod.Status.SINGULAR_JACOBIAN, mod.Status.NON_FINITE)
    assert "singular" in r.message or "non-finite" in r.message


@pytest.mark.parametrize("name", ["cart_pole_oc", "heavy_top_rotors_oc"])
def test_step_map_is_refused_on_constrained_models(compiled, name):
    with pytest.raises(ValueError, match="solve_bvp"):
        compiled(name).integrate(np.zeros((4, 2)), 10, 0.05)


@pytest.mark.parametrize("name", ["rigid_body_oc", "rigid_body_oc_exp"])
def test_half_turn_between_the_fixed_ends_is_outside_the_chart(compiled, name):
    """A half-turn g_1⁻¹g_{N−1} has no τ⁻¹ (Cayley: I + W singular; exp: angle π), so the
    default chord guess cannot be built."""
    mod, half_turn = compiled(name), np.diag([1.0, -1.0, -1.0])
    r = mod.solve_bvp([I3] * 2, [half_turn] * 2, 40, 1 / 40)
    assert r.status == mod.Status.OUTSIDE_CHART and not r.success
    assert "chart" in r.message


@pytest.mark.parametrize("change, pattern", [
    (dict(actuated=[2]), r"actuated directions .* 0\.\.1.*\[2\]"),
    (dict(actuated=[0, 0], controls="u v"), r"distinct indices"),
    (dict(controls="u v"), r"2 control symbols for 1 actuated"),
    (dict(cost="v**2/2"), r"does not depend on the controls"),
    (dict(cost="u**2/2 + rho*v**2"), r"undeclared symbol.*rho.*cost"),
])
def test_optimal_control_declaration_errors(change, pattern):
    """A cart-like system (x, θ) with the force on x: each bad declaration is a ModelError
    naming the problem; the good one builds."""
    G = PairGroupoid("x theta")
    (_, th), (v, w) = G.q, G.qdot
    u, L = sp.Symbol("u", real=True), v**2 / 2 + w**2 / 2 + sp.cos(th)
    args = dict(cost=u**2 / 2, controls=[u], actuated=[0])
    optimal_control("good", G, L, **args)
    args.update(change)
    if isinstance(args["cost"], str):
        args["cost"] = sp.sympify(args["cost"], locals=dict(u=u, v=v, rho=sp.Symbol("rho")))
    with pytest.raises(ModelError, match=pattern):
        optimal_control("bad", G, L, **args)
