"""A run started from a state (q₀, v₀) (issue 22, item 1): the first element from the
discrete Legendre transform F⁻L_d(x₀, f₀) = ∂L/∂v (``_runtime/step/legendre.py``).

Checked against SciPy's DOP853 (rtol = atol = 1e-13) on the continuous equations, written
here independently of symvi — Lagrange's equations of the pair-groupoid models derived
with SymPy, Euler's and Poisson's equations for the rigid body and the heavy top: the
error at T = 2 falls at order 2 in h (slope within 0.1), and the node form given the
transform's nodes reproduces the path bit for bit.
"""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp

from symvi.models import get

T, STEPS = 2.0, (100, 200, 400, 800)


def hat(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def lagrange_rhs(name):
    """q̈ = M(q)⁻¹(∂L/∂q − (∂²L/∂q̇∂q) q̇) of a bundled pair-groupoid model, lambdified."""
    model = get(name)
    q, v = model.groupoid.q, model.groupoid.qdot
    L = model.lagrangian.xreplace(dict(model.parameters))
    p = sp.Matrix([sp.diff(L, s) for s in v])
    M, rhs = p.jacobian(v), sp.Matrix([sp.diff(L, s) for s in q]) - p.jacobian(q) * sp.Matrix(v)
    accel = sp.lambdify([*q, *v], M.LUsolve(rhs), "numpy")
    n = len(q)
    return lambda t, y: np.concatenate([y[n:], np.ravel(accel(*y))])


def reference(rhs, y0):
    return solve_ivp(rhs, (0.0, T), y0, method="DOP853", rtol=1e-13, atol=1e-13).y[:, -1]


def order(errors):
    slopes = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    print(f"\nerrors at T = {T}: {np.array(errors)}; slopes {slopes}")
    return slopes


@pytest.mark.parametrize("name, q0, v0", [
    ("pendulum", [1.0], [0.5]),
    ("double_pendulum", [0.5, -0.3], [0.2, 0.7]),
])
def test_pair_groupoid_state_converges_at_order_two(compiled, name, q0, v0):
    module = compiled(name)
    exact = reference(lagrange_rhs(name), np.array(q0 + v0))[:len(q0)]
    model = get(name)
    L = model.lagrangian.xreplace(dict(model.parameters))
    state = dict(zip(model.groupoid.q + model.groupoid.qdot, q0 + v0))
    p0 = np.array([float(sp.diff(L, s).xreplace(state)) for s in model.groupoid.qdot])
    errors = []
    for N in STEPS:
        r = module.integrate(module.State(x=q0, v=v0), N, T / N)
        assert r.success and len(r.t) == N + 1 and r.t[-1] == pytest.approx(T, abs=1e-12)
        errors.append(np.abs(r.x[-1] - exact).max())
        np.testing.assert_allclose(r.momenta[0], p0, rtol=1e-13, atol=1e-13)  # matched
        again = module.integrate(r.x[:2], N, T / N)
        np.testing.assert_array_equal(again.x, r.x)
    assert np.all(np.abs(order(errors) - 2.0) <= 0.1)


def test_rigid_body_state_converges_at_order_two(compiled):
    module, I = compiled("rigid_body"), np.array([1.0, 2.0, 3.0])
    W0 = np.array([0.3, 1.0, -0.4])

    def rhs(t, y):
        R, W = y[:9].reshape(3, 3), y[9:]
        return np.concatenate([(R @ hat(W)).ravel(), np.cross(I * W, W) / I])
    exact = reference(rhs, np.concatenate([np.eye(3).ravel(), W0]))[:9].reshape(3, 3)
    errors = []
    for N in STEPS:
        r = module.integrate(module.State(v=W0), N, T / N)
        assert r.success and len(r.t) == N + 1
        errors.append(np.abs(r.g[-1] - exact).max())
        again = module.integrate((np.eye(3), r.f[:1]), N, T / N)
        np.testing.assert_array_equal(again.g, r.g)
    assert np.all(np.abs(order(errors) - 2.0) <= 0.1)


def test_heavy_top_state_converges_at_order_two(compiled):
    """Γ̇ = Γ × Ω, IΩ̇ = IΩ × Ω + mgl Γ × χ (from l = ½ΩᵀIΩ − mgl χ·Γ)."""
    module, I = compiled("heavy_top"), np.array([1.0, 2.0, 3.0])
    chi, mgl = np.array([0.6, 0.0, 0.8]), 1.0
    G0, W0 = np.array([0.0, 0.6, 0.8]), np.array([0.5, 0.3, 2.0])

    def rhs(t, y):
        G, W = y[:3], y[3:]
        return np.concatenate([np.cross(G, W), (np.cross(I * W, W) + mgl * np.cross(G, chi)) / I])
    exact = reference(rhs, np.concatenate([G0, W0]))[:3]
    errors = []
    for N in STEPS:
        r = module.integrate(module.State(x=G0, v=W0), N, T / N)
        assert r.success and len(r.t) == N + 1
        errors.append(np.abs(r.x[-1] - exact).max())
        again = module.integrate((G0, r.f[:1]), N, T / N)
        np.testing.assert_array_equal(again.x, r.x)
    assert np.all(np.abs(order(errors) - 2.0) <= 0.1)


def test_a_state_off_its_manifold_or_of_a_second_order_model_is_refused(compiled):
    top = compiled("heavy_top")
    with pytest.raises(ValueError, match="the state's position x"):
        top.integrate(top.State(x=[0.0, 0.6, 0.9], v=[0.5, 0.3, 2.0]), 10, 0.01)
    with pytest.raises(ValueError, match="the state's velocity v"):
        top.integrate(top.State(x=[0.0, 0.6, 0.8], v=[0.5, 0.3]), 10, 0.01)
    spline = compiled("cubic_spline")
    with pytest.raises(ValueError, match="a State starts first-order models only"):
        spline.integrate(spline.State(x=[0.0], v=[1.0]), 10, 0.01)


def test_a_product_with_an_action_factor_starts_from_a_state(compiled, build_dir):
    """The heavy top (action groupoid S²×SO(3)) times the pendulum (pair groupoid), their
    Lagrangians summed, started from one State: its path is the two factors' paths from
    their own States — each checked against DOP853 at order 2 above — to rounding."""
    from symvi import Model, ProductGroupoid, State, compile_model
    top, pendulum = get("heavy_top"), get("pendulum")
    both = compile_model(Model("top_and_pendulum", ProductGroupoid(top.groupoid,
                                                                   pendulum.groupoid),
                               lagrangian=top.lagrangian + pendulum.lagrangian,
                               parameters=dict(top.parameters) | dict(pendulum.parameters)),
                         build_dir)
    h, n = 0.01, 200
    path = both.integrate(State(x=[0.0, 0.6, 0.8, 0.3], v=[0.5, 0.3, 2.0, 0.1]), n, h)
    alone = compiled("heavy_top").integrate(State(x=[0.0, 0.6, 0.8], v=[0.5, 0.3, 2.0]), n, h)
    swing = compiled("pendulum").integrate(State(x=[0.3], v=[0.1]), n, h)
    assert np.abs(path.x[:, :3] - alone.x).max() <= 1e-13
    assert np.abs(path.g - alone.g).max() <= 1e-13
    assert np.abs(path.x[:, 3:] - swing.x).max() <= 1e-13
