"""Check ``consistency`` (issue 5, item 3) and the expansion beyond the pair groupoid.

Sampling a smooth curve — pair nodes q(t + jh), group increments ξ_i = y(t + (i + ½ − c)h)
at the middle of their element, action base points x_0 = q(t − ch) and x_{j+1} =
β(x_j, ξ_j), multipliers at their window's middle node — the residual at the middle node of
every bundled model expands as R = h·E + h³·c₃ + …, where E is the variational derivative of
the action: E(L) = ∂L/∂q − d/dt ∂L/∂q̇ (+ d²/dt² ∂L/∂q̈) on the pair groupoid, E = −EL_r(L)
on an algebroid (EL₁ of Appendix C.2; EL₂ with P = ∂L̃/∂y − d/dt ∂L̃/∂ẏ), E(L̃ + λ_A Φ^A)
for constrained models, whose discrete constraints give h·Φ + O(h³).

1. The continuous operators: EL₁ agrees with symvi.declaration.control.euler_lagrange_operator; EL₂ is
   −E(L) on TQ and −(d/dt + Ω×)(u̇ + Df(Ω)ᵀu) on so(3) (ERRATA.md, "Agree"); hand-written
   rigid body and heavy top equations.
2. The expansion against the residual evaluated in exact / 60-digit arithmetic at two
   step sizes: what is left after the computed terms through h³ is O(h⁴) or O(h⁵).
3. The check on the bundled models (pass, order 2, bounded time), and negative controls
   that it must catch and name: the swapped signs of ERRATA item 7, an action groupoid
   whose left variation forgets to move the base point, discrete Lagrangians that do not
   match the continuous one (wrong factor, wrong relative sign), a wrong constraint.
"""
from __future__ import annotations

import random

import pytest
import sympy as sp
from sympy.core.function import AppliedUndef

from curves import curve as _f, derivative as _d, parameters as _params
from symvi import (SO3, ActionGroupoid, Groupoid, MatrixLieGroup, Model, PairGroupoid,
                   ProductGroupoid, h)
from symvi.checks import Context, check, run_check
from symvi.checks.expansions import (TIME, check_consistency, constraint_expansion, euler_lagrange,
                               euler_lagrange_algebroid, expand_stencil, residual_expansion,
                               sample_stencil)
from symvi.declaration.control import euler_lagrange_operator
from symvi.derivation.derive import derive
from symvi.discretisation.discretise import discretise
from symvi.models import get
from symvi.discretisation.rules import Rule

t = TIME


def _zero(expr):
    return sp.simplify(sp.expand(expr)) == 0


def _equal(a, b):
    return all(_zero(u - v) for u, v in zip(a, b))


def _to_symbols(expr, groupoid):
    """Functions of t → the algebroid's symbols (q, y, ẏ): the form of
    :func:`symvi.declaration.control.euler_lagrange_operator`."""
    a = groupoid.algebroid()
    mapping = {}
    for q, y, v in zip(a.q, a.y, a.ydot):  # pair-type blocks: y = q̇
        if str(y) == f"{q}_dot":
            mapping |= {_d(_f(str(q))): y, _d(_f(str(q)), 2): v}
    for q in a.q:
        mapping[_f(str(q))] = q
    for y, v in zip(a.y, a.ydot):
        mapping |= {_d(_f(str(y))): v, _f(str(y)): y}
    return sp.sympify(expr).xreplace(mapping)


# ---------------------------------------------------------------------------------------
# 1. The continuous operators
# ---------------------------------------------------------------------------------------
def _rotor_top():
    """A Lagrangian on the product of the heavy-top action groupoid and a pair groupoid."""
    top = ActionGroupoid(SO3(), "Gamma1 Gamma2 Gamma3", lambda q, W: W.T * q)
    G = ProductGroupoid(top, PairGroupoid("theta"))
    (W1, W2, W3), (th,), (w,) = top.xi, G.factors[1].q, G.factors[1].qdot
    a, b, c, J, k = sp.symbols("a b c J k", positive=True)
    L = (a * W1**2 + b * W2**2 + c * W3**2) / 2 + J * W3 * w + J * w**2 / 2 \
        - k * top.q[2] - k * sp.cos(th) * top.q[0]
    return G, L


@pytest.mark.parametrize("name", ["rigid_body", "planar_body", "heavy_top", "pendulum",
                                  "product"])
def test_first_order_operator_is_that_of_appendix_c2(name):
    if name == "product":
        G, L = _rotor_top()
    else:
        model = get(name)
        G, L = model.groupoid, model.lagrangian
    ours = euler_lagrange_algebroid(G, L, 1).applyfunc(lambda e: _to_symbols(e, G))
    assert _equal(ours, euler_lagrange_operator(G.algebroid(), L))


