"""Consistency of the discrete Euler–Lagrange residuals (DESIGN.md §5, symvi.checks.expansions).

Sampling a smooth curve, q_{j+i} = q(t + i h), the residual of every bundled model expands
as R = h·E(L) + h³·c₃ + …, where E(L) = ∂L/∂q − d/dt ∂L/∂q̇ + d²/dt² ∂L/∂q̈ is the
variational derivative of the action.

* Power h¹ for both orders: R_j = ∂S_d/∂q_j with S_d = Σ L_d ≈ ∫ L dt, and moving one node
  changes the curve on a time span of order h, so ∂S_d/∂q_j ≈ h·δS/δq(t_j). For the
  three-point rule this means the poles of its terms cancel: the kinetic part
  ½|q̈|² gives (1/h³)·(fourth difference) = h q⁗ + h³ q⁽⁶⁾/6 + …
* Sign +1 for both orders, against E(L): that is −(d/dt ∂L/∂q̇ − ∂L/∂q) for first order
  and +(d²/dt² ∂L/∂q̈ − d/dt ∂L/∂q̇ + ∂L/∂q) for second order.
* Next power h³ (relative error O(h²)): the midpoint and three-point rules are symmetric,
  L_d(q_0, …, q_r; h) = −L_d(q_r, …, q_0; −h), so the residual is odd in h.
"""
from __future__ import annotations

import pytest
import sympy as sp

from curves import curve as _q, derivative as _d, parameters as _params
from conftest import PAIR
from symvi import Model, PairGroupoid, h
from symvi.checks.expansions import (check_consistency, euler_lagrange, expand_residual,
                               residual_expansion)
from symvi.derivation.derive import derive
from symvi.discretisation.discretise import discretise
from symvi.errors import ModelError
from symvi.models import get


def _hand_written(name):
    """E(L) of each bundled model, written out from textbook equations of motion."""
    model = get(name)
    P = _params(model)
    if name == "harmonic_oscillator":
        x = _q("x")
        return [-(P["m"] * _d(x, 2) + P["k"] * x)]
    if name == "pendulum":
        th, (m, l, g) = _q("theta"), (P["m"], P["l"], P["g"])
        return [-(m * l**2 * _d(th, 2) + m * g * l * sp.sin(th))]
    if name == "double_pendulum":
        a, b = _q("theta1"), _q("theta2")
        m1, m2, l1, l2, g = (P[k] for k in ("m1", "m2", "l1", "l2", "g"))
        return [-((m1 + m2) * l1**2 * _d(a, 2) + m2 * l1 * l2 * _d(b, 2) * sp.cos(a - b)
                  + m2 * l1 * l2 * _d(b)**2 * sp.sin(a - b) + (m1 + m2) * g * l1 * sp.sin(a)),
                -(m2 * l2**2 * _d(b, 2) + m2 * l1 * l2 * _d(a, 2) * sp.cos(a - b)
                  - m2 * l1 * l2 * _d(a)**2 * sp.sin(a - b) + m2 * g * l2 * sp.sin(b))]
    if name == "robot_arm":
        return _kane(model)
    if name in ("minimum_jerk", "minimum_snap"):     # L = ½|q⁽ᵏ⁾|²: (−1)ᵏ q⁽²ᵏ⁾
        k = model.order
        return [(-1)**k * _d(_q(c), 2 * k) for c in "xyz"]
    x, y = _q("x"), _q("y")
    if name == "cubic_spline":
        return [_d(x, 4), _d(y, 4)]
    alpha, beta = P["alpha"], P["beta"]
    r2 = x**2 + y**2
    return [_d(x, 4) + alpha * x + beta * r2 * x, _d(y, 4) + alpha * y + beta * r2 * y]


def _kane(model):
    """−(M q̈ − F) of the robot arm from SymPy mechanics' Kane's method on the System the
    model was built from (speeds u = q̇), in the test's curves."""
    from sympy.physics.mechanics import dynamicsymbols
    from symvi.models.robot_arm import arm
    system = arm()
    system.form_eoms()
    t, P = dynamicsymbols._t, _params(model)
    curves = {q: _q(str(q.func)) for q in system.q}
    rates = {u: q.diff(t) for u, q in zip(system.u, system.q)}
    eom = (system.mass_matrix * sp.Matrix(system.u).diff(t) - system.forcing).xreplace(
        {u.diff(t): q.diff(t, 2) for u, q in zip(system.u, system.q)}).xreplace(rates)
    eom = eom.subs({q.diff(t, k): _d(curves[q], k) for q in system.q for k in (2, 1)})
    eom = eom.xreplace(curves).xreplace({sp.Symbol(n, positive=True): v for n, v in P.items()})
    return [-e for e in eom]


def _equal(a, b):
    return all(sp.simplify(u - v) == 0 for u, v in zip(a, b))


@pytest.mark.parametrize("name", PAIR)
def test_euler_lagrange_expression(name):
    assert _equal(euler_lagrange(get(name)), _hand_written(name))


