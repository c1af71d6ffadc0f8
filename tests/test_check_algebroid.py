"""Check ``algebroid``: structure equations (Appendix C.1, estruc1, estruc2) and closure."""
from __future__ import annotations

import pytest
import sympy as sp

from symvi import SO3, ActionGroupoid, Model
from symvi.checks import check
from symvi.checks.algebroid import algebra_closure, structure_equations
from symvi.groupoids.base import Algebroid


@pytest.mark.parametrize("name", ["pendulum", "rigid_body", "heavy_top", "se3_body",
                                  "heavy_top_rotors_oc"])
def test_bundled_algebroids_satisfy_the_structure_equations(name):
    from symvi.models import get
    result = check(get(name), only=["algebroid"])["algebroid"]
    assert result.status == "pass", result.details


def _top_algebroid() -> Algebroid:
    return ActionGroupoid(SO3(), "G1 G2 G3", lambda q, W: W.T * q).algebroid()


def test_a_flipped_structure_constant_breaks_estruc1_on_the_action_algebroid():
    A = _top_algebroid()
    C = [M.copy() for M in A.structure]
    C[2][0, 1], C[2][1, 0] = -C[2][0, 1], -C[2][1, 0]       # [e1, e2] = −e3 instead of e3
    problems = structure_equations(Algebroid(A.q, A.y, A.ydot, A.anchor, tuple(C)))
    # ρ(e₃) rotates Γ about e₃: the defect 2ρ(e₃) has no G3 component.
    assert [p.split(": ", 1)[1] for p in problems] == [
        "[ρ(e_α), ρ(e_β)] − ρ(⟦e_α, e_β⟧) = 2*G2", "[ρ(e_α), ρ(e_β)] − ρ(⟦e_α, e_β⟧) = -2*G1"]
    assert [p.split(":")[0] for p in problems] == ["estruc1 (α=1, β=2, component G1)",
                                                   "estruc1 (α=1, β=2, component G2)"]


def test_a_left_action_anchor_breaks_estruc1():
    """The anchor of a left action is an anti-homomorphism: estruc1 catches the sign."""
    A = _top_algebroid()
    problems = structure_equations(Algebroid(A.q, A.y, A.ydot, -A.anchor, A.structure))
    assert {p.split(",")[0] for p in problems} == {"estruc1 (α=1", "estruc1 (α=2"}


def test_a_bracket_without_the_jacobi_identity_breaks_estruc2():
    y = sp.symbols("y1:4")
    C = [sp.zeros(3, 3) for _ in range(3)]
    C[2][0, 1], C[2][1, 0] = 1, -1          # [e1, e2] = e3
    C[0][1, 2], C[0][2, 1] = 1, -1          # [e2, e3] = e1
    C[0][2, 0], C[0][0, 2] = 1, -1          # [e3, e1] = e1 (so(3) would have e2)
    problems = structure_equations(Algebroid((), y, y, sp.zeros(0, 3), tuple(C)))
    assert problems == ["estruc2 (α=1, β=2, γ=3, ν=3): cyclic sum = -1"]


def test_broken_antisymmetry_is_named():
    y = sp.symbols("y1:3")
    C = [sp.zeros(2, 2), sp.Matrix([[0, 1], [1, 0]])]
    problems = structure_equations(Algebroid((), y, y, sp.zeros(0, 2), tuple(C)))
    assert problems[0] == "antisymmetry: C^2_12 + C^2_21 = 2"


def test_closure_against_wrong_constants_and_a_non_closing_basis():
    G = SO3()
    assert algebra_closure(G.basis, G.structure_constants) == []
    wrong = dict(G.structure_constants)
    wrong[(0, 1)] = tuple(-c for c in wrong[(0, 1)])
    problems = algebra_closure(G.basis, wrong)
    assert len(problems) == 1 and problems[0].startswith("closure: [E1, E2]")
    # Two elements of so(3) do not close under the bracket: no constants can fix it.
    assert algebra_closure(G.basis[:2], {}) and "[E1, E2]" in algebra_closure(G.basis[:2], {})[0]


def test_a_model_whose_groupoid_declares_wrong_structure_functions_fails():
    class Misdeclared(ActionGroupoid):
        def algebroid(self):
            A = super().algebroid()
            return Algebroid(A.q, A.y, A.ydot, A.anchor, tuple(-C for C in A.structure))

    G = Misdeclared(SO3(), "G1 G2 G3", lambda q, W: W.T * q)
    model = Model(name="misdeclared", groupoid=G, lagrangian=sum(v**2 for v in G.xi) / 2)
    result = check(model, only=["algebroid"])["algebroid"]
    # three brackets, each wrong in the two components of Γ its rotation moves
    assert result.status == "fail" and result.data["violations"] == 6
    assert all("estruc1" in d for d in result.details)
