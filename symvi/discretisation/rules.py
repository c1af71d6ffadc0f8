"""Discretisation rules: each owns its quadrature and its order of consistency (DESIGN.md §3).

A rule turns a continuous Lagrangian into L_d = h Σ w_i L(point_i) on a window of ``order``
slots (x_j, f_j), each point a substitution of the groupoid's continuous symbols. The
quadrature reads the window through the groupoid's own coordinates — the nodes of a pair
groupoid (``window_nodes``, ``point``), the Lie algebra point and base points of a group
or action groupoid (``algebra_point``, ``base_quadrature``), a product's factors
(``factors``, ``factor_slots``) — hooks every :class:`~symvi.groupoids.base.Groupoid`
declares — so a rule applies to the groupoids that give them, and each groupoid lists its
rules (:meth:`~symvi.groupoids.base.Groupoid.rules`; the first is the default). A rule
asks the groupoid, never which kind it is.
"""
from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable, Sequence

import sympy as sp
from sympy.calculus.finite_diff import finite_diff_weights

if TYPE_CHECKING:       # for annotations only: the groupoids import this module
    from ..groupoids.base import Groupoid

#: The highest order of a Lagrangian (the number of slots of L_d) that the rules here
#: discretise: L(q, q̇, …, q⁽ᵏ⁾) on a pair groupoid, L(ξ, …, ξ⁽ᵏ⁻¹⁾) on a Lie group.
MAX_ORDER = 6

Points = list[tuple[sp.Expr, dict]]
#: (groupoid, xs, fs, h) → weighted points, the groupoid being whichever lists the rule.
Quadrature = Callable[["Groupoid", Sequence, Sequence, sp.Expr], Points]


@dataclass(frozen=True)
class Rule:
    """A named discretisation of a given order.

    ``consistency_order`` is p in R = ±h·E + O(h^{p+1}) for the discrete Euler–Lagrange
    residual R against the continuous equations E (2 for the symmetric rules here): the
    ``consistency`` check fails a residual that falls short of it.
    """

    name: str
    order: int
    summary: str
    quadrature: Quadrature = field(repr=False, compare=False)
    consistency_order: int = 2

    def applies_to(self, groupoid: Groupoid) -> bool:
        return self in groupoid.rules(self.order)

    def build(self, groupoid: Groupoid, L: sp.Expr, xs, fs, step: sp.Expr) -> sp.Expr:
        """L_d = h Σ w_i L(point_i) on the window (xs, fs)."""
        return step * self.average(groupoid, L, xs, fs, step)

    def average(self, groupoid: Groupoid, F: sp.Expr, xs, fs, step: sp.Expr) -> sp.Expr:
        """Σ w_i F(point_i): the quadrature's weighted mean of F over one window."""
        return sum(w * F.xreplace(point) for w, point in self.quadrature(groupoid, xs, fs, step))


# -- pair groupoid: the nodes q_0, q_1, … of the window ----------------------------------
def _nodes(g: Groupoid, xs, fs) -> list[sp.Matrix]:
    return [sp.Matrix(n) for n in g.window_nodes(xs, fs)]


def _midpoint(g: Groupoid, xs, fs, h) -> Points:
    q0, q1 = _nodes(g, xs, fs)
    return [(sp.Integer(1), g.point((q0 + q1) / 2, (q1 - q0) / h))]


def _trapezoid(g: Groupoid, xs, fs, h) -> Points:
    q0, q1 = _nodes(g, xs, fs)
    v = (q1 - q0) / h
    return [(sp.S.Half, g.point(q0, v)), (sp.S.Half, g.point(q1, v))]


@functools.lru_cache(maxsize=None)
def central_weights(times: tuple[sp.Rational, ...], centre: sp.Rational,
                    derivatives: int) -> tuple[tuple[sp.Rational, ...], ...]:
    """Row j: the weights of the samples at ``times`` (in units of h) that give the j-th
    derivative at ``centre`` of their interpolating polynomial (j = 0 … ``derivatives``;
    SymPy's Fornberg weights), to be divided by h^j."""
    weights = finite_diff_weights(derivatives, list(times), centre)
    return tuple(tuple(weights[j][-1]) for j in range(derivatives + 1))


def window_derivatives(samples: Sequence[sp.Matrix], first: sp.Rational,
                       h: sp.Expr) -> list[sp.Matrix]:
    """The value and derivatives at the window's centre of the polynomial through
    ``samples``, taken at times (first + j)·h: central differences of order 2 at least
    (the interpolant of k + 1 equally spaced samples differentiated at their centre)."""
    k = len(samples) - 1
    times = tuple(first + j for j in range(k + 1))
    rows = central_weights(times, first + sp.Rational(k, 2), k)
    return [sum((w * q for w, q in zip(row, samples)), sp.zeros(*samples[0].shape)) / h**j
            for j, row in enumerate(rows)]