@pytest.mark.parametrize("name", ["cubic_spline", "spline_potential", "double_pendulum"])
def test_operators_on_TQ_are_minus_the_variational_derivative(name):
    model = get(name)
    ours = euler_lagrange_algebroid(model.groupoid, model.lagrangian, model.order)
    assert _equal(ours, -euler_lagrange(model))


def test_second_order_euler_poincare_on_so3():
    """rigid_body_oc: L̃ = ½|u|², u = Ω̇ − f(Ω), f_i = P_i Ω_j Ω_k (ERRATA 1). EL₂(L̃) is
    −(d/dt + Ω×)(u̇ + Df(Ω)ᵀu)."""
    model = get("rigid_body_oc")
    I1, I2, I3 = (_params(model)[k] for k in ("I1", "I2", "I3"))
    W = sp.Matrix([_f(f"Omega{i}") for i in (1, 2, 3)])
    P = [(I2 - I3) / I1, (I3 - I1) / I2, (I1 - I2) / I3]
    f = sp.Matrix([P[0] * W[1] * W[2], P[1] * W[2] * W[0], P[2] * W[0] * W[1]])
    u = W.diff(t) - f
    Df = f.jacobian(W)
    v = u.diff(t) + Df.T * u
    expected = -(v.diff(t) + W.cross(v))
    ours = euler_lagrange_algebroid(model.groupoid, model.lagrangian, 2)
    assert _equal(ours, expected)
    assert _equal(euler_lagrange(model), -expected)    # no constraints: E = −EL₂


def test_hand_written_rigid_body_and_heavy_top():
    """E = −(IΩ̇ + Ω×IΩ) (Euler); heavy top −(IΩ̇ + Ω×IΩ + mgl χ×Γ), Γ̇ = Γ×Ω."""
    rb, ht = get("rigid_body"), get("heavy_top")
    W = sp.Matrix([_f(f"Omega{i}") for i in (1, 2, 3)])
    Gamma = sp.Matrix([_f(f"Gamma{i}") for i in (1, 2, 3)])
    P = _params(ht)
    inertia = sp.diag(P["I1"], P["I2"], P["I3"])
    chi = sp.Matrix([P["chi1"], P["chi2"], P["chi3"]])
    euler = inertia * W.diff(t) + W.cross(inertia * W)
    assert _equal(euler_lagrange(rb), -euler)
    assert _equal(euler_lagrange(ht), -(euler + P["mgl"] * chi.cross(Gamma)))


def test_multipliers_enter_under_the_time_derivative():
    """ERRATA 8: the constrained equations carry −d/dt(∂L̃/∂y + λ_A ∂Φ^A/∂y); for
    cart_pole_oc (TQ) E(L̃ + λΦ) − E(L̃) = E(λ(t) Φ) with λ differentiated."""
    model = get("cart_pole_oc")
    with_l = euler_lagrange(model)
    without = euler_lagrange(model, multipliers=False)
    lam = _f("lambda0")
    G = model.groupoid
    phi = model.constraints[0]
    x, th = _f("x"), _f("theta")
    to_f = {G.q[0]: x, G.q[1]: th, G.qdot[0]: _d(x), G.qdot[1]: _d(th),
            G.qddot[0]: _d(x, 2), G.qddot[1]: _d(th, 2)}
    term = [sp.diff(lam * phi, s).xreplace(to_f) for s in G.q]
    term = [term[i] - sp.diff(sp.diff(lam * phi, G.qdot[i]).xreplace(to_f), t)
            + sp.diff(sp.diff(lam * phi, G.qddot[i]).xreplace(to_f), t, 2) for i in range(2)]
    assert _equal(with_l - without, term)
    assert with_l.has(_d(lam, 2))


