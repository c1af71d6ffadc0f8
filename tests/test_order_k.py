"""Lagrangians of order k > 2 (issue 25, part 2): exact discrete solutions, the banded
whole-trajectory solve, its honesty about conditioning, and bad input.

Minimum jerk (k = 3) and minimum snap (k = 4) on the pair groupoid: L = ½|q⁽ᵏ⁾|², whose
Euler–Lagrange equation is q⁽²ᵏ⁾ = 0. The rule ``central<k>`` takes q⁽ᵏ⁾ on a window of
k + 1 nodes as their k-th difference over hᵏ, so the discrete equation at a node is the
2k-th difference of the nodes = 0: samples of any polynomial of degree 2k − 1 are exact
discrete solutions, for the step map and for the whole-trajectory solve.

On SO(3) and SE(3), L = ½ ξ⁽ᵏ⁻¹⁾ᵀ I ξ⁽ᵏ⁻¹⁾: the gradient of the action sum in each
increment ξ_j is a (2k − 2)-th difference of the increments, which vanishes when they
sample a polynomial of degree 2k − 3 — so those increments solve the discrete
Euler–Poincaré equations exactly, whatever the group's trivialisation terms.

The variational oracle (tests/test_oracle.py, tests/test_lie_groups.py) and the
consistency check (tests/test_checks_order_k.py) cover the same models.
"""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from symvi import SO3, ActionGroupoid, Model, ModelError, PairGroupoid, ProductGroupoid, h
from symvi.models import get

EXACT = 1e-10


def _polynomial(coefficients: np.ndarray):
    """t ↦ the rows of np.polyval of each column of ``coefficients``."""
    return lambda t: np.stack([np.polyval(c, t) for c in coefficients.T], axis=1)


@pytest.mark.parametrize("name", ["minimum_jerk", "minimum_snap"])
def test_polynomials_of_degree_2k_minus_1_are_exact(name, compiled):
    model, mod = get(name), compiled(name)
    k = model.order
    q = _polynomial(np.random.default_rng(k).standard_normal((2 * k, 3)))
    # the step map from the first 2k nodes; its rounding grows like n^(2k−1), so a short run
    n, step = 12, 1 / 12
    t = np.arange(n + 1) * step
    run = mod.integrate(q(t[:2 * k]), n, step)
    assert run.success, run.message
    assert np.abs(run.x - q(t)).max() <= EXACT * np.abs(q(t)).max()
    # the whole-trajectory solve between the first and last k nodes, from a poor start
    n, step = 40, 1 / 40
    t = np.arange(n + 1) * step
    solve = mod.solve_bvp(q(t[:k]), q(t[-k:]), n, step)
    assert solve.success, solve.message
    assert np.abs(solve.x - q(t)).max() <= EXACT * np.abs(q(t)).max()
    # and the path is not a polynomial of lower degree: the top coefficient matters
    assert np.abs(np.diff(q(t), 2 * k - 1, axis=0)).max() > 1e-9


@pytest.mark.parametrize("name", ["so3_jerk", "se3_snap"])
def test_polynomial_increments_are_exact_on_the_group(name, compiled):
    model, mod = get(name), compiled(name)
    k, dim = model.order, model.groupoid.fibre_dim
    xi = _polynomial(0.4 * np.random.default_rng(k).standard_normal((2 * k - 2, dim)))
    n, step = 16, 1 / 16
    middles = (np.arange(n) + 0.5) * step
    g0 = np.eye(model.groupoid.matrix_dim)
    run = mod.integrate((g0, xi(middles[:2 * k - 1])), n, step)
    assert run.success, run.message
    assert np.abs(run.f - xi(middles)).max() <= EXACT * np.abs(xi(middles)).max()
    # the solve between the first and last k configurations finds the same increments
    solve = mod.solve_bvp(run.g[:k], run.g[-k:], n, step)
    assert solve.success, solve.message
    assert np.abs(solve.f - xi(middles)).max() <= EXACT * np.abs(xi(middles)).max()
    assert np.ptp(run.f, axis=0).max() > 0.1       # the increments do vary


def _initial_data(model, k: int, seed: int):
    """The first 2k nodes (pair groupoid) or g₀ and the first 2k − 1 increments."""
    rng, dim = np.random.default_rng(seed), model.groupoid.fibre_dim
    if isinstance(model.groupoid, PairGroupoid):
        return 0.1 * rng.standard_normal((2 * k, dim))
    return np.eye(model.groupoid.matrix_dim), 0.1 * rng.standard_normal((2 * k - 1, dim))


