"""End conditions of optimal control (issue 21): a free end, or ψ(q, y) = 0 on the last
element, with the last nodes as unknowns (``optimal_control(..., end=...)``).

- A rigid-body spin-up on SO(3) to the rate Ω = (1, 0, 0), attitude free: the discrete
  optimum is exact — ξ ramps linearly over the N − 1 free increments, J_d = N/(2(N−1)T)
  — and with a free horizon (cost J + ρT) the optimal T = √(N/(2ρ(N−1))), which needs
  the end conditions' share ν·∂ψ/∂h of dJ*/dT.
- A cart-pole catching its pole, tilted 0.3 rad at rest, upright and at rest at T = 2
  with the cart's position free: the same optimum as SLSQP on the same discrete problem
  written again in NumPy (free nodes q₂ … q_N, the windows' Φ and ψ as equalities), also
  with a force limit active (the bundled ``cart_pole_catch``).
- A free end is the natural boundary condition: from a hanging pole, the optimum is the
  unforced motion, every discrete control zero.
"""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from symvi import SO3, Example, ModelError, Symmetry, optimal_control
from symvi.build import compile_model
from symvi.models.cart_pole_oc import G as CART_POLE, LAGRANGIAN, PARAMETERS
from symvi.models.rigid_body_oc import slew
from test_independent_optimum import CartPole, cs_derivative

T, TILTED = 2.0, np.array([[0.0, 0.3], [0.0, 0.3]])
(X, TH), (V, W) = CART_POLE.q, CART_POLE.qdot
U = sp.Symbol("u", real=True)
CAUGHT = {"upright": TH, "pole at rest": W, "cart at rest": V}


def cart_pole(name: str, end, **options):
    return optimal_control(name=name, groupoid=CART_POLE, lagrangian=LAGRANGIAN,
                           cost=U**2 / 2, controls=[U], actuated=[0],
                           parameters=PARAMETERS | options.pop("parameters", {}), end=end,
                           example=Example(h=T / 60, n_steps=60, start=TILTED, end=None),
                           **options)


@pytest.fixture(scope="module")
def models(build_dir, compiled):
    Omega = sp.Matrix(SO3().xi)
    rate = {"w1": Omega[0] - 1, "w2": Omega[1], "w3": Omega[2]}
    return {
        "spin": compile_model(slew("spin_up", "cayley", "spin-up", steps=20, end=rate),
                              build_dir),
        "spin_timed": compile_model(slew("spin_up_timed", "cayley", "spin-up, free T",
                                         steps=20, end=rate, time_cost=0.5), build_dir),
        "caught": compile_model(cart_pole("cart_pole_caught", CAUGHT), build_dir),
        "limited": compiled("cart_pole_catch"),     # the same, |u| ≤ u_max (bundled)
        "free": compile_model(cart_pole("cart_pole_free_end", "free"), build_dir),
    }


@pytest.mark.parametrize("N", [20, 100])
def test_spin_up_with_the_attitude_free_is_the_exact_discrete_ramp(models, N):
    r = models["spin"].solve_bvp([np.eye(3)] * 2, None, N, 1.0 / N)
    ramp = np.arange(N) / (N - 1)
    np.testing.assert_allclose(r.f[:, 0], ramp, rtol=0, atol=1e-12)
    np.testing.assert_allclose(r.f[:, 1:], 0.0, rtol=0, atol=1e-12)
    assert abs(r.cost - N / (2 * (N - 1))) <= 1e-12
    # ν is the costate of the end: minus the final torque, here constant
    np.testing.assert_allclose(r.end_multipliers, [-N / (N - 1), 0, 0], atol=1e-9)


@pytest.mark.parametrize("N", [20, 100])
def test_a_free_horizon_with_end_conditions_finds_the_exact_optimal_time(models, N):
    rho = 0.5
    r = models["spin_timed"].solve_bvp([np.eye(3)] * 2, None, N, 1.3 / N)
    exact = np.sqrt(N / (2 * rho * (N - 1)))
    assert r.success and abs(r.T - exact) <= 1e-9 * exact, (r.T, exact, r.message)


class Caught(CartPole):
    """The cart-pole of test_independent_optimum with its last nodes free: unknowns
    q₂ … q_N; equalities h·Φ per window and ψ on the last element by the midpoint rule
    (θ̄ = (θ_{N−1} + θ_N)/2, θ̇ and ẋ as differences over h)."""

    def __init__(self, N, u_max=None):
        self.p = {str(s): v for s, v in PARAMETERS.items()}
        self.h, self.N, self.start, self.u_max = T / N, N, TILTED, u_max

    def nodes(self, z):
        inner = z.reshape(z.shape[:-1] + (self.N - 1, 2))
        return np.concatenate([np.broadcast_to(self.start, z.shape[:-1] + (2, 2)), inner], -2)

    def from_symvi(self, r):
        np.testing.assert_array_equal(r.x[:2], self.start)
        return r.x[2:].reshape(-1)

    def psi(self, z):
        a, b = self.nodes(z)[..., -2, :], self.nodes(z)[..., -1, :]
        return np.stack([(a[..., 1] + b[..., 1]) / 2, (b[..., 1] - a[..., 1]) / self.h,
                         (b[..., 0] - a[..., 0]) / self.h], -1)

    def constraints(self, z):
        phi = self.h * self.phi(z)
        return np.concatenate([phi.reshape(phi.shape[:-2] + (-1,)), self.psi(z)], -1)

    def limits(self, z):
        u = self.controls(z)[..., 0]
        return np.concatenate([self.u_max - u, self.u_max + u], -1)