# ---------------------------------------------------------------------------------------
# 2. The expansion against the residual evaluated exactly
# ---------------------------------------------------------------------------------------
def _defects(model, dm, hs=(sp.Rational(1, 200), sp.Rational(1, 400))):
    """|R(h) − Σ_{p ≤ 3} c_p h^p| at two step sizes, R evaluated on the sampled stencil
    (exact rational arithmetic for the Cayley map, 60 digits otherwise)."""
    kernel = dm.kernel("stencil" if model.constraints else "step")
    R = dict(kernel.outputs)["residual"]
    r = dm.order
    windows, count = (r + 1, dm.constraint_count) if model.constraints else (0, 0)
    expansion = residual_expansion(model, derived=dm)
    assert expansion.through == 3
    samples = sample_stencil(model.groupoid, kernel.z, dm.step, elements=2 * r, centre=r,
                             order=r, degree=8, windows=windows, multipliers=count)
    atoms = set()
    for e in list(samples.values()) + [e for _, M in expansion.terms for e in M]:
        atoms |= e.atoms(sp.Derivative) | e.atoms(AppliedUndef)
    rng = random.Random(5)
    values = {a: sp.Rational(rng.randint(-900, 900), 1000) for a in atoms}
    params = {s: sp.Rational(v).limit_denominator(1000) for s, v in model.parameters}
    defects = []
    for step in hs:
        env = {dm.step: step} | params
        env |= {s: e.xreplace(values).xreplace(env) for s, e in samples.items()}
        for s, e in kernel.definitions:
            env[s] = e.xreplace(env)
        for i, e in enumerate(R):
            predicted = sum(M[i].xreplace(values).xreplace(params) * step**p
                            for p, M in expansion.terms)
            defects.append((step, abs(sp.N(e.xreplace(env) - predicted, 60))))
    return [max(d for s, d in defects if s == step) for step in hs]


@pytest.mark.parametrize("name", ["rigid_body", "rigid_body_exp", "so3_cubic", "heavy_top",
                                  "cart_pole_oc", "spline_potential"])
def test_expansion_is_exact_through_h3(name, derived):
    """Halving h divides what the terms through h³ leave by 2⁴ (x_0 at the first node
    breaks the time symmetry of an action groupoid's sampling at h⁴) or 2⁵."""
    coarse, fine = _defects(get(name), derived(name))
    assert coarse / fine > 14, (coarse, fine)


@pytest.mark.parametrize("name", ["pendulum", "double_pendulum", "spline_potential"])
def test_algebroid_sampling_reproduces_the_pair_expansion(name, derived):
    """On TQ the general expansion (jets q, y^{(k)} with q̇ = y) gives the pair groupoid's
    terms, written with the same functions."""
    model, dm = get(name), derived(name)
    kernel = dm.kernel("step")
    general = expand_stencil(dict(kernel.outputs)["residual"], kernel.z, model.groupoid,
                             dm.step, elements=2 * dm.order, centre=dm.order,
                             order=dm.order, through=3)
    pair = residual_expansion(model, derived=dm)
    assert [p for p, _ in general.terms] == [p for p, _ in pair.terms] == [1, 3]
    for (_, A), (_, B) in zip(general.terms, pair.terms):
        assert _equal(A, B)


@pytest.mark.parametrize("name", ["rigid_body", "planar_body_exp", "so3_cubic", "heavy_top",
                                  "spherical_pendulum_exp"])
def test_lie_and_action_residuals_are_consistent(name, derived):
    model = get(name)
    report = check_consistency(model, derived=derived(name))
    assert (report.power, report.sign, report.order) == (1, 1, 2)
    assert _equal(report.expansion.leading, euler_lagrange(model))
    assert report.constraints is None


def test_constrained_residual_and_constraints_are_consistent(derived):
    model = get("heavy_top_rotors_oc")
    report = check_consistency(model, derived=derived("heavy_top_rotors_oc"))
    assert (report.power, report.sign, report.order) == (1, 1, 2)
    c = report.constraints
    assert (c.power, c.sign, c.order) == (1, 1, 2)
    # the expected equations carry the multipliers and their second derivatives
    assert report.expected.has(_d(_f("lambda2"), 2))
    # constraint row 2 is the top's third equation: Ī₃Ω̇₃ + … = 0 (ERRATA 4, eq. 3)
    I3 = _params(model)["I3bar"]
    assert c.expansion.leading[2].coeff(_d(_f("Omega3"))) == I3


# ---------------------------------------------------------------------------------------
# 3. The check
# ---------------------------------------------------------------------------------------
def test_report_is_json():
    report = check(get("so3_cubic"), only=["consistency"])
    assert '"order": 2' in report.to_json()
    assert "EL₂(L̃)" in report["consistency"].summary


def test_discrete_lagrangian_only_is_skipped():
    G = PairGroupoid("q")
    (q0,), (q1,) = G.nodes(2)
    model = Model(name="direct", groupoid=G, order=1,
                  discrete_lagrangian=(q1 - q0)**2 / (2 * h) - h * (q0**2 + q1**2) / 4)
    result = check(model, only=["consistency"])["consistency"]
    assert result.status == "skip" and "discrete Lagrangian only" in result.summary