@pytest.mark.parametrize("name", ["cubic_spline", "minimum_jerk", "minimum_snap", "so3_jerk",
                                  "se3_snap"])
def test_short_runs_keep_the_states_their_path_determines(name, compiled):
    """Issue 48: every n_steps ≥ 2k − 1 integrates. State j < k takes its momenta from
    F⁻L_d on the 2k − 1 elements after it, so a path of fewer than 3k − 2 elements
    determines only its first n − 2k + 2 states: those are returned (equal to a longer
    run's), never states read past the path's end — a run failing at its first step too,
    and the batch loop trajectory by trajectory."""
    model, mod = get(name), compiled(name)
    k = model.order
    for n in range(2 * k - 1, 3 * k):
        data = [_initial_data(model, k, seed) for seed in (n, n + 100)]
        runs = [mod.integrate(d, n, 0.1) for d in data]
        longer = mod.integrate(data[0], 3 * k + 2, 0.1)
        assert all(run.success for run in runs + [longer]), runs[0].message
        states = n - k + 2 if n >= 3 * k - 2 else n - 2 * k + 2
        assert runs[0].momenta.shape[0] == states, (n, runs[0].momenta.shape)
        np.testing.assert_allclose(runs[0].momenta, longer.momenta[:states], rtol=1e-12,
                                   atol=1e-12)
        if isinstance(model.groupoid, PairGroupoid):
            batch = mod.integrate_many(np.stack(data), n, 0.1)
            for b, run in enumerate(runs):
                assert np.array_equal(batch[b].momenta, run.momenta), (n, b)
    failed = mod.integrate(_initial_data(model, k, 0), 20, 0.1, maxiter=1, xtol=0.0)
    assert not failed.success and failed.momenta.shape[0] == 1, failed.message


def test_band_grows_with_the_order_not_with_n(compiled):
    """The whole-trajectory Newton matrix of an order-k model couples nodes within k of
    each other: n(k + 1) − 1 diagonals on either side, whatever N."""
    for name in ("cubic_spline", "minimum_jerk", "minimum_snap", "so3_jerk", "se3_snap"):
        model, lib = get(name), compiled(name).model.lib
        n, k = model.groupoid.fibre_dim, model.order
        assert lib.symvi_bvp_bandwidth() == n * (k + 1) - 1, name
        assert lib.symvi_bvp_unknowns(1000) - lib.symvi_bvp_unknowns(100) == 900 * n


def test_conditioning_is_reported_not_hidden(compiled):
    """κ grows like N^{2k}: minimum jerk at N = 1000 still converges to the exact quintic,
    minimum snap at N = 1000 (κ ≈ 10²⁴) cannot reach xtol and says so — never SUCCESS with
    a wrong path."""
    for name, expect_success in (("minimum_jerk", True), ("minimum_snap", False)):
        model, mod = get(name), compiled(name)
        k = model.order
        q = _polynomial(np.random.default_rng(1).standard_normal((2 * k, 3)))
        n = 1000
        t = np.arange(n + 1) / n
        solve = mod.solve_bvp(q(t[:k]), q(t[-k:]), n, 1 / n)
        error = np.abs(solve.x - q(t)).max()
        if solve.success:
            assert error <= 1e-8 * np.abs(q(t)).max(), (name, error, solve.message)
        assert solve.success == expect_success, (name, solve.message)
        if not expect_success:
            assert "conditioning" in solve.message or "rounding" in solve.message


def test_slowly_converging_newton_is_not_a_success(compiled):
    """Minimum jerk from rest at 0 to rest at 1 over N = 2500, h = 3: its Newton matrix is
    so ill-conditioned that the corrections shrink only by ρ ≈ 0.9 per iteration, leaving
    an error ρ/(1 − ρ) times the last one. The path must not be SUCCESS unless the exact
    discrete solution — the quintic in the node index through the six fixed nodes — is
    within the tolerance (it was once, 8.7 tolerances off)."""
    mod, n = compiled("minimum_jerk"), 2500
    res = mod.solve_bvp(np.zeros((3, 3)), np.ones((3, 3)), n, 3.0)
    fixed = np.r_[0:3, n - 2:n + 1] / n
    quintic = np.linalg.solve(np.vander(fixed, 6), np.r_[0.0, 0, 0, 1, 1, 1])
    exact = np.polyval(quintic, np.arange(n + 1) / n)
    error = np.abs(res.x - exact[:, None]).max()
    tolerance = 1e-9 * (1 + np.abs(exact).max())
    assert not res.success or error <= tolerance, (error / tolerance, res.message)
    if not res.success:     # and the message says why
        assert "did not converge" in res.message or "rounding" in res.message