#: The robot arm's symbolic expansion takes 50 s: its consistency is the check's
#: (test_check_bundled) and its order is measured against Kane's equations
#: (test_mechanics).
@pytest.mark.parametrize("name", [n for n in PAIR if n != "robot_arm"])
def test_residual_is_consistent_with_euler_lagrange(name, derived):
    model = get(name)
    expansion = residual_expansion(model, derived=derived(name))
    # Every power below h¹ (down to the h⁻³ of the three-point rule's 1/h² terms) cancels.
    assert expansion.leading_power == 1
    assert _equal(expansion.leading, euler_lagrange(model))
    assert _equal(expansion.leading, _hand_written(name))
    assert expansion.sign_against(euler_lagrange(model)) == 1
    # Next term: h³, so the residual approximates h·E(L) with relative error O(h²).
    assert expansion.next_power == 3
    assert expansion.order == 2
    assert not _equal(expansion.next_term, sp.zeros(*expansion.next_term.shape))


def test_next_term_of_the_harmonic_oscillator():
    """R = m(2x_j − x_{j−1} − x_{j+1})/h − hk(x_{j−1} + 2x_j + x_{j+1})/4, by hand:
    h³ coefficient −m x⁗/12 − k x''/4."""
    model = get("harmonic_oscillator")
    P, x = _params(model), _q("x")
    expansion = residual_expansion(model)
    assert _equal(expansion.next_term, [-P["m"] * _d(x, 4) / 12 - P["k"] * _d(x, 2) / 4])


def _against_sympy_series(model, dm):
    """Our expansion of the step residual against brute force: substitute the Taylor
    polynomials of the nodes and call sympy.series (slow in general, fine for these)."""
    kernel = dm.kernel("step")
    residual = dict(kernel.outputs)["residual"]
    r, n = dm.order, dm.fibre_dim
    nodes = [kernel.z[i * n:(i + 1) * n] for i in range(2 * r + 1)]
    names = model.groupoid.names
    through, degree = 3, 3 + 2 * r - 1   # enough Taylor terms for exact h³ coefficients
    jets = [[sp.Symbol(f"J{c}_{k}") for k in range(degree + 1)] for c in range(n)]
    to_functions = {jets[c][k]: (_q(nm) if k == 0 else _d(_q(nm), k))
                    for c, nm in enumerate(names) for k in range(degree + 1)}
    taylor = {s: sum((i - r)**k * h**k / sp.factorial(k) * jets[c][k]
                     for k in range(degree + 1))
              for i, node in enumerate(nodes) for c, s in enumerate(node)}
    expansion = expand_residual(residual, nodes, h, names, centre=r, through=through)
    ours = dict(expansion.terms)
    for row, entry in enumerate(residual):
        brute = sp.expand(sp.series(entry.xreplace(taylor), h, 0, through + 1).removeO())
        for p in range(-2 * r, through + 1):
            expected = brute.coeff(h, p).xreplace(to_functions)
            got = ours[p][row] if p in ours else 0
            assert sp.simplify(got - expected) == 0, (model.name, row, p)


@pytest.mark.parametrize("name", ["harmonic_oscillator", "pendulum", "spline_potential"])
def test_expansion_agrees_with_sympy_series(name, derived):
    _against_sympy_series(get(name), derived(name))


def _non_polynomial(name):
    G = PairGroupoid("q")
    (q,), (v,) = G.q, G.qdot
    L = {"relativistic": -sp.sqrt(1 - v**2) - q**2 / 2,      # fractional powers of v
         "varying_mass": v**2 / (2 * (1 + q**2)) - q**4 / 4}[name]  # 1/(polynomial in q)
    return Model(name=name, groupoid=G, lagrangian=L)


@pytest.mark.parametrize("name", ["relativistic", "varying_mass"])
def test_non_polynomial_lagrangians(name):
    """The series arithmetic's analytic-function and reciprocal paths, which no bundled
    model reaches, against sympy.series; both midpoint residuals are consistent."""
    model = _non_polynomial(name)
    _against_sympy_series(model, derive(discretise(model)))
    report = check_consistency(model)
    assert (report.power, report.sign, report.order) == (1, 1, 2)


# ---------------------------------------------------------------------------------------
# Negative controls: wrong residuals and inconsistent discrete Lagrangians are caught
# ---------------------------------------------------------------------------------------
def _slot_derivatives(model):
    """D_i L_d as functions of the window's nodes (pair groupoid)."""
    dm = discretise(model)
    window = [tuple(dm.slots[0][0])] + [tuple(f) for _, f in dm.slots]
    grads = [[sp.diff(dm.lagrangian, s) for s in node] for node in window]

    def D(i, nodes):
        mapping = {s: v for node, values in zip(window, nodes) for s, v in zip(node, values)}
        return sp.Matrix([g.xreplace(mapping) for g in grads[i]])
    return D


def _node_symbols(count, n):
    return [tuple(sp.Symbol(f"n{i}_{c}", real=True) for c in range(n)) for i in range(count)]


