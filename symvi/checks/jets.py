"""Jets of smooth curves and the continuous Euler–Lagrange operators (DESIGN.md §5).

Time derivatives are plain *jet* symbols until a result is reported, so the identities the
consistency expansions (:mod:`symvi.checks.expansions`) need are polynomial ones:

* :class:`_Jets`: q^{(k)}(t) on the pair groupoid, with :func:`_variational_derivative`
  E(L) = ∂L/∂q − d/dt ∂L/∂q̇ + d²/dt² ∂L/∂q̈, and for a Lagrangian of order r
  E(L) = Σ_{j=0}^{r} (−d/dt)^j ∂L/∂q⁽ʲ⁾ (the symbols q⁽ʲ⁾ are ``groupoid.derivative(j)``);
* :class:`_AlgebroidJets`: on a Lie algebroid, the base point q(t), the derivatives
  y^{(k)}(t) of the fibre curve and of the multipliers λ_A(t); derivatives of q follow
  from the anchor, q̇ = ρ(q) y;
* :func:`euler_lagrange_algebroid`: the operator EL₁ of Appendix C.2 and its second-order
  version EL₂ (paper eq. ``ecuacionesvakonomoalgebroides2``, times −1), with signs and
  conventions as stated in :mod:`symvi.checks.expansions`; of order r, EL_r with the
  momentum P_α = Σ_{j<r} (−d/dt)^j ∂L/∂y⁽ʲ⁾_α (y⁽ʲ⁾ the symbols of :func:`fibre_levels`);
* :func:`continuous_equations`: those equations with the constraints Φ^A = 0, in named
  jet symbols (``Omega1_dddot``, ``lambda1_dot``), for comparison with hand-derived ones;
* :func:`constraint_functions`, and how each groupoid's fibre is sampled along a curve
  (:func:`unsupported`, :func:`component_names`).

Results are reported as functions of t: base coordinates q_i(t), fibre coordinates y_α(t)
and their derivatives (a pair factor's y^{(k)} as q^{(k+1)}).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import sympy as sp
from sympy.core.function import AppliedUndef

from ..errors import ModelError
from ..declaration.model import Model
from ..groupoids.base import derivative_name
from .series import _Generators, _Poly, _generator, active_generators, generator_expr, in_scope

#: Time variable of the continuous curve the nodes are sampled from.
TIME = sp.Symbol("t", real=True)


# --------------------------------------------------------------------------------------
# Jets: q^{(k)}(t) as plain symbols
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Jets:
    """Symbols J[c][k] standing for the k-th time derivative of coordinate c."""

    names: tuple[str, ...]
    depth: int
    symbols: tuple[tuple[sp.Symbol, ...], ...]

    @classmethod
    def make(cls, names: Sequence[str], depth: int) -> "_Jets":
        symbols = tuple(tuple(sp.Dummy(f"{n}_{k}", real=True) for k in range(depth + 1))
                        for n in names)
        return cls(tuple(names), depth, symbols)

    def derivative(self, expr: sp.Expr) -> sp.Expr:
        """Total time derivative d/dt of a jet expression."""
        total = sp.Integer(0)
        for column in self.symbols:
            for k in range(self.depth):
                total += sp.diff(expr, column[k]) * column[k + 1]
        if expr.has(*(c[self.depth] for c in self.symbols)):
            raise ModelError("jet depth too small for this time derivative")
        return total

    def to_functions(self, expr: sp.Expr, t: sp.Symbol) -> sp.Expr:
        """Replace jets by derivatives of functions q_c(t)."""
        mapping = {}
        for name, column in zip(self.names, self.symbols):
            q = sp.Function(name, real=True)(t)
            for k, s in enumerate(column):
                mapping[s] = q if k == 0 else sp.Derivative(q, (t, k))
        return expr.xreplace(mapping)

    def from_functions(self, expr, t: sp.Symbol):
        """Inverse of :meth:`to_functions` (derivatives beyond the jet depth are kept)."""
        columns = dict(zip(self.names, self.symbols))

        def jet(name, k):
            column = columns.get(name)
            return column[k] if column is not None and k <= self.depth else None
        return _replace_functions(expr, t, jet)


def _replace_functions(expr, t: sp.Symbol, jet):
    """Replace f(t) and its derivatives by ``jet(name of f, k)`` where that is not None
    (functions are matched by name, whatever their assumptions)."""
    expr = sp.sympify(expr)
    mapping = {}
    for d in expr.atoms(sp.Derivative):
        if isinstance(d.expr, AppliedUndef) and d.expr.args == (t,) \
                and all(v == t for v in d.variables):
            value = jet(d.expr.func.__name__, d.derivative_count)
            if value is not None:
                mapping[d] = value
    for f in expr.atoms(AppliedUndef):
        if f.args == (t,):
            value = jet(f.func.__name__, 0)
            if value is not None:
                mapping[f] = value
    return expr.xreplace(mapping)


def derivative_levels(groupoid, order: int) -> list[tuple[sp.Symbol, ...]]:
    """The symbols of q, q̇, …, q⁽ʳ⁾ (r = ``order``) of a pair groupoid's Lagrangians
    (``groupoid.derivative(j)``: ``q``, ``qdot``, ``qddot``, then ``<name>_dddot``, …)."""
    return [tuple(groupoid.derivative(j)) for j in range(order + 1)]


def _variational_derivative(groupoid, lagrangian: sp.Expr, order: int, jets: _Jets) -> sp.Matrix:
    """E(L) = Σ_{j=0}^{r} (−d/dt)^j ∂L/∂q⁽ʲ⁾ on jets (r = ``order``; the jets' depth must be
    at least 2r)."""
    levels = derivative_levels(groupoid, order)
    mapping = {s: jets.symbols[c][k] for k, level in enumerate(levels)
               for c, s in enumerate(level)}
    rows = []
    for c in range(groupoid.fibre_dim):
        row = sp.Integer(0)
        for k, level in enumerate(levels):
            term = sp.diff(lagrangian, level[c]).xreplace(mapping)
            for _ in range(k):
                term = jets.derivative(term)
            row += (-1)**k * term
        rows.append(sp.expand(row))
    return sp.Matrix(rows)


# --------------------------------------------------------------------------------------
# Jets on a Lie algebroid: q(t), y^{(k)}(t) and multipliers λ^{(k)}(t) as plain symbols
# --------------------------------------------------------------------------------------
def _layout(groupoid) -> tuple[int | None, ...]:
    """How each fibre coordinate of ``groupoid`` is sampled along a curve
    (:meth:`~symvi.groupoids.base.Groupoid.fibre_sampling`): a base coordinate's index
    where it is the target node's value, None for an increment at the element's middle."""
    try:
        return groupoid.fibre_sampling()
    except NotImplementedError as exc:
        raise ModelError(str(exc)) from None


def unsupported(groupoid) -> str | None:
    """Why the expansion cannot sample ``groupoid`` along a curve, or None if it can."""
    try:
        _layout(groupoid)
    except ModelError as exc:
        return str(exc)
    return None


def fibre_levels(groupoid, algebroid=None) -> list[tuple[sp.Symbol, ...]]:
    """The continuous symbols of y, ẏ, …, y⁽ᵏ⁻¹⁾ on the algebroid of ``groupoid``, for every
    order k its Lagrangians may have (``groupoid.max_order``).

    y and ẏ are the algebroid's ``y`` and ``ydot``; y⁽ʲ⁾ is the groupoid's leading symbol
    of order j + 1 (``leading_symbols(j + 1)``: ξ⁽ʲ⁾ on a Lie group, q⁽ʲ⁺¹⁾ on a pair
    groupoid, the factors' in a product; its orders 1 and 2 are the algebroid's y and ẏ)."""
    a = algebroid if algebroid is not None else groupoid.algebroid()
    if groupoid.max_order <= 2:
        return [tuple(a.y), tuple(a.ydot)]
    return [tuple(groupoid.leading_symbols(j + 1)) for j in range(groupoid.max_order)]


def component_names(groupoid) -> tuple[str, ...]:
    """Names of the residual's components (:meth:`Groupoid.component_names`)."""
    return tuple(groupoid.component_names())