def test_groupoid_that_cannot_be_sampled_is_skipped():
    """A groupoid that does not say how its fibre is sampled along a curve (no
    ``fibre_sampling``) is skipped, naming it."""
    class Odd(PairGroupoid):
        def fibre_sampling(self):
            return Groupoid.fibre_sampling(self)

        def __repr__(self):
            return "Odd"
    G = Odd("q")
    model = Model(name="odd", groupoid=G, lagrangian=G.qdot[0]**2 / 2 - G.q[0]**2 / 2)
    result = check(model, only=["consistency"])["consistency"]
    assert result.status == "skip" and "sample the fibre of Odd" in result.summary


def _left_point(g, xs, fs, step):
    """L_d = h L(q₀, (q₁ − q₀)/h): not symmetric, so R = h·E + O(h²) (order 1)."""
    (q0,), (q1,) = g.window_nodes(xs, fs)
    return [(sp.Integer(1), g.point([q0], [(q1 - q0) / step]))]


@pytest.mark.parametrize("declared, status", [(2, "fail"), (1, "pass")])
def test_rule_falling_short_of_its_consistency_order_fails(declared, status):
    """A rule owns its quadrature and its order: the left-point rule measured at order 1
    fails when it declares 2 and passes when it declares 1."""
    rule = Rule(f"left_point_{declared}", 1, "L_d = h L(q0, (q1-q0)/h)", _left_point,
                consistency_order=declared)

    class LeftPair(PairGroupoid):
        def rules(self, order):
            return (rule,) if order == 1 else super().rules(order)
    G = LeftPair("q")
    (q,), (v,) = G.q, G.qdot            # a position-dependent mass: no symmetric accident
    model = Model(name=f"left_{declared}", groupoid=G, discretisation=rule.name,
                  lagrangian=(1 + q**2) * v**2 / 2 - q**2 / 2)
    result = check(model, only=["consistency"])["consistency"]
    assert result.status == status, result.summary
    assert result.data["order"] == 1
    if status == "fail":
        assert "order 1, below the order 2 of the rule 'left_point_2'" in result.summary


class SwappedSigns(MatrixLieGroup):
    """ERRATA item 7: the paper's final display of §2, (dτ⁻¹_{hξ_k})*μ_k −
    (dτ⁻¹_{−hξ_{k+1}})*μ_{k+1} = 0, with the ± of the trivialisations swapped."""

    def right(self, x, f, h):
        return self.dtau_inv([h * v for v in f]) / h

    def left(self, x, f, h):
        return -self.dtau_inv([-h * v for v in f]) / h


def _rigid_body(G, name):
    W = G.xi
    I1, I2, I3 = sp.symbols("I1 I2 I3", positive=True)
    return Model(name=name, groupoid=G,
                 lagrangian=(I1 * W[0]**2 + I2 * W[1]**2 + I3 * W[2]**2) / 2,
                 parameters={I1: 1.0, I2: 2.0, I3: 3.0})


def test_swapped_signs_of_errata_7_are_caught():
    G = SwappedSigns(SO3().basis, "Omega1 Omega2 Omega3", "SO3swapped")
    result = check(_rigid_body(G, "swapped"), only=["consistency"])["consistency"]
    assert result.status == "fail"
    assert "not ±h^1·E in Omega1, Omega2, Omega3" in result.summary
    # the leading term is −(IΩ̇ − Ω×IΩ): the Ω×IΩ term of Euler's equations has the
    # wrong sign, so the difference is twice it
    text = "\n".join(result.details)
    assert "component Omega1 (row 0)" in text
    assert "minus E_0 = -2*I2*Omega2*Omega3 + 2*I3*Omega2*Omega3" in text
    assert "leading coefficient: -I1*Omega1' - I2*Omega2*Omega3 + I3*Omega2*Omega3" in text


class FrozenBase(ActionGroupoid):
    """An action groupoid whose left variation forgets the infinitesimal action on q."""

    def left(self, x, f, h):
        return sp.Matrix.vstack(sp.zeros(self.source_dim, self.fibre_dim),
                                self.group.left((), f, h))


def test_action_groupoid_without_base_motion_is_caught():
    ht = get("heavy_top")
    G = FrozenBase(SO3(), "Gamma1 Gamma2 Gamma3", lambda q, W: W.T * q, label="frozen")
    model = Model(name="frozen", groupoid=G, lagrangian=ht.lagrangian,
                  parameters=dict(ht.parameters))
    result = check(model, only=["consistency"])["consistency"]
    assert result.status == "fail"
    # the gravity torque mgl χ×Γ is the difference, in every component
    text = "\n".join(result.details)
    assert "-Gamma2*chi3*mgl + Gamma3*chi2*mgl" in text
    assert "Gamma1*chi3*mgl - Gamma3*chi1*mgl" in text


