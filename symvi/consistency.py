"""Consistency of discrete Euler–Lagrange residuals with the continuous equations (DESIGN.md §5).

For a pair-groupoid model the residual at node j, R(q_{j−r}, …, q_{j+r}; h), is expanded
in h along a smooth curve: each node is replaced by the Taylor polynomial
q_{j+i} = q(t + i h) = Σ_k (i h)^k/k! q^{(k)}(t). The coefficient of the lowest power of h
that survives must be the continuous Euler–Lagrange expression; the power of the next
surviving term measures how well the residual approximates it.

Conventions. :func:`euler_lagrange` returns the *variational derivative* of the action,

    E(L) = ∂L/∂q − d/dt ∂L/∂q̇ + d²/dt² ∂L/∂q̈,

which is minus the usual first-order expression d/dt ∂L/∂q̇ − ∂L/∂q and equal to the
usual second-order one. With it the sign is the same for every order: the residual is
∂S_d/∂q_j and a node carries a time span h of the action, so R = h·E(L)(t_j) + O(h²).
For a symmetric rule, L_d(q_0, …, q_r; h) = −L_d(q_r, …, q_0; −h) (midpoint, trapezoid,
three-point), the residual is odd in h and the next term is O(h³): the relative
consistency error is O(h²).

Method. The expansion is a small truncated Laurent-series arithmetic over the residual's
expression tree (sums, products, integer powers, analytic functions of one argument) that
tracks up to which power every intermediate result is exact. It never calls
``sympy.series`` on the substituted residual, which is slow for trigonometric Lagrangians,
and derivatives q^{(k)}(t) are plain *jet* symbols until the result is reported, so the
identities needed are polynomial ones.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import sympy as sp

from .derive import DerivedModel, derive
from .discretise import discretise
from .errors import ModelError
from .model import Model

#: Time variable of the continuous curve the nodes are sampled from.
TIME = sp.Symbol("t", real=True)

_EXACT = 10**9  # "exact to every power": precision of expressions free of h


# --------------------------------------------------------------------------------------
# Truncated Laurent series in one symbol
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Series:
    """Σ_p terms[p]·h^p, exact for every power ≤ ``prec`` (higher powers unknown)."""

    terms: Mapping[int, sp.Expr]
    prec: int

    def valuation(self) -> int:
        """Lower bound of the lowest power with a non-zero coefficient."""
        nonzero = [p for p, c in self.terms.items() if c != 0]
        return min(nonzero) if nonzero else self.prec + 1


def _truncate(terms: Mapping[int, sp.Expr], prec: int) -> _Series:
    return _Series({p: c for p, c in terms.items() if p <= prec and c != 0}, prec)


def _add(a: _Series, b: _Series) -> _Series:
    terms = dict(a.terms)
    for p, c in b.terms.items():
        terms[p] = sp.expand(terms.get(p, 0) + c)
    return _truncate(terms, min(a.prec, b.prec))


def _mul(a: _Series, b: _Series, limit: int) -> _Series:
    va, vb = a.valuation(), b.valuation()
    prec = min(limit, a.prec + vb, b.prec + va)
    terms: dict[int, sp.Expr] = {}
    for p, c in a.terms.items():
        for q, d in b.terms.items():
            if p + q <= prec:
                terms[p + q] = terms.get(p + q, 0) + c * d
    return _truncate({p: sp.expand(c) for p, c in terms.items()}, prec)


class _Expander:
    """Laurent expansion of expressions in ``step`` with some symbols replaced by series."""

    def __init__(self, step: sp.Symbol, atoms: Mapping[sp.Symbol, _Series]):
        self.step, self.atoms = step, dict(atoms)
        self._valuations: dict[sp.Expr, int] = {}

    def depends(self, expr: sp.Expr) -> bool:
        return expr.has(self.step, *self.atoms)

    def valuation(self, expr: sp.Expr) -> int:
        """A lower bound of the order of ``expr`` in h (cheap; no cancellation detected)."""
        if expr not in self._valuations:
            self._valuations[expr] = self._valuation(expr)
        return self._valuations[expr]

    def _valuation(self, expr: sp.Expr) -> int:
        if not self.depends(expr):
            return 0
        if expr == self.step:
            return 1
        if expr in self.atoms:
            return self.atoms[expr].valuation()
        if expr.is_Add:
            return min(self.valuation(a) for a in expr.args)
        if expr.is_Mul:
            return sum(self.valuation(a) for a in expr.args)
        if expr.is_Pow and expr.exp.is_Integer and expr.exp > 0:
            return int(expr.exp) * self.valuation(expr.base)
        if expr.is_Pow and expr.base == self.step and expr.exp.is_Integer:
            return int(expr.exp)
        if expr.is_Pow and expr.exp.is_Integer:
            # 1/b^m: the lower bound of b gives no bound for 1/b; find b's true order.
            return int(expr.exp) * self._true_order(expr.base)
        return 0  # analytic function of an argument that is O(1)

    def _true_order(self, expr: sp.Expr) -> int:
        guess = self.valuation(expr)
        for extra in range(0, 8):
            s = self.series(expr, guess + extra)
            leading = [p for p, c in sorted(s.terms.items()) if not _is_zero(c)]
            if leading:
                return leading[0]
        raise ModelError(f"cannot find the order in h of {expr} (it may vanish identically)")

    def series(self, expr: sp.Expr, limit: int) -> _Series:
        """Series of ``expr`` exact through h**limit (or less, as its ``prec`` says)."""
        if not self.depends(expr):
            return _Series({0: expr} if expr != 0 else {}, _EXACT)
        if expr == self.step:
            return _Series({1: sp.Integer(1)}, _EXACT)
        if expr in self.atoms:
            s = self.atoms[expr]
            return _truncate(s.terms, min(s.prec, limit))
        if expr.is_Add:
            result = _Series({}, _EXACT)
            for a in expr.args:
                result = _add(result, self.series(a, limit))
            return _truncate(result.terms, min(result.prec, limit))
        if expr.is_Mul:
            return self._product(expr.args, limit)
        if expr.is_Pow and expr.exp.is_Integer:
            return self._integer_power(expr.base, int(expr.exp), limit)
        if expr.is_Pow and not self.depends(expr.exp):
            x = sp.Dummy("x")
            return self._analytic(x**expr.exp, x, expr.base, limit)
        if isinstance(expr, sp.Function) and len(expr.args) == 1:
            x = sp.Dummy("x")
            return self._analytic(expr.func(x), x, expr.args[0], limit)
        raise ModelError(f"cannot expand {expr} in {self.step}: only sums, products, powers "
                         f"and analytic functions of one argument are supported")

    def _product(self, factors: Sequence[sp.Expr], limit: int) -> _Series:
        vals = [self.valuation(f) for f in factors]
        total = sum(vals)
        result, remaining = _Series({0: sp.Integer(1)}, _EXACT), total
        for f, v in zip(factors, vals):
            remaining -= v  # the partial product must be exact through limit − remaining
            result = _mul(result, self.series(f, limit - (total - v)), limit - remaining)
        return result

    def _integer_power(self, base: sp.Expr, m: int, limit: int) -> _Series:
        if base == self.step:
            return _Series({m: sp.Integer(1)}, _EXACT)
        if m > 0:
            return self._product([base] * m, limit)
        m = -m
        w = self._true_order(base)
        # base = c h^w (1 + u), u = O(h): base^{-m} = c^{-m} h^{-mw} Σ_j binom(−m, j) u^j.
        need = limit + m * w
        b = self.series(base, w + need)
        c = b.terms[w]
        u = _truncate({p - w: sp.expand(cp / c) for p, cp in b.terms.items() if p != w},
                      b.prec - w)
        total = _Series({0: sp.Integer(1)}, _EXACT)
        power = _Series({0: sp.Integer(1)}, _EXACT)
        for j in range(1, need + 1):
            power = _mul(power, u, need)
            coeff = sp.binomial(-m, j)
            total = _add(total, _Series({p: coeff * cp for p, cp in power.terms.items()},
                                        power.prec))
        total = _truncate(total.terms, min(total.prec, need, u.prec))
        scale = c**(-m)
        return _truncate({p - m * w: sp.expand(scale * cp) for p, cp in total.terms.items()},
                         min(limit, total.prec - m * w))

    def _analytic(self, g: sp.Expr, x: sp.Symbol, argument: sp.Expr, limit: int) -> _Series:
        a = self.series(argument, max(limit, 0))
        if a.valuation() < 0:
            raise ModelError(f"cannot expand {g.subs(x, argument)}: its argument is "
                             f"unbounded as {self.step} → 0")
        a0 = a.terms.get(0, sp.Integer(0))
        delta = _truncate({p: c for p, c in a.terms.items() if p != 0}, a.prec)
        prec = min(limit, a.prec)
        result = _Series({0: g.subs(x, a0)}, _EXACT)
        power = _Series({0: sp.Integer(1)}, _EXACT)
        derivative = g
        for k in range(1, prec + 1):
            power = _mul(power, delta, prec)
            derivative = sp.diff(derivative, x)
            coeff = derivative.subs(x, a0) / math.factorial(k)
            result = _add(result, _Series({p: coeff * c for p, c in power.terms.items()},
                                          power.prec))
        return _truncate(result.terms, prec)


def _is_zero(expr: sp.Expr) -> bool:
    expr = sp.expand(expr)
    return expr == 0 or sp.simplify(expr) == 0


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


def _variational_derivative(groupoid, lagrangian: sp.Expr, order: int, jets: _Jets) -> sp.Matrix:
    levels = [tuple(groupoid.q), tuple(groupoid.qdot), tuple(groupoid.qddot)][: order + 1]
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
# Public API
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ResidualExpansion:
    """The Taylor expansion in h of a discrete Euler–Lagrange residual along q(t).

    Attributes
    ----------
    step, time : the symbols h and t.
    terms : the non-zero coefficients, ((power, column matrix), …) in increasing power,
        in terms of the functions q_c(t) and their derivatives.
    through : every power ≤ ``through`` has been computed (absent powers vanish).
    """

    step: sp.Symbol
    time: sp.Symbol
    terms: tuple[tuple[int, sp.Matrix], ...]
    through: int
    _jets: _Jets
    _jet_terms: tuple[tuple[int, sp.Matrix], ...]

    @property
    def leading_power(self) -> int | None:
        return self.terms[0][0] if self.terms else None

    @property
    def leading(self) -> sp.Matrix | None:
        return self.terms[0][1] if self.terms else None

    @property
    def next_power(self) -> int | None:
        return self.terms[1][0] if len(self.terms) > 1 else None

    @property
    def next_term(self) -> sp.Matrix | None:
        return self.terms[1][1] if len(self.terms) > 1 else None

    @property
    def order(self) -> int | None:
        """Consistency order: next power − leading power (the relative error is O(h^order))."""
        if self.leading_power is None or self.next_power is None:
            return None
        return self.next_power - self.leading_power

    def sign_against(self, expected: sp.Matrix) -> int | None:
        """+1 if the leading coefficient equals ``expected``, −1 if it equals −expected,
        None otherwise (``expected`` as returned by :func:`euler_lagrange` with the same
        ``time``)."""
        if not self._jet_terms:
            return None
        lead = self._jet_terms[0][1]
        target = _to_jets(expected, self._jets, self.time)
        for sign in (1, -1):
            if all(_is_zero(a - sign * b) for a, b in zip(lead, target)):
                return sign
        return None


def _to_jets(expr: sp.Matrix, jets: _Jets, t: sp.Symbol) -> sp.Matrix:
    """Inverse of :meth:`_Jets.to_functions` (derivatives beyond the jet depth are kept)."""
    mapping = {}
    for name, column in zip(jets.names, jets.symbols):
        q = sp.Function(name, real=True)(t)
        mapping[q] = column[0]
        mapping.update({sp.Derivative(q, (t, k)): column[k] for k in range(1, jets.depth + 1)})
    return expr.xreplace(mapping)


def euler_lagrange(model: Model, t: sp.Symbol = TIME) -> sp.Matrix:
    """E(L) = ∂L/∂q − d/dt ∂L/∂q̇ + d²/dt² ∂L/∂q̈ along functions q_c(t) (see module doc).

    Needs a model declared with a continuous Lagrangian.
    """
    if model.lagrangian is None:
        raise ModelError(f"model {model.name!r} has no continuous Lagrangian")
    jets = _Jets.make(model.groupoid.names, 2 * model.order)
    return _variational_derivative(model.groupoid, model.lagrangian, model.order,
                                   jets).applyfunc(lambda e: jets.to_functions(e, t))


def expand_residual(residual: sp.Matrix, nodes: Sequence[Sequence[sp.Symbol]],
                    step: sp.Symbol, names: Sequence[str], *, centre: int,
                    through: int, t: sp.Symbol = TIME) -> ResidualExpansion:
    """Expand ``residual`` in ``step`` with node i set to q(t + (i − centre)·h).

    ``nodes[i]`` are the coordinate symbols of node i; ``names`` name the coordinate
    functions. Every power of h up to ``through`` is computed; the node Taylor polynomials
    are lengthened until that precision is reached.
    """
    residual = sp.Matrix(residual)
    for degree in range(through + 1, through + 12):
        jets = _Jets.make(names, degree)
        atoms = {}
        for i, node in enumerate(nodes):
            offset = i - centre
            for c, s in enumerate(node):
                atoms[s] = _truncate({k: sp.Rational(offset**k, math.factorial(k))
                                      * jets.symbols[c][k] for k in range(degree + 1)}, degree)
        expander = _Expander(step, atoms)
        columns = [expander.series(e, through) for e in residual]
        if min(s.prec for s in columns) >= through:
            break
    else:
        raise ModelError(f"could not reach precision h^{through} in the residual expansion")
    powers = sorted({p for s in columns for p in s.terms})
    jet_terms = []
    for p in powers:
        coefficient = sp.Matrix([s.terms.get(p, sp.Integer(0)) for s in columns])
        if not all(_is_zero(c) for c in coefficient):
            jet_terms.append((p, coefficient.applyfunc(sp.expand)))
    terms = tuple((p, M.applyfunc(lambda e: jets.to_functions(e, t))) for p, M in jet_terms)
    return ResidualExpansion(step=step, time=t, terms=terms, through=through, _jets=jets,
                             _jet_terms=tuple(jet_terms))


def residual_expansion(model: Model, *, derived: DerivedModel | None = None,
                       terms: int = 2, max_power: int = 7,
                       t: sp.Symbol = TIME) -> ResidualExpansion:
    """Expand the discrete Euler–Lagrange residual of a pair-groupoid ``model`` in h.

    The residual is the ``step`` kernel of ``derive(discretise(model))`` (pass ``derived``
    to reuse one), whose stencil is the nodes q_{j−r} … q_{j+r}. Powers are computed
    until ``terms`` non-zero coefficients are found or ``max_power`` is reached.
    """
    if model.groupoid.kind != "pair":
        raise ModelError(f"consistency expansions need the pair groupoid, not "
                         f"{model.groupoid.kind!r}")
    dm = derived if derived is not None else derive(discretise(model))
    kernel = dm.kernel("step")
    residual = dict(kernel.outputs)["residual"]
    n, r = dm.fibre_dim, dm.order
    nodes = [kernel.z[i * n:(i + 1) * n] for i in range(2 * r + 1)]
    through = 1
    while True:
        expansion = expand_residual(residual, nodes, dm.step, model.groupoid.names,
                                    centre=r, through=through, t=t)
        if len(expansion.terms) >= terms or through >= max_power:
            return expansion
        through = min(max_power, through + 2)


@dataclass(frozen=True)
class ConsistencyReport:
    """Outcome of :func:`check_consistency`.

    ``sign`` is +1 when R = h^power·E(L) + …, −1 for −E(L), None when the leading term is
    not ±E(L) (the residual is inconsistent); ``order`` is the consistency order.
    """

    model: str
    power: int | None
    sign: int | None
    order: int | None
    expansion: ResidualExpansion

    @property
    def consistent(self) -> bool:
        return self.sign is not None


def check_consistency(model: Model, *, derived: DerivedModel | None = None,
                      lagrangian_model: Model | None = None) -> ConsistencyReport:
    """Compare the leading term of ``model``'s residual with the Euler–Lagrange expression.

    ``lagrangian_model`` supplies the continuous Lagrangian when ``model`` was declared
    with a discrete one (default: ``model`` itself).
    """
    reference = lagrangian_model if lagrangian_model is not None else model
    expansion = residual_expansion(model, derived=derived)
    expected = euler_lagrange(reference, expansion.time)
    sign = expansion.sign_against(expected)
    return ConsistencyReport(model=model.name, power=expansion.leading_power, sign=sign,
                             order=expansion.order, expansion=expansion)
