"""Check ``algebroid``: the structure equations of the Lie algebroid (paper Appendix C.1,
eqs. ``estruc1``, ``estruc2``) and the closure of every matrix Lie algebra's basis.

In coordinates (q^i) and a basis of sections e_α, with anchor ρ(e_α) = ρ^i_α ∂/∂q^i and
bracket ⟦e_α, e_β⟧ = C^γ_{αβ} e_γ, the structure functions must satisfy

* antisymmetry, C^γ_{αβ} = −C^γ_{βα};
* ``estruc1`` (the anchor is a bracket homomorphism):
  ρ^j_α ∂ρ^i_β/∂q^j − ρ^j_β ∂ρ^i_α/∂q^j = ρ^i_γ C^γ_{αβ};
* ``estruc2`` (Jacobi identity): Σ_cyclic(α,β,γ) [ρ^i_α ∂C^ν_{βγ}/∂q^i + C^ν_{αμ} C^μ_{βγ}] = 0.

For a matrix Lie group the commutator of two basis matrices must lie in the span of the
basis with the declared constants, [E_a, E_b] = C^c_{ab} E_c. Each violation is named by
its equation, its indices (1-based, as in the paper) and the non-zero left-hand side.
"""
from __future__ import annotations

from itertools import combinations
from typing import Sequence

import sympy as sp

from ..groupoids.base import Algebroid, Groupoid
from ..groupoids.lie import MatrixLieGroup
from .report import CheckResult

NAME = "algebroid"


def _zero(expr: sp.Expr) -> bool:
    expr = sp.expand(expr)
    return expr == 0 or sp.simplify(expr) == 0


def structure_equations(A: Algebroid) -> list[str]:
    """Violations of antisymmetry, ``estruc1`` and ``estruc2`` by ``A`` (empty: none)."""
    q, rho, C, n = A.q, A.anchor, A.structure, len(A.y)
    out = []
    for g, a, b in ((g, a, b) for g in range(n) for a, b in combinations(range(n), 2)):
        if not _zero(C[g][a, b] + C[g][b, a]):
            out.append(f"antisymmetry: C^{g + 1}_{a + 1}{b + 1} + C^{g + 1}_{b + 1}{a + 1} = "
                       f"{sp.simplify(C[g][a, b] + C[g][b, a])}")
    for a, b in combinations(range(n), 2):
        for i in range(len(q)):
            lhs = sum((rho[j, a] * sp.diff(rho[i, b], q[j]) - rho[j, b] * sp.diff(rho[i, a], q[j])
                       for j in range(len(q))), sp.S.Zero)
            rhs = sum((rho[i, g] * C[g][a, b] for g in range(n)), sp.S.Zero)
            if not _zero(lhs - rhs):
                out.append(f"estruc1 (α={a + 1}, β={b + 1}, component {q[i]}): "
                           f"[ρ(e_α), ρ(e_β)] − ρ(⟦e_α, e_β⟧) = {sp.simplify(lhs - rhs)}")
    for a, b, c in combinations(range(n), 3):
        for nu in range(n):
            total = sp.S.Zero
            for x, y, z in ((a, b, c), (b, c, a), (c, a, b)):
                total += sum((rho[i, x] * sp.diff(C[nu][y, z], q[i]) for i in range(len(q))),
                             sp.S.Zero)
                total += sum((C[nu][x, m] * C[m][y, z] for m in range(n)), sp.S.Zero)
            if not _zero(total):
                out.append(f"estruc2 (α={a + 1}, β={b + 1}, γ={c + 1}, ν={nu + 1}): cyclic sum "
                           f"= {sp.simplify(total)}")
    return out


def algebra_closure(basis: Sequence[sp.Matrix], constants: dict) -> list[str]:
    """Violations of [E_a, E_b] = C^c_{ab} E_c for the declared ``constants`` (pairs a < b
    → coefficient tuple, as :attr:`MatrixLieGroup.structure_constants`)."""
    out = []
    for a, b in combinations(range(len(basis)), 2):
        bracket = basis[a] * basis[b] - basis[b] * basis[a]
        combination = sum((c * E for c, E in zip(constants.get((a, b), ()), basis)),
                          sp.zeros(*bracket.shape))
        difference = (bracket - combination).applyfunc(sp.simplify)
        if difference != sp.zeros(*bracket.shape):
            out.append(f"closure: [E{a + 1}, E{b + 1}] − Σ_c C^c_{a + 1}{b + 1} E_c = "
                       f"{difference.tolist()} (not in the span of the basis, or wrong "
                       f"constants)")
    return out


def _groups(groupoid: Groupoid) -> list[MatrixLieGroup]:
    return list(groupoid.matrix_groups())


def run(ctx) -> CheckResult:
    G = ctx.model.groupoid
    A = G.algebroid()
    problems = structure_equations(A)
    groups = _groups(G)
    for H in groups:
        problems += [f"{H.label}: {p}" for p in algebra_closure(H.basis, H.structure_constants)]
    n, m = len(A.y), len(A.q)
    scope = f"rank {n} over {m} base coordinate{'s' if m != 1 else ''}" + \
        (f", {len(groups)} Lie algebra basis closure{'s' if len(groups) > 1 else ''}"
         if groups else "")
    if problems:
        return CheckResult.failed(NAME, f"{len(problems)} structure equation(s) violated "
                                        f"({scope})", problems, violations=len(problems))
    return CheckResult.passed(NAME, f"antisymmetry, estruc1, estruc2 hold ({scope})",
                              rank=n, base_dim=m)