def _direct_so3_cubic(scale):
    """so3_cubic's L̃ = ½|ξ̇|² discretised by hand, ξ̇ ≈ (ξ₁ − ξ₀)/(scale·h)."""
    G = SO3()
    xi0, xi1 = sp.Matrix(G.discrete_symbols(2)[:3]), sp.Matrix(G.discrete_symbols(2)[3:])
    rate = (xi1 - xi0) / (scale * h)
    return Model(name=f"cubic_{scale}", groupoid=G, order=2,
                 discrete_lagrangian=h * rate.dot(rate) / 2)


def test_discrete_lagrangian_inconsistent_with_the_declared_one_is_caught(derived):
    """The check compares the derivation it is handed with the model's continuous
    Lagrangian: here so3_cubic's, against the derivation of an L_d whose ξ̇ is half
    the rate — the fourth-order term comes out a quarter of what it should be."""
    ctx = Context(get("so3_cubic"))
    ctx.__dict__["derived"] = derive(discretise(_direct_so3_cubic(2)))
    result = run_check("consistency", ctx)
    assert result.status == "fail"
    assert result.data["power"] == 1
    text = "\n".join(result.details)
    # E = Ω⃛ + Ω×Ω̈ (EL₂ = −(d/dt + Ω×)Ω̈); the leading term is a quarter of it
    assert "leading h^1 coefficient minus E_0 = -3*Omega1'''/4" in text
    # and with the right rate it is consistent
    ctx.__dict__["derived"] = derive(discretise(_direct_so3_cubic(1)))
    assert run_check("consistency", ctx).status == "pass"


def test_discrete_models_against_a_continuous_reference():
    """check_consistency(model, lagrangian_model=…) for discrete Lagrangians on a group and
    an action groupoid: the right rule passes, a flipped potential is caught."""
    cubic = get("so3_cubic")
    good = check_consistency(_direct_so3_cubic(1), lagrangian_model=cubic)
    assert (good.power, good.sign, good.order) == (1, 1, 2)
    bad = check_consistency(_direct_so3_cubic(2), lagrangian_model=cubic)
    assert bad.power == 1 and not bad.consistent

    ht = get("heavy_top")
    G = ht.groupoid
    P = _params(ht)
    W, Gamma = sp.Matrix(G.group.discrete_symbols(1)), sp.Matrix(G.q)
    chi = sp.Matrix([P["chi1"], P["chi2"], P["chi3"]])
    kinetic = (P["I1"] * W[0]**2 + P["I2"] * W[1]**2 + P["I3"] * W[2]**2) / 2
    for sign, consistent in ((-1, True), (1, False)):
        Ld = h * (kinetic + sign * P["mgl"] * chi.dot(Gamma))
        model = Model(name="top", groupoid=G, order=1, discrete_lagrangian=Ld,
                      parameters=dict(ht.parameters))
        report = check_consistency(model, lagrangian_model=ht)
        assert report.consistent is consistent
        assert (report.power, report.order) == (1, 2)


def test_wrong_constraint_is_caught():
    """A constrained model whose discrete constraint is not h·Φ: the check names it."""
    model = get("cart_pole_oc")
    G = model.groupoid
    # declare the same problem with a constraint scaled on one term only
    phi = model.constraints[0]
    wrong = phi + G.qddot[0]
    broken = Model(name="broken", groupoid=G, lagrangian=model.lagrangian,
                   parameters=dict(model.parameters), constraints=[wrong])
    ctx = Context(model)
    ctx.__dict__["derived"] = derive(discretise(broken))
    result = run_check("consistency", ctx)
    assert result.status == "fail"
    assert "discrete constraints" in result.summary
    assert "constraint component Φ0 (row 0)" in "\n".join(result.details)
    assert "x''" in "\n".join(result.details)


def test_constraint_expansion_alone():
    model = get("rigid_body_oc")
    with pytest.raises(Exception, match="no constraints"):
        constraint_expansion(model)


def test_multipliers_zero_leaves_the_second_order_residual_of_L_tilde(derived):
    """With λ = 0 the stencil residual of a constrained model is that of L̃ alone."""
    model = get("cart_pole_oc")
    report = check_consistency(model, derived=derived("cart_pole_oc"), multipliers=False)
    assert (report.power, report.sign, report.order) == (1, 1, 2)
    assert not report.expected.has(_f("lambda0"))
