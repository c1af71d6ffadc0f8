"""`symvi check` on the algebroid itself and on slips in its bracket terms (issue 26).

New ``HandDerived`` targets: ``anchor``, ``structure_functions`` and ``variation`` (the
complete lift). Seeded slips: the paper's complete lift with its indices swapped, and
the fourth-order optimality conditions derived with the opposite sign of every
structure constant (a wrong lift). The report must name exactly the terms that differ —
checked by adding its groups back up to hand − derived — with the scale fixed by the
equations' linear part, not by the majority of terms.
"""
import dataclasses
import re

import pytest
import sympy as sp

from symvi import euler_lagrange_operator
from symvi.checks.equations import HandDerived, compare
from symvi.checks.jets import continuous_equations
from symvi.checks.spaces import symbol_space
from symvi.fixtures import paper_rigid_body as RIGID
from symvi.models import get


def reported_difference(note: str) -> sp.Expr:
    """hand − c·derived as a report states it: Σ over its groups of (hand − right)."""
    total = sp.S.Zero
    body = note.split(": ", 1)[1] if note.startswith("vs derived") or \
        note.startswith("differs") else note
    for group in body.split("; "):
        assert not group.startswith("…"), f"groups left out of the report: {note}"
        group = re.sub(r" \[.*\]$", "", group)
        if group.startswith("missing "):
            total -= sp.sympify(group[len("missing "):])
        elif group.startswith("spurious "):
            total += sp.sympify(group[len("spurious "):])
        else:
            hand, right = re.match(r"(.*) where (.*) is right", group).groups()
            total += sp.sympify(hand) - sp.sympify(right)
    return total


def plain(expr) -> sp.Expr:
    """``expr`` in plain symbols (the report's), expanded."""
    return sp.expand(expr.xreplace({s: sp.Symbol(s.name) for s in expr.free_symbols}))


def negated_lift(model):
    """The continuous optimality conditions of ``model`` derived on its algebroid with every
    structure function's sign flipped: the wrong complete lift's equations."""
    cls = type(model.groupoid)
    original = cls.algebroid

    def flipped(self):
        A = original(self)
        return dataclasses.replace(A, structure=tuple(-C for C in A.structure))
    cls.algebroid = flipped
    try:
        return continuous_equations(model).equations
    finally:
        cls.algebroid = original


def test_the_printed_complete_lift_is_flagged_and_its_swapped_terms_located():
    printed = compare(RIGID.complete_lift(), RIGID.model)
    assert not printed.ok
    eta = sp.symbols("eta1:4")
    Omega = sp.symbols("Omega1:4")
    for i, result in enumerate(printed.equations):
        assert not result.ok and "hand ≈" not in result.message and "eta" in result.message
        assert "_dot" not in result.message, result.message        # η̇ is right: not blamed
        # hand − derived = C η Ω − C Ω η = 2 (η × Ω)_i, all of it, nothing else
        swapped = 2 * sp.Matrix(eta).cross(sp.Matrix(Omega))[i]
        assert sp.expand(reported_difference(result.message) - swapped) == 0, result.message
    assert compare(RIGID.complete_lift(printed=False), RIGID.model).ok
    assert RIGID.complete_lift().name in [h.name for h in RIGID.equations]


def test_the_variation_is_the_one_symvis_euler_lagrange_equations_come_from():
    """Integrating δ∫L by parts with the derived variation (δq = ρη, δy = η̇ + C y η)
    gives −EL(L) of :func:`symvi.euler_lagrange_operator` — on SO(3) and on the heavy
    top's action groupoid, whose anchor and bracket depend on the base point."""
    for name in ("rigid_body", "heavy_top"):
        model = get(name)
        A = model.groupoid.algebroid()
        m, n = len(A.q), len(A.y)
        space = symbol_space(HandDerived("v", "variation", [0] * (m + n)), model, None, None)
        dq, dy = space.derived[:m], space.derived[m:]
        eta = [space.names[f"eta{a + 1}"] for a in range(n)]
        eta_dot = [space.names[f"eta{a + 1}_dot"] for a in range(n)]
        L = model.lagrangian
        first = sum(sp.diff(L, q) * d for q, d in zip(A.q, dq)) + \
            sum(sp.diff(L, y) * d for y, d in zip(A.y, dy))
        EL = euler_lagrange_operator(A, L)
        for b in range(n):
            assert sp.diff(first, eta_dot[b]) == sp.diff(L, A.y[b])
            # δS = ∫ Σ_b (∂first/∂η_b − d/dt ∂L/∂y_b) η_b = −∫ EL_b η_b
            integrated = sp.diff(first, eta[b]) - _ddt(A, sp.diff(L, A.y[b]))
            assert sp.simplify(integrated + EL[b]) == 0, (name, b)


def _ddt(A, F):
    """d/dt F along q̇ = ρ(q)y, ẏ = ydot."""
    qdot = A.anchor * sp.Matrix(A.y) if A.q else sp.zeros(0, 1)
    return sum((sp.diff(F, a) * b for a, b in zip(A.q, qdot)), sp.S.Zero) + \
        sum((sp.diff(F, a) * b for a, b in zip(A.y, A.ydot)), sp.S.Zero)