# -- declarations ---------------------------------------------------------------------------
def test_order_and_rule_follow_the_highest_derivative():
    G = PairGroupoid("x y")
    x3, y3 = G.derivative(3)
    assert (str(x3), str(y3)) == ("x_dddot", "y_dddot") and G.derivative(2) == G.qddot
    m = Model("jerk_decl", G, lagrangian=(x3**2 + y3**2) / 2 + G.q[0]**2)
    assert (m.order, m.discretisation) == (3, "central3")
    S = SO3()
    m = Model("so3_snap_decl", S, lagrangian=sum(v**2 for v in S.derivative(3)) / 2)
    assert (m.order, m.discretisation) == (4, "lie_central4")


def test_central_rule_samples_the_interpolant_at_the_centre():
    """central3 on nodes of a cubic gives its exact value and derivatives at t = 3h/2."""
    G = PairGroupoid("x")
    m = Model("jerk_rule", G, lagrangian=G.derivative(3)[0]**2 / 2 + G.q[0] * G.qdot[0]
              + G.qddot[0] ** 2)
    from symvi.discretisation.rules import central
    t = sp.Symbol("t")
    cubic = 2 - t + 3 * t**2 - 5 * t**3
    nodes = [(cubic.subs(t, j * h),) for j in range(4)]
    (weight, point), = central(3).quadrature(G, [nodes[0]], nodes[1:], h)
    centre = 3 * h / 2
    for j in range(4):
        expected = sp.diff(cubic, t, j).subs(t, centre)
        assert sp.simplify(point[G.derivative(j)[0]] - expected) == 0, j
    assert weight == 1 and m.order == 3


@pytest.mark.parametrize("build, pattern", [
    # degenerate in the top derivative: y''' missing from L
    (lambda G: Model("bad_jerk", G, lagrangian=G.derivative(3)[0]**2 / 2 + G.qdot[1]**2),
     r"not regular.*rank 1 < 2.*D₁₄L_d"),
    # the Lagrangian's order against the rule's
    (lambda G: Model("bad_rule", G, lagrangian=G.derivative(3)[0]**2 + G.derivative(3)[1]**2,
                     discretisation="three_point"),
     r"depends on \['x_dddot', 'y_dddot'\] \(order 3\) but the discretisation 'three_point' is "
     r"second order; use 'central3'"),
    (lambda G: Model("bad_rule", G, lagrangian=G.derivative(3)[0]**2 + G.derivative(3)[1]**2,
                     order=4),
     r"order=4 contradicts discretisation 'central3' \(order 3\)"),
    # a discrete Lagrangian whose nodes do not match its order
    (lambda G: Model("bad_nodes", G, discrete_lagrangian=sum(
        (a - 3 * b + 3 * c - d)**2 for (a, _), (b, _), (c, _), (d, _) in [G.nodes(4)]),
        order=2), r"undeclared symbol\(s\) x_3"),
    (lambda G: Model("bad_order", G, discrete_lagrangian=G.nodes(2)[0][0], order=7),
     r"needs an integer order from 1 to 6"),
    (lambda G: Model("bad_order", G, lagrangian=G.derivative(7)[0]**2),
     r"derivative\(7\): the derivatives of a Lagrangian's symbols go from 0 to 6"),
    (lambda G: G.derivative(-1), r"derivative\(-1\)"),
    # a product whose factors' derivative names meet: the pair's w⃛ is the group's ξ₁
    (lambda G: ProductGroupoid(PairGroupoid("w"), SO3(names="w_dddot b c")),
     r"share coordinate names \['w_dddot'\]"),
])
def test_bad_order_k_input_is_refused_with_its_reason(build, pattern):
    with pytest.raises(ModelError, match=pattern):
        build(PairGroupoid("x y"))


def test_action_groupoids_stay_at_order_two():
    H = SO3()
    G = ActionGroupoid(H, "a1 a2 a3", lambda q, W: list(W[:3, :3].T * q),
                       manifold=lambda q: [q.dot(q) - 1])
    jerk = sum(v**2 for v in H.derivative(2))
    with pytest.raises(ModelError, match=r"order 3.*takes orders up to 2"):
        Model("action_jerk", G, lagrangian=jerk)
