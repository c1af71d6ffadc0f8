"""Noether symmetries of a discrete Lagrangian (paper §4.4, Theorem ``teoremanoethergroupoids``).

A symmetry is a section Z = Z^a(x) e_a of the Lie algebroid AG (one coefficient per fibre
direction, a function of the base point). It moves every node of a path by σ_{Z(x)}(ε):
each element g goes to σ_{Z(α(g))}(ε)⁻¹·g·σ_{Z(β(g))}(ε). On the pair groupoid this is
the flow of the vector field Z on Q; on a Lie group (over a point, Z constant) it is
conjugation; on the heavy top's action groupoid Z(Γ) = Γ is the rotation about the
vertical.

L_d is *invariant* when every window's action term is unchanged to first order, and
*quasi-invariant* with potential f when its change is a difference,
δL_d(g_k, …, g_{k+r−1}) = f(last r−1 elements) − f(first r−1 elements) — for first order
(r = 1) f is a function of a base point, for second order of one element. Then
F_Z = ⟨momentum of the windows crossing a node, Z⟩ + f is conserved along every solution
(the discrete Noether theorem); :mod:`symvi.derivation.derive` emits it as the ``noether`` kernel and
``symvi check`` verifies the (quasi-)invariance.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import sympy as sp


@dataclass(frozen=True)
class Symmetry:
    """A declared symmetry Z of a model (see the module docstring).

    Parameters
    ----------
    name:
        Name of the conserved quantity (e.g. ``"vertical_momentum"``).
    section:
        The coefficients Z^a, one per fibre direction of the groupoid, as expressions in
        the algebroid's base coordinates (``groupoid.algebroid().q``) and the model's
        parameters.
    potential:
        f of a quasi-invariant Lagrangian (0 for an invariant one): for first-order
        models an expression in the base coordinates; for second-order models in the
        groupoid's discrete symbols of one element (``groupoid.discrete_symbols(1)``).
    """

    name: str
    section: Sequence[Any]
    potential: Any = 0

    def __post_init__(self) -> None:
        section = self.section
        if isinstance(section, sp.MatrixBase):
            section = list(section)
        object.__setattr__(self, "section", tuple(sp.sympify(v) for v in section))
        object.__setattr__(self, "potential", sp.sympify(self.potential))