class _AlgebroidJets:
    """Jet symbols on the algebroid of ``groupoid``: the base point q (values only), the
    derivatives y^{(k)} of the fibre curve (k ≤ depth) and of ``multipliers`` functions
    λ_A; the total derivative uses q̇ = ρ(q) y."""

    def __init__(self, groupoid, depth: int, multipliers: int = 0,
                 multiplier_names: Sequence[str] | None = None):
        algebroid = groupoid.algebroid()
        self.algebroid, self.depth = algebroid, depth
        #: The continuous symbols of y, ẏ, …, y⁽ʲ⁾ (:func:`fibre_levels`).
        self.levels = fibre_levels(groupoid, algebroid)
        self.layout = _layout(groupoid)
        if len(self.layout) != len(algebroid.y):
            raise ModelError("the algebroid's rank differs from the groupoid's fibre dimension")
        self.q = tuple(sp.Dummy(str(s), real=True) for s in algebroid.q)
        self.y = tuple(tuple(sp.Dummy(f"{s}_{k}", real=True) for k in range(depth + 1))
                       for s in algebroid.y)
        self.lam = tuple(tuple(sp.Dummy(f"lambda{a}_{k}", real=True) for k in range(depth + 1))
                         for a in range(multipliers))
        base = dict(zip(algebroid.q, self.q))
        self.anchor = algebroid.anchor.xreplace(base)
        self.structure = tuple(C.xreplace(base) for C in algebroid.structure)
        y0 = sp.Matrix([column[0] for column in self.y])
        self.qdot = tuple(self.anchor * y0) if self.q else ()
        self.base_names = tuple(str(s) for s in algebroid.q)
        #: Function name and derivative shift of each fibre coordinate (a pair factor's
        #: y^{(k)} is q^{(k+1)}).
        self.fibre_functions = tuple((self.base_names[i], 1) if i is not None else (str(y), 0)
                                     for i, y in zip(self.layout, algebroid.y))
        self.multiplier_names = tuple(multiplier_names or
                                      (f"lambda{a}" for a in range(multipliers)))
        self._base_derivatives = [[s] for s in self.q]
        #: The generators of the polynomials these jets keep (the derivatives of the base
        #: coordinates): the expansion's that made them, or their own.
        self.generators = active_generators() or _Generators()

    def symbol_map(self) -> dict:
        """The groupoid's continuous symbols (q, y, ẏ of the algebroid, and the higher
        derivatives y⁽ʲ⁾ of Lagrangians of order > 2, j ≤ depth) → jets."""
        a = self.algebroid
        mapping = dict(zip(a.q, self.q))
        for j, level in enumerate(self.levels[:self.depth + 1]):
            mapping |= {s: c[j] for s, c in zip(level, self.y)}
        return mapping

    def derivative(self, expr: sp.Expr) -> sp.Expr:
        """Total time derivative: ∂/∂q · ρ(q) y + Σ_k ∂/∂y^{(k)} · y^{(k+1)} (and λ)."""
        free = expr.free_symbols
        total = sp.Integer(0)
        for s, v in zip(self.q, self.qdot):
            if s in free:
                total += sp.diff(expr, s) * v
        for column in self.y + self.lam:
            for k, s in enumerate(column):
                if s in free:
                    if k == self.depth:
                        raise ModelError("jet depth too small for this time derivative")
                    total += sp.diff(expr, s) * column[k + 1]
        return total

    def base_derivative(self, i: int, k: int) -> sp.Expr:
        """d^k q_i/dt^k along q̇ = ρ(q) y."""
        with in_scope(self.generators):
            return self.base_derivative_poly(i, k).as_expr()

    def base_derivative_poly(self, i: int, k: int) -> "_Poly":
        """d^k q_i/dt^k as a coefficient polynomial (the product rule on the polynomial's
        terms: far faster than ``sympy.diff`` on the growing expanded expressions), in the
        expansion that made these jets."""
        if active_generators() is not self.generators:
            raise RuntimeError("the jets' polynomials are used outside the expansion that "
                               "made them")
        column = self._base_derivatives[i]
        if not isinstance(column[0], _Poly):
            column[0] = _Poly.of(column[0])
        while len(column) <= k:
            column.append(self._poly_derivative(column[-1]))
        return column[k]

    def _poly_derivative(self, p: "_Poly") -> "_Poly":
        if not hasattr(self, "_rules"):
            self._rules = {}
            for s, v in zip(self.q, self.qdot):
                self._rules[_generator(s)] = _Poly.of(v)
            for column in self.y + self.lam:
                for k in range(self.depth):
                    self._rules[_generator(column[k])] = _Poly.of(column[k + 1])
        total = _Poly({})
        for monomial, c in p.terms.items():
            for j, (i, e) in enumerate(monomial):
                if i not in self._rules:
                    self._rules[i] = _Poly.of(sp.expand(self.derivative(generator_expr(i))))
                rule = self._rules[i]
                if not rule:
                    continue
                rest = monomial[:j] + ((i, e - 1),) + monomial[j + 1:] if e != 1 \
                    else monomial[:j] + monomial[j + 1:]
                total = total + _Poly({rest: c * e}) * rule
        return total

    def _functions(self, t: sp.Symbol) -> dict:
        mapping = {s: sp.Function(n, real=True)(t) for s, n in zip(self.q, self.base_names)}
        named = list(zip(self.y, self.fibre_functions)) \
            + [(c, (n, 0)) for c, n in zip(self.lam, self.multiplier_names)]
        for column, (name, shift) in named:
            f = sp.Function(name, real=True)(t)
            for k, s in enumerate(column):
                mapping[s] = f if k + shift == 0 else sp.Derivative(f, (t, k + shift))
        return mapping

    def to_functions(self, expr, t: sp.Symbol):
        return expr.xreplace(self._functions(t))

    def from_functions(self, expr, t: sp.Symbol):
        """Inverse of :meth:`to_functions`; derivatives of base coordinates follow from
        the anchor (q̇ = ρ(q) y)."""
        base = {n: i for i, n in enumerate(self.base_names)}
        other = {name: column for column, (name, shift) in zip(self.y, self.fibre_functions)
                 if shift == 0}
        other |= dict(zip(self.multiplier_names, self.lam))

        def jet(name, k):
            if name in base:
                return self.base_derivative(base[name], k) if k <= self.depth + 1 else None
            column = other.get(name)
            return column[k] if column is not None and k <= self.depth else None
        return _replace_functions(expr, t, jet)