@pytest.mark.parametrize("name", ["harmonic_oscillator", "pendulum"])
def test_sign_flip_in_first_order_del_is_detected(name):
    model = get(name)
    D, nodes = _slot_derivatives(model), _node_symbols(3, 1)
    names, el = model.groupoid.names, euler_lagrange(model)
    # D2 L_d(q_{j−1}, q_j) + D1 L_d(q_j, q_{j+1}), and the same with one sign flipped
    right = D(1, nodes[0:2]) + D(0, nodes[1:3])
    wrong = D(0, nodes[1:3]) - D(1, nodes[0:2])
    good = expand_residual(right, nodes, h, names, centre=1, through=3)
    assert (good.leading_power, good.sign_against(el), good.next_power) == (1, 1, 3)
    bad = expand_residual(wrong, nodes, h, names, centre=1, through=3)
    assert bad.leading_power == 0          # −2 L_v: not an equation of motion at all
    assert bad.sign_against(el) is None


def test_sign_flip_in_second_order_del_is_detected():
    model = get("spline_potential")
    D, nodes = _slot_derivatives(model), _node_symbols(5, 2)
    names, el = model.groupoid.names, euler_lagrange(model)
    right = D(2, nodes[0:3]) + D(1, nodes[1:4]) + D(0, nodes[2:5])
    wrong = D(2, nodes[0:3]) - D(1, nodes[1:4]) + D(0, nodes[2:5])
    good = expand_residual(right, nodes, h, names, centre=2, through=3)
    assert (good.leading_power, good.sign_against(el), good.next_power) == (1, 1, 3)
    bad = expand_residual(wrong, nodes, h, names, centre=2, through=3)
    assert bad.leading_power == -1         # (q_{j−2} − 2q_j + q_{j+2})/h³ ≈ 4q''/h
    assert bad.sign_against(el) is None


def _direct(name, reference, build, order):
    """A model with L_d given directly, built from the reference model's L."""
    G = reference.groupoid
    nodes = [sp.Matrix(node) for node in G.nodes(order + 1)]
    Ld = build(reference.lagrangian, G, nodes)
    return Model(name=name, groupoid=G, discrete_lagrangian=Ld, order=order,
                 parameters=dict(reference.parameters))


def _subs(L, G, q, v, a=None):
    mapping = dict(zip(G.q, q)) | dict(zip(G.qdot, v))
    if a is not None:
        mapping |= dict(zip(G.qddot, a))
    return L.xreplace(mapping)


def test_inconsistent_first_order_discrete_lagrangian_is_detected():
    """Velocity (q1 − q0)/(2h) instead of /h: the kinetic term is a quarter too small."""
    ho = get("harmonic_oscillator")
    bad = _direct("bad_ho", ho, lambda L, G, n: h * _subs(L, G, (n[0] + n[1]) / 2,
                                                          (n[1] - n[0]) / (2 * h)), 1)
    report = check_consistency(bad, lagrangian_model=ho)
    assert report.power == 1 and not report.consistent


def test_inconsistent_second_order_discrete_lagrangian_is_detected():
    """Acceleration (q2 − 2q1 + q0)/(2h²) instead of /h²: the q⁗ term comes out a
    quarter too small."""
    sp_model = get("spline_potential")

    def scaled(L, G, n):
        return h * _subs(L, G, (n[0] + n[1] + n[2]) / 3, (n[2] - n[0]) / (2 * h),
                         (n[2] - 2 * n[1] + n[0]) / (2 * h**2))
    report = check_consistency(_direct("bad_spline", sp_model, scaled, 2),
                               lagrangian_model=sp_model)
    assert report.power == 1 and not report.consistent


def test_asymmetric_rule_has_first_order_consistency():
    """The left-point rule L_d = h L(q0, (q1 − q0)/h) is consistent but not symmetric: for
    the double pendulum (whose mass matrix depends on q) its residual has an h² term, so
    the measured order drops to 1 — the reported order is measured, not assumed."""
    dp = get("double_pendulum")
    left = _direct("left_dp", dp, lambda L, G, n: h * _subs(L, G, n[0], (n[1] - n[0]) / h), 1)
    report = check_consistency(left, lagrangian_model=dp)
    assert (report.power, report.sign, report.order) == (1, 1, 1)


def test_trapezoid_rule_is_second_order():
    pendulum = get("pendulum")
    trap = Model(name="trap", groupoid=pendulum.groupoid, lagrangian=pendulum.lagrangian,
                 discretisation="trapezoid", parameters=dict(pendulum.parameters))
    report = check_consistency(trap, lagrangian_model=pendulum)
    assert (report.power, report.sign, report.order) == (1, 1, 2)


def test_discrete_model_needs_a_continuous_reference():
    ho = get("harmonic_oscillator")
    direct = _direct("direct", ho, lambda L, G, n: h * _subs(L, G, n[0], (n[1] - n[0]) / h), 1)
    with pytest.raises(ModelError, match="no continuous Lagrangian"):
        check_consistency(direct)
