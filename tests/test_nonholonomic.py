"""Nonholonomic optimal control on D⁽²⁾ (issue 25, part 1).

The unicycle's parallel parking is checked against everything that does not come from
symvi's derivation:

* its controlled Lagrange–d'Alembert equations, against the textbook ones (and the
  Chaplygin sled's and the rolling coin's);
* the discrete kinematic constraints (q₁ − q₀)/h = ρ(q̄)ȳ, re-evaluated in NumPy on the
  solution: they hold to 1e-12;
* the optimum of the same discrete problem found by SciPy's SLSQP from the same start at
  small N, written here by hand (cost Σ h L̃(midpoint), constraints h Φ(midpoint));
* the continuous optimum: Pontryagin's conditions for the unicycle, solved by
  scipy.integrate.solve_bvp; the discrete optimal cost converges to it at order 2 in h.
"""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_bvp as scipy_bvp
from scipy.optimize import minimize

from symvi import ModelError, PairGroupoid
from symvi.declaration.nonholonomic import (distribution, lagrange_dalembert,
                                            nonholonomic_control)
from symvi.models import get
from symvi.models.unicycle_parking import guess as unicycle_guess

M, J = 1.0, 0.5         # the bundled unicycle's mass and inertia
START, END = np.zeros(5), np.array([0.0, 1.0, 0.0, 0.0, 0.0])
T = 4.0


def solve_unicycle(mod, n: int):
    s = np.arange(1, n) / n
    return mod.solve_bvp(START[None], END[None], n, T / n, guess=unicycle_guess(s))


def kinematic_defect(nodes: np.ndarray, h: float) -> np.ndarray:
    """(q₁ − q₀)/h − ρ(q̄)ȳ per element, in NumPy."""
    q, y = nodes[:, :3], nodes[:, 3:]
    qm, ym = (q[1:] + q[:-1]) / 2, (y[1:] + y[:-1]) / 2
    rho_y = np.stack([np.cos(qm[:, 2]) * ym[:, 0], np.sin(qm[:, 2]) * ym[:, 0], ym[:, 1]], 1)
    return np.diff(q, axis=0) / h - rho_y


def discrete_cost(nodes: np.ndarray, h: float) -> float:
    """Σ h ½(F² + τ²) with F = m (v₁ − v₀)/h, τ = J (ω₁ − ω₀)/h."""
    dv, dw = np.diff(nodes[:, 3]) / h, np.diff(nodes[:, 4]) / h
    return float(np.sum(h * ((M * dv)**2 + (J * dw)**2) / 2))


@pytest.fixture(scope="module")
def unicycle(compiled):
    return compiled("unicycle_parking")


# -- declarations ------------------------------------------------------------------------
def test_lagrange_dalembert_equations_are_the_textbook_ones():
    Q = PairGroupoid("x y theta")
    th = Q.q[2]
    m, I, a = sp.symbols("m I a", positive=True)
    T_kin = m * (Q.qdot[0]**2 + Q.qdot[1]**2) / 2 + I * Q.qdot[2]**2 / 2
    sled = distribution(Q, [[sp.cos(th), sp.sin(th), 0], [-a * sp.sin(th), a * sp.cos(th), 1]],
                        "u omega", parameters=[a])
    (u, w), (du, dw) = sled.y, sled.ydot
    E = lagrange_dalembert(sled, T_kin)
    # Chaplygin sled: m(u̇ − aω²) forward, (I + ma²)ω̇ + m a u ω about the edge
    assert sp.simplify(E[0] - m * (du - a * w**2)) == 0
    assert sp.simplify(E[1] - ((I + m * a**2) * dw + m * a * u * w)) == 0
    # a potential enters through ∂L/∂q along the fields: V = m g y pushes the drive by
    # m g sin θ and not the turning
    g = sp.Symbol("g", positive=True)
    unicycle = distribution(Q, [[sp.cos(th), sp.sin(th), 0], [0, 0, 1]], "v omega")
    E = lagrange_dalembert(unicycle, T_kin - m * g * Q.q[1])
    (dv, dw) = unicycle.ydot
    assert sp.simplify(E[0] - (m * dv + m * g * sp.sin(th))) == 0
    assert sp.simplify(E[1] - I * dw) == 0


def test_the_model_is_the_paper_discretisation_of_d2():
    """L̃_d = h L̃(q̄, ȳ, (y₁ − y₀)/h) and Φ_d = h[(q₁ − q₀)/h − ρ(q̄)ȳ] on D_d⁽²⁾."""
    model = get("unicycle_parking")
    assert model.order == 1 and model.discretisation == "midpoint"
    G = model.groupoid
    assert [str(s) for s in G.q] == ["x", "y", "theta", "v", "omega"]
    assert len(model.constraints) == 3 and len(model.controls) == 2
    x, y, th, v, w = G.q
    qd = G.qdot
    expected = [qd[0] - v * sp.cos(th), qd[1] - v * sp.sin(th), qd[2] - w]
    assert all(sp.simplify(c - e) == 0 for c, e in zip(model.constraints, expected))