def test_anchor_and_structure_functions_targets():
    """SO(3): ⟦a, b⟧ = a × b, and b × a is flagged as its negative; the heavy top's
    anchor Γ̇ = Γ × Ω (the vertical seen from the body)."""
    rigid = get("rigid_body_oc")
    a, b = sp.Matrix(sp.symbols("a1:4")), sp.Matrix(sp.symbols("b1:4"))
    assert compare(HandDerived("so(3)", "structure_functions", list(a.cross(b))), rigid).ok
    swapped = compare(HandDerived("so(3) swapped", "structure_functions",
                                  list(b.cross(a))), rigid)
    assert not swapped.ok          # a value: −1 × the bracket is not the bracket
    assert all(r.message == "equal up to the factor -1: hand = -1 × derived"
               for r in swapped.equations), [r.message for r in swapped.equations]
    top = get("heavy_top")
    Gamma, Omega = sp.Matrix(sp.symbols("Gamma1:4")), sp.Matrix(sp.symbols("Omega1:4"))
    assert compare(HandDerived("Γ̇ = Γ × Ω", "anchor", list(Gamma.cross(Omega))), top).ok
    assert not compare(HandDerived("Γ̇ = Ω × Γ", "anchor", list(Omega.cross(Gamma))), top).ok
    with pytest.raises(ValueError, match="compares values"):
        HandDerived("x", "anchor", [0], mode="equations")


@pytest.mark.parametrize("name, rows", [("rigid_body_oc", 3), ("heavy_top_rotors_oc", 3)])
def test_a_wrong_lift_in_the_optimality_conditions_is_located_term_by_term(name, rows):
    """The conditions derived with the opposite sign of the structure constants differ in
    30 of 57 terms per rigid-body row (15 of 29, 15 of 29, 16 of 31 heavy-top Ω rows):
    the majority of terms would pick the scale −1 and blame the other ones. The linear
    part fixes it at +1, and the groups add up to exactly hand − derived."""
    model = get(name)
    right = continuous_equations(model).equations
    wrong = negated_lift(model)
    result = compare(HandDerived("wrong lift", "euler_lagrange", list(wrong)), model)
    assert not result.ok
    for i, row in enumerate(result.equations[:len(right)]):
        difference = plain(wrong[i] - right[i])
        if difference == 0:
            assert row.ok, row.message
            continue
        assert i < rows and not row.ok
        assert row.message.startswith(f"vs derived eq. {i + 1}: "), row.message     # no × −1
        assert sp.expand(reported_difference(row.message) - difference) == 0, row.message


def test_a_display_times_minus_one_is_recovered_not_blamed():
    model = get("heavy_top_rotors_oc")
    right = continuous_equations(model).equations
    result = compare(HandDerived("negated", "euler_lagrange", [-e for e in right]), model)
    assert result.ok, result.details()
    assert all(r.message.endswith("× -1") for r in result.equations[:3]), \
        [r.message for r in result.equations]


@pytest.mark.parametrize("name, target", [("rigid_body_oc", "controls"),
                                          ("heavy_top_rotors_oc", "constraints")])
def test_a_wrong_lift_in_the_first_order_controlled_equations(name, target):
    """EL(L) on the algebroid with the structure functions' sign flipped: u = IΩ̇ − Ω×IΩ
    for the rigid body's torques, the heavy top's unactuated rows likewise; the report
    names exactly the bracket terms, at scale +1."""
    from symvi.declaration.control import euler_lagrange_operator as EL
    model = get(name)
    system = model.control_system
    A = model.groupoid.algebroid()
    wrong = EL(dataclasses.replace(A, structure=tuple(-C for C in A.structure)),
               system.lagrangian)
    right = EL(A, system.lagrangian)
    rows = list(system.unactuated(len(A.y)) if target == "constraints" else system.actuated)
    u = sp.symbols(f"u1:{len(rows) + 1}", real=True)
    exprs = [wrong[r] - (u[k] if target == "controls" else 0) for k, r in enumerate(rows)]
    result = compare(HandDerived("wrong lift", target, exprs), model)
    assert not result.ok
    for k, (row, r) in enumerate(zip(result.equations, rows)):
        difference = plain(wrong[r] - right[r])
        assert row.message.startswith(f"vs derived eq. {k + 1}: "), row.message
        assert sp.expand(reported_difference(row.message) - difference) == 0, row.message


def test_a_wrong_display_with_permuted_rows_is_paired_back():
    """The rigid body's wrong-lift conditions with their rows reversed: each row is told
    against its own equation (the pairing recovered), with the same exact differences."""
    model = get("rigid_body_oc")
    right = continuous_equations(model).equations
    wrong = negated_lift(model)
    rows = [2, 1, 0]
    result = compare(HandDerived("reversed", "euler_lagrange", [wrong[r] for r in rows]),
                     model)
    for row, r in zip(result.equations, rows):
        assert row.message.startswith(f"vs derived eq. {r + 1}: "), row.message
        assert sp.expand(reported_difference(row.message) - plain(wrong[r] - right[r])) == 0


def test_lift_target_holds_the_complete_and_the_vertical_lift():
    """On the heavy top (anchor Γ × ·, base point dependent): the complete lift's six
    components and then the vertical lift's; a vertical lift written with η̇ is flagged."""
    model = get("heavy_top")
    Gamma, Omega = sp.Matrix(sp.symbols("Gamma1:4")), sp.Matrix(sp.symbols("Omega1:4"))
    eta, eta_dot = sp.Matrix(sp.symbols("eta1:4")), sp.Matrix(sp.symbols("eta1_dot eta2_dot "
                                                                          "eta3_dot"))
    complete = list(Gamma.cross(eta)) + list(eta_dot + Omega.cross(eta))
    vertical = [0, 0, 0] + list(eta)
    assert compare(HandDerived("η^C, η^V", "lift", complete + vertical), model).ok
    assert compare(HandDerived("η^V", "lift", list(eta), select=(9, 10, 11)), model).ok
    wrong = compare(HandDerived("η^V", "lift", list(eta_dot), select=(9, 10, 11)), model)
    assert not wrong.ok and all("eta" in r.message for r in wrong.equations)