def _algebroid_operator(jets: _AlgebroidJets, lagrangian: sp.Expr, order: int) -> sp.Matrix:
    """EL_r(L) on jets (:mod:`symvi.checks.expansions`): d/dt P_α − ρ^i_α ∂L/∂q^i + C^γ_{αβ} y^β P_γ with
    P_α = Σ_{j=0}^{r−1} (−d/dt)^j ∂L/∂y⁽ʲ⁾_α: ∂L/∂y (r = 1), ∂L/∂y − d/dt ∂L/∂ẏ (r = 2), …
    (the jets' depth must be at least 2r − 1)."""
    y0 = [column[0] for column in jets.y]
    P = []
    for c, column in enumerate(jets.y):
        p = sp.diff(lagrangian, y0[c])
        for j in range(1, order):
            term = sp.diff(lagrangian, column[j])
            for _ in range(j):
                term = jets.derivative(term)
            p += (-1)**j * term
        P.append(sp.expand(p))
    dLdq = [sp.diff(lagrangian, s) for s in jets.q]
    rows = []
    for a in range(len(y0)):
        row = jets.derivative(P[a])
        row -= sum((jets.anchor[i, a] * dLdq[i] for i in range(len(jets.q))), sp.S.Zero)
        row += sum((C[a, b] * y0[b] * P[g] for g, C in enumerate(jets.structure)
                    for b in range(len(y0)) if C[a, b] != 0), sp.S.Zero)
        rows.append(sp.expand(row))
    return sp.Matrix(rows)