def slsqp(prob, z0):
    """SLSQP in the variables z = z₀ + P y, P = H^{-1/2} of the Gauss–Newton Hessian at z₀
    (as test_independent_optimum.direct_minimum: the cost's conditioning ~N⁴ stalls
    SLSQP otherwise), with the force limits as inequalities; returns the minimiser z."""
    from scipy.optimize import minimize

    Ju = cs_derivative(lambda z: prob.controls(z).reshape(z.shape[:-1] + (-1,)), z0)
    Jc = cs_derivative(prob.constraints, z0)
    lam, V = np.linalg.eigh(prob.h * Ju.T @ Ju + Jc.T @ Jc / prob.h)
    P = V / np.sqrt(np.maximum(lam, 1e-10 * lam.max()))
    J0 = prob.cost(z0)

    def wrap(fun):
        return dict(fun=lambda y: fun(z0 + y @ P.T),
                    jac=lambda y: cs_derivative(lambda v: fun(z0 + v @ P.T), y))
    cons = [dict(type="eq", **wrap(prob.constraints))]
    if prob.u_max is not None:
        cons.append(dict(type="ineq", **wrap(prob.limits)))
    cost = wrap(lambda v: prob.cost(v) / J0)
    res = minimize(cost["fun"], np.zeros(z0.size), jac=cost["jac"], method="SLSQP",
                   constraints=cons, options=dict(ftol=1e-14, maxiter=500))
    return res, z0 + res.x @ P.T


@pytest.mark.parametrize("which, u_max", [("caught", None), ("limited", 5.0)])
def test_catching_the_pole_is_the_optimum_of_an_independent_direct_minimisation(
        models, which, u_max):
    N = 40
    prob = Caught(N, u_max)
    params = {} if u_max is None else {"u_max": u_max}
    r = models[which].solve_bvp(TILTED, None, N, prob.h, params=params)
    z = prob.from_symvi(r)
    assert abs(prob.cost(z) - r.cost) <= 1e-12 * r.cost
    assert np.abs(prob.constraints(z)).max() <= 1e-9
    if u_max is not None:
        assert prob.limits(z).min() >= -1e-9 and r.active.any()     # the limit is reached
    # a warm start from the result (its last nodes, λ, z and ν) ends where it began
    again = models[which].solve_bvp(TILTED, None, N, prob.h, params=params, guess=r)
    assert again.success and again.iterations <= 2 and abs(again.cost - r.cost) <= 1e-10 * r.cost
    res, z_opt = slsqp(prob, z + 0.02 * np.sin(np.arange(z.size)))
    assert res.success, res.message
    assert np.abs(prob.constraints(z_opt)).max() <= 1e-8
    print(f"\n{which}: symvi J = {r.cost:.12g}, SLSQP J = {prob.cost(z_opt):.12g}")
    assert abs(prob.cost(z_opt) - r.cost) <= 1e-8 * r.cost


@pytest.mark.parametrize("N", [60, 200])
def test_a_free_end_gives_the_unforced_motion(models, N):
    """Natural boundary conditions: nothing pins the end, so the optimum costs nothing —
    the pole, hanging 0.3 rad off the vertical, swings freely and the cart follows."""
    hanging = np.array([[0.0, np.pi - 0.3]] * 2)
    r = models["free"].solve_bvp(hanging, None, N, T / N)
    assert r.success, r.message
    assert np.abs(r.controls).max() <= 1e-9 and r.cost <= 1e-18
    assert np.abs(r.x[:, 1] - r.x[0, 1]).max() > 0.1       # it did swing


def test_end_conditions_refused_at_declaration():
    with pytest.raises(ModelError, match="end must be 'fixed', 'free' or the end conditions"):
        cart_pole("bad_end", "sideways")
    with pytest.raises(ModelError, match=r"uses \['u'\] \(controls are not part of the state\)"):
        cart_pole("control_in_psi", {"pushed": U})
    with pytest.raises(ModelError, match="5 end conditions ψ = 0 for a state of 4"):
        cart_pole("too_many", [X, TH, V, W, X - TH])
    G = SO3()
    Omega = sp.Matrix(G.xi)
    with pytest.raises(ModelError, match="declared symmetries fix the multipliers"):
        optimal_control(name="gauged_free", groupoid=G,
                        lagrangian=(Omega.T * Omega)[0] / 2, cost=sp.Symbol("a") ** 2,
                        controls=[sp.Symbol("a")], actuated=[0], equations="variational",
                        symmetries=[Symmetry("z", [0, 0, 1])], end="free")


