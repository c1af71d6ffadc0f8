"""Discretisation: continuous Lagrangian → discrete Lagrangian L_d (DESIGN.md §3).

The output, :class:`DiscreteModel`, expresses L_d in *slot* coordinates: a first-order
L_d : G → R has one slot (x₀, f₀), a second-order L_d : G₂ → R two composable slots
(x₀, f₀), (x₁, f₁) (paper §3.1). The derivation engine only ever sees slots, so every
groupoid shares it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import sympy as sp

from .groupoids.base import Groupoid

if TYPE_CHECKING:
    from .model import Model

Slot = tuple[tuple[sp.Symbol, ...], tuple[sp.Symbol, ...]]

#: The time step. It is a run-time argument of every generated function.
h = sp.Symbol("h", positive=True)


@dataclass(frozen=True)
class Rule:
    """A named discretisation of a given order (DESIGN.md §3).

    The groupoid supplies its quadrature (:meth:`Groupoid.quadrature`): weighted points
    (w_i, substitution of the continuous symbols) with L_d = h Σ w_i L(point_i).
    """

    name: str
    order: int
    summary: str

    def applies_to(self, groupoid: Groupoid) -> bool:
        return self.name in groupoid.rules(self.order)

    def build(self, groupoid: Groupoid, L: sp.Expr, xs, fs, step: sp.Expr) -> sp.Expr:
        return step * self.average(groupoid, L, xs, fs, step)

    def average(self, groupoid: Groupoid, F: sp.Expr, xs, fs, step: sp.Expr) -> sp.Expr:
        """Σ w_i F(point_i): the quadrature's weighted mean of F over one window."""
        return sum(w * F.xreplace(point)
                   for w, point in groupoid.quadrature(self.name, xs, fs, step))


#: Registry of discretisation rules by name.
RULES: dict[str, Rule] = {r.name: r for r in (
    Rule("midpoint", 1, "pair: L_d(q0, q1) = h L((q0+q1)/2, (q1-q0)/h)"),
    Rule("trapezoid", 1, "pair: L_d(q0, q1) = h/2 [L(q0, (q1-q0)/h) + L(q1, (q1-q0)/h)]"),
    Rule("three_point", 2,
         "pair: L_d(q0, q1, q2) = h L((q0+q1+q2)/3, (q2-q0)/2h, (q2-2q1+q0)/h^2)"),
    Rule("lie", 1, "Lie group: L_d(w) = h l(xi), xi = tau^-1(w)/h; action groupoid: "
                   "h/2 [l(q0, xi) + l(q1, xi)]"),
    Rule("lie_midpoint", 2, "Lie group: L_d(w0, w1) = h L((xi0+xi1)/2, (xi1-xi0)/h) (paper eq. "
                            "sdfinal); action groupoid: the base point at the middle node"),
    Rule("product", 1, "product groupoid: each factor's first-order default, tensor product"),
    Rule("product2", 2, "product groupoid: each factor's second-order default, tensor product"),
)}


def rule_names() -> list[str]:
    return sorted(RULES)


@dataclass(frozen=True, eq=False)
class DiscreteModel:
    """L_d in slot coordinates, with everything later stages need (no Model inside)."""

    name: str
    groupoid: Groupoid
    order: int
    slots: tuple[Slot, ...]
    lagrangian: sp.Expr
    step: sp.Symbol
    parameters: tuple[sp.Symbol, ...]
    defaults: tuple[float, ...]
    continuous_lagrangian: sp.Expr | None
    fingerprint: str
    #: Discrete constraints Φ^A_d (slot coordinates) and their multipliers λ_A (paper
    #: §3.2: the augmented L_d + λ_A Φ^A_d on every window).
    constraints: tuple[sp.Expr, ...] = ()
    multipliers: tuple[sp.Symbol, ...] = ()
    #: Controls at a window's quadrature point (slot coordinates).
    controls: tuple[sp.Expr, ...] = ()
    #: Declared Noether symmetries (:class:`symvi.symmetry.Symmetry`, base coordinates).
    symmetries: tuple = ()


def slot_symbols(groupoid: Groupoid, order: int) -> tuple[Slot, ...]:
    """Fresh coordinate symbols (x_j, f_j) of the ``order`` slots of L_d."""
    m, n = groupoid.source_dim, groupoid.fibre_dim
    return tuple((tuple(sp.Dummy(f"X{j}_{i}", real=True) for i in range(m)),
                  tuple(sp.Dummy(f"F{j}_{i}", real=True) for i in range(n)))
                 for j in range(order))


def discretise(model: "Model") -> DiscreteModel:
    """Turn a validated :class:`~symvi.model.Model` into a :class:`DiscreteModel`."""
    g = model.groupoid
    slots = slot_symbols(g, model.order)
    xs, fs = [s[0] for s in slots], [s[1] for s in slots]
    if model.lagrangian is not None:
        rule = RULES[model.discretisation]
        Ld = rule.build(g, model.lagrangian, xs, fs, h)
        constraints = tuple(rule.build(g, c, xs, fs, h) for c in model.constraints)
        controls = tuple(rule.average(g, u, xs, fs, h) for u in model.controls)
    else:
        mapping = g.discrete_mapping(model.order, xs, fs)
        Ld = model.discrete_lagrangian.xreplace(mapping)
        constraints, controls = tuple(c.xreplace(mapping) for c in model.constraints), ()
    multipliers = tuple(sp.Dummy(f"lambda{a}", real=True) for a in range(len(constraints)))
    return DiscreteModel(name=model.name, groupoid=g, order=model.order, slots=slots,
                         lagrangian=Ld, step=h, parameters=model.parameter_symbols,
                         defaults=model.parameter_defaults,
                         continuous_lagrangian=model.lagrangian,
                         fingerprint=model.fingerprint(), constraints=constraints,
                         multipliers=multipliers, controls=controls,
                         symmetries=tuple(model.symmetries))