def _central(g: Groupoid, xs, fs, h) -> Points:
    """L(q, q̇, …, q⁽ᵏ⁾) at the window's centre, kh/2, from the polynomial through its
    k + 1 nodes (k = 2: q₁, (q₂ − q₀)/2h, (q₂ − 2q₁ + q₀)/h²)."""
    return [(sp.Integer(1), g.point(*window_derivatives(_nodes(g, xs, fs), sp.S.Zero, h)))]


def _three_point(g: Groupoid, xs, fs, h) -> Points:
    q0, q1, q2 = _nodes(g, xs, fs)
    return [(sp.Integer(1), g.point((q0 + q1 + q2) / 3, (q2 - q0) / (2 * h),
                                    (q2 - 2 * q1 + q0) / h**2))]


# -- Lie groups and action groupoids: ξ (and ξ̇) from the increments ---------------------
def _lie(g: Groupoid, xs, fs, h) -> Points:
    """h l(ξ) on a Lie group; on an action groupoid the trapezoid in the base,
    h/2 [l(q_0, ξ) + l(q_1, ξ)] (symmetric, order 2): the groupoid's
    :meth:`~symvi.groupoids.base.Groupoid.base_quadrature`."""
    algebra = g.algebra_point(fs, h)
    return [(w, base | algebra) for w, base in g.base_quadrature(xs, fs, h)]


def _lie_midpoint(g: Groupoid, xs, fs, h) -> Points:
    """L((ξ_0 + ξ_1)/2, (ξ_1 − ξ_0)/h) (paper eq. ``sdfinal``), on an action groupoid at
    the base point of the middle node."""
    return [(sp.Integer(1), g.base_point(xs[1]) | g.algebra_point(fs, h))]


# -- products: the tensor product of the factors' default rules ------------------------
def _product(g: Groupoid, xs, fs, h) -> Points:
    order = len(fs)
    per_factor = [factor.rules(order)[0].quadrature(factor, fx, ff, h)
                  for factor, (fx, ff) in zip(g.factors, g.factor_slots(xs, fs))]
    points = []
    for combination in itertools.product(*per_factor):
        point: dict = {}
        for _, p in combination:
            point |= p
        points.append((sp.Mul(*[w for w, _ in combination]), point))
    return points


MIDPOINT = Rule("midpoint", 1, "pair: L_d(q0, q1) = h L((q0+q1)/2, (q1-q0)/h)", _midpoint)
TRAPEZOID = Rule("trapezoid", 1,
                 "pair: L_d(q0, q1) = h/2 [L(q0, (q1-q0)/h) + L(q1, (q1-q0)/h)]", _trapezoid)
THREE_POINT = Rule("three_point", 2, "pair: L_d(q0, q1, q2) = h L((q0+q1+q2)/3, (q2-q0)/2h, "
                                     "(q2-2q1+q0)/h^2)", _three_point)
LIE = Rule("lie", 1, "Lie group: L_d(w) = h l(xi), xi = tau^-1(w)/h; action groupoid: "
                     "h/2 [l(q0, xi) + l(q1, xi)]", _lie)
LIE_MIDPOINT = Rule("lie_midpoint", 2, "Lie group: L_d(w0, w1) = h L((xi0+xi1)/2, "
                                       "(xi1-xi0)/h) (paper eq. sdfinal); action groupoid: "
                                       "the base point at the middle node", _lie_midpoint)


@functools.lru_cache(maxsize=None)
def central(order: int) -> Rule:
    """The pair groupoid's rule of ``order`` ≥ 3 (:func:`_central`)."""
    return Rule(f"central{order}", order,
                f"pair: L_d(q0, ..., q{order}) = h L at the window's centre, q and its "
                f"derivatives from the polynomial through the {order + 1} nodes", _central)


@functools.lru_cache(maxsize=None)
def lie_central(order: int) -> Rule:
    """A Lie group's rule of ``order`` ≥ 3: :func:`_lie_midpoint`'s on ``order`` increments."""
    return Rule(f"lie_central{order}", order,
                f"Lie group: L_d(w0, ..., w{order - 1}) = h L(xi, ..., xi^({order - 1})) at the "
                f"window's centre from the polynomial through its {order} increments xi_j "
                f"(at the elements' middles)", _lie_midpoint)


@functools.lru_cache(maxsize=None)
def product(order: int) -> Rule:
    """A product groupoid's rule of ``order``: the tensor product of its factors'."""
    if order <= 2:
        return (PRODUCT, PRODUCT2)[order - 1]
    return Rule(f"product{order}", order, "product groupoid: each factor's default of order "
                f"{order}, tensor product", _product)


PRODUCT = Rule("product", 1, "product groupoid: each factor's first-order default, tensor "
                             "product", _product)
PRODUCT2 = Rule("product2", 2, "product groupoid: each factor's second-order default, "
                               "tensor product", _product)

#: Every rule, by name.
RULES: dict[str, Rule] = {r.name: r for r in (
    MIDPOINT, TRAPEZOID, THREE_POINT, LIE, LIE_MIDPOINT, PRODUCT, PRODUCT2,
    *(make(k) for make in (central, lie_central, product) for k in range(3, MAX_ORDER + 1)))}


def rule_names() -> list[str]:
    return sorted(RULES)