@pytest.mark.parametrize("which, start", [("spin", [np.eye(3)] * 2), ("caught", TILTED)])
def test_the_newton_matrix_of_the_unknown_end_is_the_residuals_derivative(models, which, start):
    """The band the C assembles — the partial stencils of the last nodes, ν's columns, ψ's
    rows — against central differences of the residual along every unknown (nodes moved
    by the retraction, multipliers and ν shifted), at a path off the optimum; pinned
    unknowns (identity rows) aside."""
    from test_bvp_merit import dense_jacobian, runtime_of

    module = models[which]
    model, N = module.model, 8
    p, h = model.params(), 1.0 / N
    problem = runtime_of(module, "bvp.assembly").Problem(model, p, h)
    path = runtime_of(module, "core.paths").initial_path(model, start, None, N, None, p, h)
    size = int(model.lib.symvi_bvp_unknowns(N + 1))
    rng = np.random.default_rng(3)
    path = problem.moved(path, 0.1 * rng.standard_normal(size), 1.0)   # off the optimum
    path.lam[:] = rng.standard_normal(path.lam.shape)
    path.nu[:] = rng.standard_normal(path.nu.shape)
    res, ab, bw, finite = problem.assemble(path, True)
    J = dense_jacobian(ab, bw)
    delta = 1e-6
    for i in range(size):
        e = np.zeros(size)
        e[i] = delta
        plus = problem.assemble(problem.moved(path, e, 1.0), False)[0]
        minus = problem.assemble(problem.moved(path, -e, 1.0), False)[0]
        column = (plus - minus) / (2 * delta)
        if not column.any() and np.array_equal(J[:, i], np.eye(size)[i]):
            continue    # a pinned unknown (a fixed node's, a missing window's λ): η = 0
        assert np.abs(column - J[:, i]).max() <= 1e-6 * (1 + np.abs(J[:, i]).max()), i


def test_end_conditions_that_cannot_determine_the_end_are_named(build_dir):
    """Redundant end conditions make their rows dependent; a ψ without gradient at the
    first guess (|Ω|² − 1 at rest) leaves the linearised conditions unsolvable. Neither is
    a SUCCESS; each is named, with the remedy — and with a guess of the end that gives
    ψ a gradient the second is solved."""
    from test_independent_optimum import cay, hat

    Omega = sp.Matrix(SO3().xi)
    twice = compile_model(slew("spin_twice", "cayley", "", steps=20,
                               end={"a": Omega[0] - 1, "b": 2 * Omega[0] - 2}), build_dir)
    r = twice.solve_bvp([np.eye(3)] * 2, None, 20, 0.05)
    assert not r.success and "end conditions 'a', 'b' are dependent" in r.message, r.message
    speed = compile_model(slew("spin_speed", "cayley", "", steps=20, end={
        "speed": Omega[0] ** 2 + Omega[1] ** 2 - 1, "w3": Omega[2]}), build_dir)
    r = speed.solve_bvp([np.eye(3)] * 2, None, 20, 0.05)
    # only 'speed' lacks a gradient: 'w3' is not named
    assert not r.success and "end conditions 'speed' cannot be met to first order" \
        in r.message, r.message
    guess = [np.eye(3), cay(hat(0.05 * np.array([0.8, 0.0, 0.0])))]
    r = speed.solve_bvp([np.eye(3)] * 2, guess, 20, 0.05)
    assert r.success, r.message
    assert abs(r.f[-1, 0] ** 2 + r.f[-1, 1] ** 2 - 1) <= 1e-10 and abs(r.f[-1, 2]) <= 1e-10


def test_a_failed_result_is_a_guess_of_nodes_only(models):
    """A false success found by a hunt (issue 50), pinned: a solve warm-started from an
    INFEASIBLE result (the catch at u_max = 3, its multipliers λ near 1e9) inherited
    those multipliers, the tolerance xtol·(1 + size) grew with them to 1.8, and the
    interior point's most accurate iterate, finished, was a SUCCESS with the pole
    equation violated by |h·Φ| = 4.7e-7 and a cost 3.6e-5 above the optimum. A result
    that failed now gives its nodes only: the solve is the cold one's, to rounding."""
    limited, N = models["limited"], 40
    h = T / N
    failed = limited.solve_bvp(TILTED, None, N, h, params=dict(u_max=3.0))
    assert failed.status.name == "INFEASIBLE", failed.message
    warm = limited.solve_bvp(TILTED, None, N, h, params=dict(u_max=100.0), guess=failed)
    cold = limited.solve_bvp(TILTED, None, N, h, params=dict(u_max=100.0))
    assert warm.success and cold.success, (warm.message, cold.message)
    prob = Caught(N, 100.0)
    z = prob.from_symvi(warm)
    assert np.abs(prob.h * prob.phi(z)).max() <= 1e-12
    assert abs(warm.cost - cold.cost) <= 1e-10 * cold.cost
    assert np.abs(warm.x - cold.x).max() <= 1e-10