def euler_lagrange_algebroid(groupoid, lagrangian: sp.Expr, order: int,
                             t: sp.Symbol = TIME, constraints: Sequence[sp.Expr] = ()) -> sp.Matrix:
    """The Euler–Lagrange operator EL_r(L) on the algebroid of ``groupoid`` along functions of
    ``t`` (:mod:`symvi.checks.expansions`): EL₁ of Appendix C.2 for ``order`` 1 (the same as
    :func:`symvi.declaration.control.euler_lagrange_operator`), the second-order operator EL₂ for
    ``order`` 2, and for ``order`` r ≥ 3 the same with the momentum
    P_α = Σ_{j<r} (−d/dt)^j ∂L/∂y⁽ʲ⁾_α. ``lagrangian`` (and ``constraints``) are written in the groupoid's
    continuous symbols; with constraints Φ^A the operator acts on L + λ_A(t) Φ^A, the
    multipliers being functions ``lambda0(t)``, ``lambda1(t)``, … of time.

    Base coordinates are functions q_i(t) (never differentiated: q̇ = ρ(q) y), fibre
    coordinates y_α(t) with their derivatives (a pair factor's y^{(k)} is q^{(k+1)}).
    The variational derivative of the action is −EL_r (:func:`euler_lagrange`).
    """
    top = groupoid.max_order
    if not isinstance(order, int) or isinstance(order, bool) or not 1 <= order <= top:
        raise ModelError(f"order must be an integer from 1 to {top} on {groupoid!r}, "
                         f"got {order!r}")
    jets = _AlgebroidJets(groupoid, 2 * order + 1, len(constraints))
    mapping = jets.symbol_map()
    L = sp.sympify(lagrangian).xreplace(mapping) \
        + sum((lam[0] * sp.sympify(c).xreplace(mapping)
               for lam, c in zip(jets.lam, constraints)), sp.S.Zero)
    return _algebroid_operator(jets, L, order).applyfunc(lambda e: jets.to_functions(e, t))