@pytest.mark.parametrize("call, pattern", [
    (lambda Q, th: distribution(Q, [[sp.cos(th), sp.sin(th), 0], [2 * sp.cos(th),
                                                                    2 * sp.sin(th), 0]], "v w"),
     r"linearly dependent \(rank 1"),
    (lambda Q, th: distribution(Q, [[sp.cos(th), sp.sin(th)]], "v"),
     r"each vector field needs 3 components"),
    (lambda Q, th: distribution(Q, [[sp.cos(th), sp.sin(th), 0]], "v w"),
     r"1 vector fields need 1 quasi-velocity names"),
    (lambda Q, th: distribution(Q, [[sp.cos(th), sp.sin(th), 0]], "theta"),
     r"clash with the coordinates"),
    (lambda Q, th: distribution(Q, [[sp.cos(th), sp.Symbol("k") * sp.sin(th), 0]], "v"),
     r"use \['k'\], which are neither coordinates"),
    (lambda Q, th: nonholonomic_control(
        "bad_cost", distribution(Q, [[sp.cos(th), sp.sin(th), 0], [0, 0, 1]], "v w"),
        Q.qdot[0]**2, sp.Symbol("F")**2 + sp.Symbol("z"), ["F"], actuated=[0]),
     r"cost of 'bad_cost' uses \['z'\]"),
    (lambda Q, th: nonholonomic_control(
        "bad_act", distribution(Q, [[sp.cos(th), sp.sin(th), 0], [0, 0, 1]], "v w"),
        Q.qdot[0]**2, sp.Symbol("F")**2, ["F"], actuated=[2]),
     r"actuated directions must be distinct indices in 0..1"),
])
def test_bad_declarations_are_refused_with_their_reason(call, pattern):
    Q = PairGroupoid("x y theta")
    with pytest.raises(ModelError, match=pattern):
        call(Q, Q.q[2])


def test_discrete_equations_are_consistent_with_the_nonholonomic_optimality_conditions():
    """The discrete residual and constraints of the unicycle expand in h as h·E + O(h³) and
    h·Φ + O(h³) (order 2), E being the optimality conditions of the extended Lagrangian
    L̃ + λ·(q̇ − ρ(q)y), written out here: ∂/∂c − d/dt ∂/∂ċ for c = x, y, θ, v, ω."""
    from symvi.checks.expansions import check_consistency
    report = check_consistency(get("unicycle_parking"))
    assert (report.power, report.sign, report.order) == (1, 1, 2)
    assert (report.constraints.power, report.constraints.sign,
            report.constraints.order) == (1, 1, 2)
    t = sp.Symbol("t", real=True)
    x, y, th, v, w, l0, l1, l2 = (sp.Function(n, real=True)(t) for n in
                                  ("x", "y", "theta", "v", "omega", "lambda0", "lambda1",
                                   "lambda2"))
    m, J = sp.symbols("m J", positive=True)
    d = sp.Derivative
    conditions = [-d(l0, t), -d(l1, t),
                  l0 * v * sp.sin(th) - l1 * v * sp.cos(th) - d(l2, t),
                  -l0 * sp.cos(th) - l1 * sp.sin(th) - m**2 * d(v, (t, 2)),
                  -l2 - J**2 * d(w, (t, 2))]
    kinematic = [d(x, t) - v * sp.cos(th), d(y, t) - v * sp.sin(th), d(th, t) - w]
    assert all(sp.simplify(a - b) == 0 for a, b in zip(report.expected, conditions))
    assert all(sp.simplify(a - b) == 0 for a, b in zip(report.constraints.expected, kinematic))


