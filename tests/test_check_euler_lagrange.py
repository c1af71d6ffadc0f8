"""Check ``equations``, targets ``euler_lagrange`` and ``discrete_action`` (issue 5, item 7).

``euler_lagrange``: the continuous (constrained) Euler–Lagrange equations EL_r(L + λ_AΦ^A)
= 0, Φ^A = 0 of §3.3.2, written by hand in functions of time or in named jets. The
paper's display, applied to the heavy top's L̃ and Φ, reproduces ERRATA 8 (−λ_A ∂Φ^A/∂y^α
where −d/dt(λ_A ∂Φ^A/∂y^α) is right), located in each equation whose Φ depends on y.
``discrete_action``: Σ_k L_d over a trajectory; the paper's sum to k = N−1 reproduces the
sum range of ERRATA 9.
"""
from __future__ import annotations

import pytest
import sympy as sp

from symvi.checks.equations import HandDerived, compare
from symvi.fixtures import paper_heavy_top_rotors as HEAVY
from symvi.fixtures import paper_rigid_body as RIGID
from symvi.checks.jets import continuous_equations, derivative_name
from symvi.models import get

t = sp.Symbol("t")
theta = sp.Function("theta")(t)
m, l, g = sp.symbols("m l g", positive=True)


def pendulum(expressions, **kw):
    return compare(HandDerived("hand", "euler_lagrange", expressions, **kw), get("pendulum"))


def test_derivative_names():
    assert [derivative_name("Omega1", k) for k in range(6)] == [
        "Omega1", "Omega1_dot", "Omega1_ddot", "Omega1_dddot", "Omega1_d4", "Omega1_d5"]


def test_pendulum_in_functions_of_time_and_named_jets():
    assert pendulum([m * l ** 2 * theta.diff(t, 2) + m * g * l * sp.sin(theta)]).ok
    named = sp.Symbol("theta_ddot") + g / l * sp.sin(sp.Symbol("theta"))   # rescaled
    assert pendulum([named]).ok


def test_pendulum_wrong_sign_is_named():
    result = pendulum([m * l ** 2 * theta.diff(t, 2) - m * g * l * sp.sin(theta)])
    assert not result.ok
    assert "-g*l*m*sin(theta) where g*l*m*sin(theta) is right (wrong sign)" in \
        result.details()[0]


def test_constrained_equations_are_the_multiplier_rule():
    """EL₂(L̃ + λΦ) on the heavy top: the θ₁ row is −J₁ d/dt(u₁-row) with u₁ = J₁(Ω̇₁+θ̈₁),
    d²/dt² of ∂L̂/∂θ̈₁ (the paper's J₁(Ω⃛₁ + θ₁⁽⁴⁾) + λ̈₁ …); Φ^A close the system."""
    eqs = continuous_equations(HEAVY.model)
    assert len(eqs.equations) == 5 + 3
    J1 = HEAVY.J1
    s = {n: sp.Symbol(n) for n in ("Omega1_dddot", "theta1_d4", "lambda1_ddot")}
    row = sp.expand(eqs.equations[3])
    assert row.coeff(s["theta1_d4"]) == -J1 ** 2
    assert row.coeff(s["Omega1_dddot"]) == -J1 ** 2
    assert row.coeff(s["lambda1_ddot"]) == -J1
    plain = [e.xreplace({v: sp.Symbol(v.name) for v in e.free_symbols})
             for e in eqs.equations[5:] + tuple(HEAVY.model.constraints)]
    assert all(sp.expand(a - b) == 0 for a, b in zip(plain[:3], plain[3:]))


@pytest.fixture(scope="module")
def errata_8():
    return [compare(HandDerived("x", "euler_lagrange", HEAVY.optimality_conditions(printed),
                                labels=HEAVY._LABELS), HEAVY.model) for printed in (True, False)]


def test_errata_8_corrected_display_agrees(errata_8):
    assert errata_8[1].ok


def test_errata_8_printed_display_is_located(errata_8):
    printed = {r.label: r for r in errata_8[0].equations}
    assert not errata_8[0].ok
    # Φ^A = 0 and nothing else agree
    assert [label for label, r in printed.items() if r.ok] == ["Φ¹", "Φ²", "Φ³"]
    # θ₁: λ_A ∂Φ^A/∂θ̇₁ = J₁(λ₃Ω₂ − λ₂Ω₃) is printed underived
    assert printed["θ₁"].message == (
        "vs derived eq. 4 × -1: J1*(Omega2*lambda3 - Omega3*lambda2) where J1*(Omega2*lambda3_dot"
        " + Omega2_dot*lambda3 - Omega3*lambda2_dot - Omega3_dot*lambda2) is right")
    # e₁: the λ̇ terms are missing, and λ multiplies Ω where it should multiply Ω̇
    message = printed["e₁ (Ω₁)"].message
    assert "missing I3bar*Omega3*lambda2_dot" in message
    assert "Omega3*lambda2*(I3bar - gamma1) where Omega3_dot*lambda2*(I3bar - gamma1)" in message


def test_errata_9_sum_range():
    printed, corrected = RIGID.equations[-2:]
    result = compare(printed, RIGID.model)
    assert not result.ok and result.undefined == ("Omega1_4", "Omega2_4", "Omega3_4")
    assert result.equations[0].message == (
        "sums 4 windows (k = 0 … 3) where a trajectory of 4 elements has 3 (k = 0 … 2): it "
        "is the action of 5 elements")
    assert compare(corrected, RIGID.model).ok


def spline_action(windows: int, scale=1):
    """Σ_{k<windows} h/2 |(q_{k+2} − 2q_{k+1} + q_k)/h²|² for q = (x, y), nodes x_k → x_k."""
    h = sp.Symbol("h")
    x, y = (sp.symbols(f"{c}_0:{windows + 2}") for c in "xy")
    return sum(scale * h / 2 * ((c[k + 2] - 2 * c[k + 1] + c[k]) / h ** 2) ** 2
               for k in range(windows) for c in (x, y))


@pytest.mark.parametrize("windows, ok", [(2, True), (3, False)])
def test_discrete_action_of_a_second_order_pair_model(windows, ok):
    """Cubic spline, three elements (nodes q_0 … q_3): two windows of L_d."""
    hand = HandDerived("spline", "discrete_action", [spline_action(windows)], elements=3)
    result = compare(hand, get("cubic_spline"))
    assert result.ok is ok
    if not ok:
        assert result.equations[0].message.startswith("sums 3 windows (k = 0 … 2) where a "
                                                      "trajectory of 3 elements has 2")


def test_discrete_action_factor_is_named():
    hand = HandDerived("spline", "discrete_action", [spline_action(2, 2)], elements=3)
    assert compare(hand, get("cubic_spline")).equations[0].message.startswith(
        "equal up to the factor 2")


def test_discrete_action_with_one_window_too_few():
    """Two elements of a second-order model: one window; a hand sum with none is not
    recounted below the model's order."""
    hand = HandDerived("spline", "discrete_action", [spline_action(1)], elements=2)
    assert compare(hand, get("cubic_spline")).ok
    wrong = HandDerived("spline", "discrete_action", [sp.Integer(0)], elements=2)
    result = compare(wrong, get("cubic_spline"))
    assert not result.ok and result.equations[0].message.startswith("differs")


def test_discrete_action_errors():
    with pytest.raises(ValueError, match="unknown target"):
        HandDerived("x", "discrete_actions", [0])
    result = compare(HandDerived("x", "discrete_action", [0], elements=1), RIGID.model)
    assert not result.ok and "a trajectory of 1 elements has no window of 2" in result.summary
