"""Discretisation: continuous Lagrangian → discrete Lagrangian L_d (DESIGN.md §3).

The output, :class:`DiscreteModel`, expresses L_d in *slot* coordinates: a first-order
L_d : G → R has one slot (x₀, f₀), a second-order L_d : G₂ → R two composable slots
(x₀, f₀), (x₁, f₁) (paper §3.1). The derivation engine only ever sees slots, so every
groupoid shares it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import sympy as sp

from .groupoids.base import Groupoid

if TYPE_CHECKING:
    from .model import Model

Slot = tuple[tuple[sp.Symbol, ...], tuple[sp.Symbol, ...]]

#: The time step. It is a run-time argument of every generated function.
h = sp.Symbol("h", positive=True)


@dataclass(frozen=True)
class Rule:
    """A named discretisation: ``build(groupoid, L, xs, fs, h)`` returns L_d.

    ``xs``, ``fs`` are the source and fibre coordinates of the rule's ``order`` slots.
    """

    name: str
    order: int
    kind: str
    build: Callable[..., sp.Expr]
    summary: str

    def applies_to(self, groupoid: Groupoid) -> bool:
        return groupoid.kind == self.kind



def _substitute(L, groupoid, q, v, a=None):
    mapping = dict(zip(groupoid.q, q)) | dict(zip(groupoid.qdot, v))
    if a is not None:
        mapping |= dict(zip(groupoid.qddot, a))
    return L.xreplace(mapping)


def _midpoint(groupoid, L, xs, fs, h):
    q0, q1 = (sp.Matrix(n) for n in groupoid.window_nodes(xs, fs))
    return h * _substitute(L, groupoid, (q0 + q1) / 2, (q1 - q0) / h)


def _trapezoid(groupoid, L, xs, fs, h):
    q0, q1 = (sp.Matrix(n) for n in groupoid.window_nodes(xs, fs))
    v = (q1 - q0) / h
    return h / 2 * (_substitute(L, groupoid, q0, v) + _substitute(L, groupoid, q1, v))


def _three_point(groupoid, L, xs, fs, h):
    q0, q1, q2 = (sp.Matrix(n) for n in groupoid.window_nodes(xs, fs))
    return h * _substitute(L, groupoid, (q0 + q1 + q2) / 3, (q2 - q0) / (2 * h),
                           (q2 - 2 * q1 + q0) / h**2)


def _lie(groupoid, L, xs, fs, h):
    return h * L.xreplace(dict(zip(groupoid.xi, fs[0])))


def _lie_midpoint(groupoid, L, xs, fs, h):
    x0, x1 = sp.Matrix(fs[0]), sp.Matrix(fs[1])
    mapping = dict(zip(groupoid.xi, (x0 + x1) / 2)) | dict(zip(groupoid.xidot, (x1 - x0) / h))
    return h * L.xreplace(mapping)


#: Registry of discretisation rules by name.
RULES: dict[str, Rule] = {
    "midpoint": Rule("midpoint", 1, "pair", _midpoint,
                     "L_d(q0, q1) = h L((q0+q1)/2, (q1-q0)/h)"),
    "trapezoid": Rule("trapezoid", 1, "pair", _trapezoid,
                      "L_d(q0, q1) = h/2 [L(q0, (q1-q0)/h) + L(q1, (q1-q0)/h)]"),
    "three_point": Rule("three_point", 2, "pair", _three_point,
                        "L_d(q0, q1, q2) = h L((q0+q1+q2)/3, (q2-q0)/2h, (q2-2q1+q0)/h^2)"),
    "lie": Rule("lie", 1, "lie", _lie, "L_d(w) = h l(xi), xi = tau^-1(w)/h"),
    "lie_midpoint": Rule("lie_midpoint", 2, "lie", _lie_midpoint,
                         "L_d(w0, w1) = h L((xi0+xi1)/2, (xi1-xi0)/h) (paper eq. sdfinal)"),
}


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
        Ld = RULES[model.discretisation].build(g, model.lagrangian, xs, fs, h)
    else:
        Ld = model.discrete_lagrangian.xreplace(g.discrete_mapping(model.order, xs, fs))
    return DiscreteModel(name=model.name, groupoid=g, order=model.order, slots=slots,
                         lagrangian=Ld, step=h, parameters=model.parameter_symbols,
                         defaults=model.parameter_defaults,
                         continuous_lagrangian=model.lagrangian,
                         fingerprint=model.fingerprint())