# -- the whole-trajectory solve ----------------------------------------------------------
def test_parking_satisfies_the_discrete_kinematic_constraints(unicycle):
    n = 40
    res = solve_unicycle(unicycle, n)
    assert res.success, res.message
    h = T / n
    assert np.abs(kinematic_defect(res.x, h)).max() <= 1e-12
    np.testing.assert_array_equal(res.x[[0, -1]], [START, END])
    # a sideways move needs the heading to turn away and back, driving along it
    assert np.abs(res.x[:, 2]).max() > 0.3 and np.abs(res.x[:, 3]).max() > 0.1
    assert res.x[n // 2, 2] != 0.0 and abs(res.x[-1, 2]) == 0.0
    # the controls are the forces of the Lagrange–d'Alembert equations at each midpoint
    F = M * np.diff(res.x[:, 3]) / h
    np.testing.assert_allclose(res.controls[:, 0], F, rtol=0, atol=1e-9)
    assert res.cost == pytest.approx(discrete_cost(res.x, h), rel=1e-12)


def test_same_optimum_as_a_direct_minimisation(unicycle):
    """SLSQP on the discrete problem written out here, from the same start, at N = 8."""
    n = 8
    h = T / n
    res = solve_unicycle(unicycle, n)
    assert res.success, res.message
    s = np.arange(1, n) / n

    def nodes(z):
        return np.vstack([START, z.reshape(n - 1, 5), END])

    direct = minimize(lambda z: discrete_cost(nodes(z), h), unicycle_guess(s).ravel(),
                      method="SLSQP",
                      constraints={"type": "eq",
                                   "fun": lambda z: h * kinematic_defect(nodes(z), h).ravel()},
                      options={"ftol": 1e-15, "maxiter": 2000})
    assert direct.success, direct.message
    assert np.abs(kinematic_defect(nodes(direct.x), h)).max() < 1e-9
    assert direct.fun == pytest.approx(res.cost, rel=1e-8)
    assert np.abs(nodes(direct.x) - res.x).max() < 1e-5


def _pontryagin(t_grid, start_path):
    """The continuous optimum of the unicycle's parking by Pontryagin's principle: states
    (x, y, θ, v, ω), costates λ; a = v̇ = −λ_v/m², α = ω̇ = −λ_ω/J²."""
    def rhs(t, z):
        x, y, th, v, w, lx, ly, lth, lv, lw = z
        return np.vstack([v * np.cos(th), v * np.sin(th), w, -lv / M**2, -lw / J**2,
                          0 * t, 0 * t, lx * v * np.sin(th) - ly * v * np.cos(th),
                          -(lx * np.cos(th) + ly * np.sin(th)), -lth])

    def bc(za, zb):
        return np.concatenate([za[:5] - START, zb[:5] - END])

    guess = np.vstack([start_path.T, np.zeros((5, len(t_grid)))])
    sol = scipy_bvp(rhs, bc, t_grid, guess, tol=1e-10, max_nodes=100_000)
    assert sol.success, sol.message
    t = np.linspace(0, T, 20_001)
    lv, lw = sol.sol(t)[8], sol.sol(t)[9]
    integrand = ((lv / M)**2 + (lw / J)**2) / 2       # ½(F² + τ²), F = m a, τ = J α
    return float(np.sum((integrand[1:] + integrand[:-1]) / 2 * np.diff(t))), sol


def test_cost_converges_at_order_two_to_the_continuous_optimum(unicycle):
    sizes = (20, 40, 80, 160)
    runs = [solve_unicycle(unicycle, n) for n in sizes]
    assert all(r.success for r in runs), [r.message for r in runs]
    costs = np.array([r.cost for r in runs])
    reference, sol = _pontryagin(runs[-1].t, runs[-1].x)
    errors = np.abs(costs - reference)
    orders = np.log2(errors[:-1] / errors[1:])
    assert np.all(np.abs(orders - 2) < 0.15), (orders, errors)
    # and the path: the nodes approach the continuous states at order 2 as well
    path_error = np.abs(runs[-1].x - sol.sol(runs[-1].t)[:5].T).max()
    assert path_error < 10 * errors[-1] / max(reference, 1.0) + 1e-4


@pytest.mark.parametrize("name", ["chaplygin_sled", "rolling_coin"])
def test_underactuated_and_rolling_problems_solve(name, compiled):
    model, mod = get(name), compiled(name)
    ex = model.example
    res = mod.solve_bvp(ex.start, ex.end, ex.n_steps, ex.h, guess=ex.guess_nodes())
    assert res.success, res.message
    assert res.multipliers.shape == (ex.n_steps, len(model.constraints))
    np.testing.assert_array_equal(res.x[[0, -1]], np.vstack([ex.start, ex.end]))
    # the kinematic constraints of D_d⁽²⁾ hold on every element, in NumPy
    h, q, y = ex.h, res.x[:, :3], res.x[:, 3:]
    qm, ym = (q[1:] + q[:-1]) / 2, (y[1:] + y[:-1]) / 2
    if name == "chaplygin_sled":
        a = 0.5
        rho_y = np.stack([np.cos(qm[:, 2]) * ym[:, 0] - a * np.sin(qm[:, 2]) * ym[:, 1],
                          np.sin(qm[:, 2]) * ym[:, 0] + a * np.cos(qm[:, 2]) * ym[:, 1],
                          ym[:, 1]], 1)
        # u̇ = aω² (unactuated) at every midpoint; below the wiggle that defined the end
        du = np.diff(res.x[:, 3]) / h
        assert np.abs(du - a * ym[:, 1]**2).max() <= 1e-10
        assert res.cost < 0.375
    else:
        q, y = res.x[:, :4], res.x[:, 4:]
        qm, ym = (q[1:] + q[:-1]) / 2, (y[1:] + y[:-1]) / 2
        R = 0.5
        rho_y = np.stack([R * np.cos(qm[:, 2]) * ym[:, 0], R * np.sin(qm[:, 2]) * ym[:, 0],
                          ym[:, 1], ym[:, 0]], 1)
    assert np.abs(np.diff(q, axis=0) / h - rho_y).max() <= 1e-12
