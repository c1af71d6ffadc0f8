"""The checks on Lagrangians of order k > 2 (issue 25, part 2): ``consistency`` against
E(L) = Σ_{j≤k} (−d/dt)^j ∂L/∂q⁽ʲ⁾ on the pair groupoid and the order-k Euler–Poincaré
operator on SO(3), at the measured order 2 of the rules ``central<k>`` and
``lie_central<k>``; a wrong discrete Lagrangian of order 3 fails; ``structure`` on the
reduced T*(H^k); ``regularity`` names D₁,ₖ₊₁L_d; ``routes`` says why it skips."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import sympy as sp
from sympy.calculus.euler import euler_equations

import symvi
from symvi.checks import consistency, regularity, routes, structure
from symvi.checks.expansions import check_consistency
from symvi.checks.jets import euler_lagrange_algebroid
from symvi.checks.runner import Context, check
from symvi.checks.stepmap import StepMap
from symvi.declaration.symbols import h
from symvi.derivation.derive import derive
from symvi.discretisation.discretise import discretise
from symvi.errors import ModelError

INERTIA = (1, 2, 3)


# -- models, one derivation each for the module ------------------------------------------
def _pair(k: int) -> symvi.Model:
    """½|q⁽ᵏ⁾|² with a state-dependent weight, a lower-order coupling and a potential."""
    G = symvi.PairGroupoid("x y")
    d, (x, y) = G.derivative, G.q
    L = sum(v**2 for v in d(k)) / 2 + sp.Rational(1, 10) * x**2 * d(k)[1]**2 - y**2 / 2
    if k > 3:
        L += d(1)[0] * d(k - 1)[1] / 3
    return symvi.Model(f"pair{k}", G, lagrangian=L)


def _so3(k: int) -> symvi.Model:
    """½ Σ I_a (ξ⁽ᵏ⁻¹⁾_a)² on SO(3)."""
    G = symvi.SO3()
    L = sum(w * v**2 for w, v in zip(INERTIA, G.derivative(k - 1))) / 2
    return symvi.Model(f"so3_k{k}", G, lagrangian=L)


@pytest.fixture(scope="module")
def pair3():
    return Context(_pair(3))


@pytest.fixture(scope="module")
def pair4():
    return Context(_pair(4))


@pytest.fixture(scope="module")
def so3_3():
    return Context(_so3(3))


@pytest.fixture(scope="module")
def so3_4():
    return Context(_so3(4))


def _functions(G, k: int, t: sp.Symbol) -> dict:
    """G.derivative(j) → d^j q(t)/dt^j, the functions the expansion reports in."""
    out = {}
    for c, name in enumerate(G.names):
        f = sp.Function(name, real=True)(t)
        out |= {G.derivative(j)[c]: f.diff(t, j) if j else f for j in range(k + 1)}
    return out


def _zero(expr) -> bool:
    return sp.expand(sp.sympify(expr).doit()) == 0


# -- consistency: the order-k equations, at order 2 ---------------------------------------
@pytest.mark.parametrize("k", [3, 4])
def test_pair_residual_is_h_times_the_order_k_euler_lagrange_expression(k, pair3, pair4):
    ctx = {3: pair3, 4: pair4}[k]
    model = ctx.model
    result = consistency.run(ctx)
    assert result.status == "pass", (result.summary, result.details)
    d = result.data
    assert (d["power"], d["sign"], d["order"], d["next_power"]) == (1, 1, 2, 3)
    assert f"Σ_{{j=0}}^{{{k}}} (−d/dt)^j ∂L/∂q⁽ʲ⁾" in d["equation"]
    assert model.discretisation == f"central{k}"
    # The leading coefficient against SymPy's own Euler–Lagrange equations of L(q, …, q⁽ᵏ⁾)
    # (Σ_j (−d/dt)^j ∂L/∂q⁽ʲ⁾, the same sign as E).
    report = check_consistency(model, derived=ctx.derived)
    e = report.expansion
    t, G = e.time, model.groupoid
    f = _functions(G, k, t)
    oracle = euler_equations(model.lagrangian.xreplace(f),
                             [f[G.q[0]], f[G.q[1]]], t)
    assert e.leading_power == 1 and e.next_power == 3
    for lead, eq in zip(e.leading, oracle):
        assert _zero(lead - eq.lhs)
    # the h² coefficient vanishes (a symmetric rule), the h³ one does not
    assert all(p != 2 for p, _ in e.terms) and any(c != 0 for c in e.next_term)
    if k == 3:      # issue 25's example: x·y'''²/5 − x⁽⁶⁾ for x
        x, y = f[G.q[0]], f[G.q[1]]
        assert _zero(e.leading[0] - (x * y.diff(t, 3)**2 / 5 - x.diff(t, 6)))


@pytest.mark.parametrize("k", [3, 4])
def test_so3_residual_is_h_times_the_order_k_euler_poincare_expression(k, so3_3, so3_4):
    ctx = {3: so3_3, 4: so3_4}[k]
    result = consistency.run(ctx)
    assert result.status == "pass", (result.summary, result.details)
    d = result.data
    assert (d["power"], d["sign"], d["order"], d["next_power"]) == (1, 1, 2, 3)
    assert f"EL_{k}(L)" in d["equation"] and f"order-{k} Euler–Poincaré" in d["equation"]
    # For L = ½ Σ I_a (ξ⁽ᵏ⁻¹⁾_a)²: P = (−1)^{k−1} I ξ⁽²ᵏ⁻²⁾, so
    # E = −EL_k = (−1)^k (I ξ⁽²ᵏ⁻¹⁾ + ξ × I ξ⁽²ᵏ⁻²⁾).
    e = check_consistency(ctx.model, derived=ctx.derived).expansion
    t = e.time
    xi = sp.Matrix([sp.Function(f"Omega{a}", real=True)(t) for a in (1, 2, 3)])
    inertia = sp.diag(*INERTIA)
    expected = (-1)**k * (inertia * xi.diff(t, 2 * k - 1)
                          + xi.cross(inertia * xi.diff(t, 2 * k - 2)))
    assert all(_zero(a - b) for a, b in zip(e.leading, expected))
    assert (e.leading_power, e.next_power) == (1, 3)
    # the continuous operator alone gives the same
    L = ctx.model.lagrangian
    operator = euler_lagrange_algebroid(ctx.model.groupoid, L, k, t)
    assert all(_zero(a + b) for a, b in zip(operator, expected))


def test_operator_orders_beyond_the_groupoid_are_refused():
    G = symvi.SO3()
    with pytest.raises(ModelError, match="order must be an integer from 1 to 6"):
        euler_lagrange_algebroid(G, G.xi[0]**2, 7)


# -- consistency: a wrong discrete Lagrangian of order 3 fails ----------------------------
def _discrete_order_3(G, middle, potential=sp.Rational(1, 2)):
    """h·L of :func:`_pair` (k = 3) with q''' the third difference of the 4 nodes and q
    the ``middle`` of them."""
    q0, q1, q2, q3 = (sp.Matrix(n) for n in G.nodes(4))
    third = (q3 - 3 * q2 + 3 * q1 - q0) / h**3
    m = middle(q0, q1, q2, q3)
    Ld = h * (sum(v**2 for v in third) / 2 + sp.Rational(1, 10) * m[0]**2 * third[1]**2
              - potential * m[1]**2)
    return symvi.Model("discrete3", G, discrete_lagrangian=Ld, order=3)


def _cubic_centre(q0, q1, q2, q3):      # the cubic through the nodes at 3h/2
    return (-q0 + 9 * q1 + 9 * q2 - q3) / 16


def test_hand_written_order_3_discrete_lagrangian_is_consistent(pair3):
    reference = pair3.model
    right = _discrete_order_3(reference.groupoid, _cubic_centre)
    report = check_consistency(right, lagrangian_model=reference)
    assert (report.power, report.sign, report.order) == (1, 1, 2)
    # the same middle node, off centre: consistent, but of order 1 only
    off = _discrete_order_3(reference.groupoid, lambda q0, q1, q2, q3: q1)
    report = check_consistency(off, lagrangian_model=reference)
    assert (report.power, report.sign, report.order) == (1, 1, 1)


def test_wrong_weight_in_an_order_3_discrete_lagrangian_fails(pair3):
    reference = pair3.model
    wrong = _discrete_order_3(reference.groupoid, _cubic_centre, potential=1)
    report = check_consistency(wrong, lagrangian_model=reference)
    assert report.sign is None and report.power == 1
    e = report.expansion
    y = sp.Function("y", real=True)(e.time)
    sign, rows = e.compare(report.expected)
    assert (sign, rows) == (1, [1])
    assert _zero(e.leading[0] - report.expected[0])
    assert _zero(e.leading[1] - report.expected[1] + y)      # −y² instead of −y²/2
    # through the check: the reference model with the wrong residual
    ctx = Context(reference)
    ctx.derived = derive(discretise(wrong))
    result = consistency.run(ctx)
    assert result.status == "fail"
    assert "not ±h^1·E in y" in result.summary
    assert any("component y (row 1)" in line and "= -y" in line for line in result.details)


# -- structure, regularity, routes ------------------------------------------------------
@pytest.mark.parametrize("which", ["pair3", "so3_3"])
def test_order_3_step_maps_preserve_the_reduced_structure(which, request):
    ctx = request.getfixturevalue(which)
    result = structure.run(ctx)
    assert result.status == "pass", (result.summary, result.details)
    assert result.data["h"] == 0.5 and result.data["tolerance"] == structure.HIGH_ORDER_TOLERANCE
    assert result.data["max_defect"] < 1e-14
    assert "(x₀, ν; f₀, f₁; p₀, p₁)" in result.summary and "T*(Q^3)" in result.summary


def test_order_3_structure_is_pinned_down_and_a_force_term_is_caught(pair3, so3_3):
    # the other relative sign of the Lie–Poisson block fails on the group …
    step = StepMap(so3_3.derived, so3_3.model.groupoid, 0.5, sign=+1.0)
    rng = np.random.default_rng(3)
    assert min(step.defect(step.sample(rng)).relative for _ in range(2)) > 1e-4
    # … and a consistent, non-variational force h·f(x₀) at the first node is caught
    derived = pair3.derived
    kernel = derived.kernel("step")
    x0, y0 = kernel.z[:2]
    R = dict(kernel.outputs)["residual"] + h * sp.Matrix([x0**3 + y0, x0 * y0])
    broken = dataclasses.replace(kernel, outputs=(("residual", R),
                                                  ("jacobian", R.jacobian(kernel.z[-2:]))))
    ctx = Context(pair3.model)
    ctx.derived = dataclasses.replace(
        derived, kernels=tuple(broken if k.name == "step" else k for k in derived.kernels))
    result = structure.run(ctx)
    assert result.status == "fail" and "does not preserve" in result.summary
    assert result.data["max_defect"] > 1e-7
    assert all("s = (x₀, f₀, …, f₄)" in line for line in result.details)


@pytest.mark.parametrize("k", [3, 4, 5, 6])
def test_regularity_names_the_step_matrix_of_order_k(k):
    G = symvi.PairGroupoid("x")
    model = symvi.Model(f"line{k}", G, lagrangian=G.derivative(k)[0]**2 / 2 - G.q[0]**2 / 2)
    result = regularity.run(Context(model))
    subscript = str(k + 1).translate(str.maketrans("0123456789", "₀₁₂₃₄₅₆₇₈₉"))
    assert result.status == "pass"
    assert result.summary.startswith(f"D₁{subscript}L_d (1×1) has full rank 1")


def test_regularity_on_the_group_and_routes_skip_with_the_reason(so3_3):
    result = regularity.run(so3_3)
    assert result.status == "pass" and result.summary.startswith("D₁₄L_d analogue (3×3)")
    result = routes.run(so3_3)
    assert result.status == "skip"
    assert "not 3" in result.summary and "higher prolongation" in result.summary


def test_issue_example_through_the_runner(pair3):
    report = check(pair3.model)
    statuses = {r.name: r.status for r in report.results}
    assert statuses == {"algebroid": "pass", "routes": "skip", "consistency": "pass",
                        "regularity": "pass", "noether": "skip", "structure": "pass",
                        "equations": "skip"}