def constraint_functions(model: Model, t: sp.Symbol = TIME) -> sp.Matrix:
    """The continuous constraints Φ^A of ``model`` along functions of ``t`` (as in
    :func:`euler_lagrange_algebroid`)."""
    if model.lagrangian is None:
        raise ModelError(f"model {model.name!r} has no continuous constraints")
    jets = _AlgebroidJets(model.groupoid, 2 * model.order + 1)
    mapping = jets.symbol_map()
    return sp.Matrix([jets.to_functions(sp.expand(c.xreplace(mapping)), t)
                      for c in model.constraints])


@dataclass(frozen=True, eq=False)
class ContinuousEquations:
    """A model's continuous Euler–Lagrange equations in named jet symbols (§3.3.2).

    ``equations`` are EL_r(L + λ_A Φ^A), one per fibre direction (paper display after
    "These equations are given by", times −1, with ERRATA 8's correction), followed by the
    constraints Φ^A. ``symbols`` maps every name they may use to its symbol: base points
    (``Gamma1``; their derivatives follow from the anchor, q̇ = ρ(q)y), fibre coordinates and
    their derivatives (``Omega1`` … ``Omega1_d4``; a pair factor's ``theta1_dot`` …
    ``theta1_d4``) and the multipliers ``lambda1`` … with theirs. ``leading`` lists the
    fibre coordinates' and multipliers' derivatives, highest first.
    """

    equations: tuple
    symbols: dict
    leading: tuple
    jets: _AlgebroidJets
    names: dict

    def named(self, expr) -> sp.Expr:
        """``expr`` with functions of time (``Omega1(t)``, ``Derivative(theta1(t), (t, 4))``,
        ``lambda1(t)``, whatever the time symbol) in the named symbols."""
        expr = sp.sympify(expr)
        times = {f.args[0] for f in expr.atoms(AppliedUndef) if len(f.args) == 1}
        for t in times:
            expr = self.jets.from_functions(expr, t)
        return expr.xreplace(self.names)


def continuous_equations(model: Model) -> ContinuousEquations:
    """The continuous (constrained) Euler–Lagrange equations of ``model``: EL_r(L̂) = 0 with
    L̂ = L + λ_A Φ^A, and Φ^A = 0 (§3.3.2; :class:`ContinuousEquations`)."""
    if model.lagrangian is None:
        raise ModelError(f"model {model.name!r} has no continuous Lagrangian")
    s = len(model.constraints)
    jets = _AlgebroidJets(model.groupoid, 2 * model.order + 1, s,
                          tuple(f"lambda{a + 1}" for a in range(s)))
    mapping = jets.symbol_map()
    constraints = [sp.sympify(c).xreplace(mapping) for c in model.constraints]
    L = sp.sympify(model.lagrangian).xreplace(mapping) \
        + sum((lam[0] * c for lam, c in zip(jets.lam, constraints)), sp.S.Zero)
    names = {q: sp.Symbol(n) for q, n in zip(jets.q, jets.base_names)}
    for column, (name, shift) in zip(jets.y, jets.fibre_functions):
        names |= {s: sp.Symbol(derivative_name(name, k + shift)) for k, s in enumerate(column)}
    for column, name in zip(jets.lam, jets.multiplier_names):
        names |= {s: sp.Symbol(derivative_name(name, k)) for k, s in enumerate(column)}
    rows = list(_algebroid_operator(jets, L, model.order)) + [sp.expand(c) for c in constraints]
    leading = tuple(names[column[k]] for k in reversed(range(jets.depth))
                    for column in jets.y + jets.lam)
    return ContinuousEquations(tuple(r.xreplace(names) for r in rows),
                               {v.name: v for v in names.values()}, leading, jets, names)
