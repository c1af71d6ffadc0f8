"""Truncated Laurent-series arithmetic for the consistency expansions (DESIGN.md §5).

The expansions of :mod:`symvi.checks.expansions` run over a residual's expression tree (sums,
products, integer powers, analytic functions of one argument — the exponential
retraction's coefficient functions of :mod:`symvi.groupoids.analytic` through their exact
Taylor series) with a small arithmetic that tracks up to which power of h every
intermediate result is exact:

* :class:`_Poly`: coefficients as sparse Laurent polynomials with rational coefficients in
  the atoms they contain (jets, parameters, values such as sin(q)) — ``sympy.expand`` of
  products of large sums was the cost;
* :class:`_Series`: Σ_p c_p h^p exact through a known power, with sums and products;
* :class:`_Expander`: the series of an expression with some symbols replaced by series
  (and named intermediate quantities, such as a kernel's base points, expanded on demand);
* :func:`_is_zero`: coefficients are tested for zero as expressions at the end (random
  points, then ``simplify`` when small), since the polynomials are not canonical where
  their generators are related (sin² + cos² = 1).

It never calls ``sympy.series``, which is slow on trigonometric Lagrangians.
"""
from __future__ import annotations

import contextlib
import functools
import math
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Mapping, Sequence

import sympy as sp
from sympy.polys.domains import QQ

from ..errors import ModelError
from ..groupoids.analytic import AnalyticCoefficient

_EXACT = 10**9  # "exact to every power": precision of expressions free of h


# --------------------------------------------------------------------------------------
# Coefficients: sparse Laurent polynomials in the atoms of the expressions
# --------------------------------------------------------------------------------------
_QQ = QQ.dtype


class _Generators:
    """The generators of one expansion's coefficient polynomials (jets, parameters,
    transcendental values such as sin(q), anything not built by +, ×, integer powers):
    expression ↔ index, and a table of monomial products. It lives as long as the
    outermost call decorated with :func:`expansion_scope`, so nothing outlives a call and
    threads do not share it."""

    __slots__ = ("exprs", "index", "products")

    def __init__(self):
        self.exprs: list[sp.Expr] = []
        self.index: dict[sp.Expr, int] = {}
        self.products: dict[tuple, tuple] = {}


_SCOPE: ContextVar[_Generators | None] = ContextVar("symvi_series_generators", default=None)


@contextlib.contextmanager
def in_scope(table: "_Generators"):
    """Compute with ``table``'s generators inside the block (an object that keeps
    polynomials, such as the jets, re-enters the table they were made in)."""
    token = _SCOPE.set(table)
    try:
        yield table
    finally:
        _SCOPE.reset(token)


def active_generators() -> "_Generators | None":
    """The generator table of the current expansion, if one is running."""
    return _SCOPE.get()


def expansion_scope(function):
    """Run ``function`` with a fresh generator table (:class:`_Generators`), or with the
    caller's when one is active: decorate every entry point that computes with series."""
    @functools.wraps(function)
    def scoped(*args, **kwargs):
        if _SCOPE.get() is not None:
            return function(*args, **kwargs)
        with in_scope(_Generators()):
            return function(*args, **kwargs)
    return scoped


def _table() -> _Generators:
    table = _SCOPE.get()
    if table is None:
        raise RuntimeError("series arithmetic outside an expansion scope: decorate the entry "
                           "point with symvi.checks.series.expansion_scope")
    return table


def _generator(expr: sp.Expr) -> int:
    table = _table()
    index = table.index.get(expr)
    if index is None:
        index = table.index[expr] = len(table.exprs)
        table.exprs.append(expr)
    return index


def generator_expr(index: int) -> sp.Expr:
    """The expression of generator ``index`` in the current scope."""
    return _table().exprs[index]


def _monomial_product(a: tuple, b: tuple) -> tuple:
    if not a:
        return b
    if not b:
        return a
    products = _table().products
    key = (a, b)
    result = products.get(key)
    if result is None:
        exponents = dict(a)
        for i, e in b:
            total = exponents.get(i, 0) + e
            if total:
                exponents[i] = total
            else:
                del exponents[i]
        result = products[key] = tuple(sorted(exponents.items()))
        if len(products) > 300_000:
            products.clear()
    return result


class _Poly:
    """Σ c·Π g_i^{e_i}: rational coefficients c, integer (possibly negative) exponents of
    the generators g_i. Much faster than ``sympy.expand`` on products of large sums; not
    canonical where the generators are related (sin² + cos² = 1), which only costs size —
    coefficients are tested for zero as expressions (:func:`_is_zero`)."""

    __slots__ = ("terms",)

    def __init__(self, terms: dict):
        self.terms = terms

    def __bool__(self) -> bool:
        return bool(self.terms)

    def __add__(self, other: "_Poly") -> "_Poly":
        if len(other.terms) > len(self.terms):
            self, other = other, self
        terms = dict(self.terms)
        for m, c in other.terms.items():
            v = terms.get(m)
            if v is None:
                terms[m] = c
            else:
                v += c
                if v:
                    terms[m] = v
                else:
                    del terms[m]
        return _Poly(terms)

    def __mul__(self, other: "_Poly") -> "_Poly":
        terms: dict = {}
        for m1, c1 in self.terms.items():
            for m2, c2 in other.terms.items():
                m = _monomial_product(m1, m2)
                v = terms.get(m)
                terms[m] = c1 * c2 if v is None else v + c1 * c2
        return _Poly({m: c for m, c in terms.items() if c})

    def scale(self, c) -> "_Poly":
        return _Poly({m: v * c for m, v in self.terms.items()}) if c else _Poly({})

    def power(self, n: int) -> "_Poly":
        result, base = _Poly.constant(1), self
        while n:
            if n & 1:
                result = result * base
            n >>= 1
            if n:
                base = base * base
        return result

    def inverse(self) -> "_Poly":
        """1/self: exact for a single term, else a new generator (self)^{-1}."""
        if len(self.terms) == 1:
            (m, c), = self.terms.items()
            return _Poly({tuple((i, -e) for i, e in m): 1 / c})
        if not self.terms:
            raise ZeroDivisionError("inverse of the zero coefficient")
        return _Poly({((_generator(self.as_expr()), -1),): _QQ(1)})

    @staticmethod
    def constant(c) -> "_Poly":
        c = _QQ(c)
        return _Poly({(): c} if c else {})

    @staticmethod
    def of(expr) -> "_Poly":
        """Conversion of a SymPy expression."""
        expr = sp.sympify(expr)
        if expr.is_Rational:
            return _Poly.constant(_QQ(int(expr.p), int(expr.q)))
        if expr.is_Add:
            result = _Poly({})
            for a in expr.args:
                result = result + _Poly.of(a)
            return result
        if expr.is_Mul:
            result = _Poly.constant(1)
            for a in expr.args:
                result = result * _Poly.of(a)
            return result
        if expr.is_Pow and expr.exp.is_Integer:
            n = int(expr.exp)
            base = _Poly.of(expr.base)
            if n >= 0:
                return base.power(n)
            if len(base.terms) == 1:
                return base.inverse().power(-n)
            return _Poly({((_generator(expr.base), n),): _QQ(1)})
        return _Poly({((_generator(expr), 1),): _QQ(1)})

    def as_expr(self) -> sp.Expr:
        exprs = _table().exprs
        return sp.Add(*[QQ.to_sympy(c) * sp.Mul(*[exprs[i]**e for i, e in m])
                        for m, c in self.terms.items()])


# --------------------------------------------------------------------------------------
# Truncated Laurent series in one symbol
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Series:
    """Σ_p terms[p]·h^p, exact for every power ≤ ``prec`` (higher powers unknown)."""

    terms: Mapping[int, _Poly]
    prec: int

    def valuation(self) -> int:
        """Lower bound of the lowest power with a non-zero coefficient."""
        nonzero = [p for p, c in self.terms.items() if c]
        return min(nonzero) if nonzero else self.prec + 1

    def coefficient(self, p: int) -> sp.Expr:
        c = self.terms.get(p)
        return c.as_expr() if c is not None else sp.Integer(0)


def _truncate(terms: Mapping[int, _Poly], prec: int) -> _Series:
    return _Series({p: c for p, c in terms.items() if p <= prec and c}, prec)


def _series_of(terms: Mapping[int, sp.Expr], prec: int) -> _Series:
    """A series from SymPy coefficients."""
    return _truncate({p: _Poly.of(c) for p, c in terms.items()}, prec)


def _add(a: _Series, b: _Series) -> _Series:
    terms = dict(a.terms)
    for p, c in b.terms.items():
        terms[p] = terms[p] + c if p in terms else c
    return _truncate(terms, min(a.prec, b.prec))


def _mul(a: _Series, b: _Series, limit: int) -> _Series:
    va, vb = a.valuation(), b.valuation()
    prec = min(limit, a.prec + vb, b.prec + va)
    terms: dict[int, _Poly] = {}
    for p, c in a.terms.items():
        for q, d in b.terms.items():
            if p + q <= prec:
                terms[p + q] = terms[p + q] + c * d if p + q in terms else c * d
    return _truncate(terms, prec)


def _scaled(s: _Series, c) -> _Series:
    """c·s for a rational c."""
    return _truncate({p: v.scale(_QQ(c)) for p, v in s.terms.items()}, s.prec)


def _times(s: _Series, c: _Poly) -> _Series:
    return _truncate({p: v * c for p, v in s.terms.items()}, s.prec)


class _Expander:
    """Laurent expansion of expressions in ``step`` with some symbols replaced by series.

    ``definitions`` are named intermediate quantities (symbol → expression in the atoms and
    earlier definitions, e.g. a kernel's base points x_j = β(x_{j−1}, f_{j−1})), expanded
    on demand.
    """

    def __init__(self, step: sp.Symbol, atoms: Mapping[sp.Symbol, _Series],
                 definitions: Mapping[sp.Symbol, sp.Expr] | None = None):
        self.step, self.atoms = step, dict(atoms)
        self.definitions = dict(definitions or {})
        self._watch = frozenset(self.atoms) | frozenset(self.definitions) | {step}
        self._valuations: dict[sp.Expr, int] = {}
        self._depends: dict[sp.Expr, bool] = {}
        self._series: dict[tuple[sp.Expr, int], _Series] = {}

    def depends(self, expr: sp.Expr) -> bool:
        if expr not in self._depends:
            self._depends[expr] = bool(expr.free_symbols & self._watch)
        return self._depends[expr]

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
        if expr in self.definitions:
            return self.valuation(self.definitions[expr])
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
            return int(expr.exp) * self.true_order(expr.base)
        return 0  # analytic function of an argument that is O(1)

    def true_order(self, expr: sp.Expr) -> int:
        """The lowest power of h with a coefficient that is not zero."""
        guess = self.valuation(expr)
        for extra in range(0, 8):
            s = self.series(expr, guess + extra)
            leading = [p for p, c in sorted(s.terms.items()) if not _is_zero(c.as_expr())]
            if leading:
                return leading[0]
        raise ModelError(f"cannot find the order in h of {expr} (it may vanish identically)")

    def series(self, expr: sp.Expr, limit: int) -> _Series:
        """Series of ``expr`` exact through h**limit (or less, as its ``prec`` says).

        Always computed at least through the lower bound of ``expr``'s order: an empty
        series says nothing about the order, and products of such series would lose
        precision (a factor's limit is negative when its partner carries a power of h).
        """
        if self.depends(expr):
            limit = max(limit, self.valuation(expr))
        key = (expr, limit)
        if key not in self._series:
            self._series[key] = self._compute(expr, limit)
        return self._series[key]

    def _compute(self, expr: sp.Expr, limit: int) -> _Series:
        if not self.depends(expr):
            return _series_of({0: expr}, _EXACT)
        if expr == self.step:
            return _series_of({1: 1}, _EXACT)
        if expr in self.atoms:
            s = self.atoms[expr]
            return _truncate(s.terms, min(s.prec, limit))
        if expr in self.definitions:
            return self.series(self.definitions[expr], limit)
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
        if isinstance(expr, AnalyticCoefficient):
            return self._coefficient(type(expr), expr.args[0], limit)
        if isinstance(expr, sp.Function) and len(expr.args) == 1:
            x = sp.Dummy("x")
            return self._analytic(expr.func(x), x, expr.args[0], limit)
        raise ModelError(f"cannot expand {expr} in {self.step}: only sums, products, powers "
                         f"and analytic functions of one argument are supported")

    def _product(self, factors: Sequence[sp.Expr], limit: int) -> _Series:
        vals = [self.valuation(f) for f in factors]
        total = sum(vals)
        result, remaining = _series_of({0: 1}, _EXACT), total
        for f, v in zip(factors, vals):
            remaining -= v  # the partial product must be exact through limit − remaining
            result = _mul(result, self.series(f, limit - (total - v)), limit - remaining)
        return result

    def _integer_power(self, base: sp.Expr, m: int, limit: int) -> _Series:
        if base == self.step:
            return _series_of({m: 1}, _EXACT)
        if m > 0:
            return self._product([base] * m, limit)
        m = -m
        w = self.true_order(base)
        # base = c h^w (1 + u), u = O(h): base^{-m} = c^{-m} h^{-mw} Σ_j binom(−m, j) u^j.
        need = limit + m * w
        if need < 0:  # base^{-m} = O(h^{-mw}) has no term through h^limit
            return _Series({}, limit)
        b = self.series(base, w + need)
        inverse = b.terms[w].inverse()
        # (terms below h^w are zero: non-canonical forms of 0 that true_order skipped)
        u = _truncate({p - w: cp * inverse for p, cp in b.terms.items() if p > w},
                      b.prec - w)
        total = _series_of({0: 1}, _EXACT)
        power = _series_of({0: 1}, _EXACT)
        for j in range(1, need + 1):
            power = _mul(power, u, need)
            total = _add(total, _scaled(power, int(sp.binomial(-m, j))))
        total = _truncate(total.terms, min(total.prec, need, u.prec))
        scale = inverse.power(m)
        return _truncate({p - m * w: scale * cp for p, cp in total.terms.items()},
                         min(limit, total.prec - m * w))

    def _analytic(self, g: sp.Expr, x: sp.Symbol, argument: sp.Expr, limit: int) -> _Series:
        a = self.series(argument, max(limit, 0))
        if a.valuation() < 0:
            raise ModelError(f"cannot expand {g.subs(x, argument)}: its argument is "
                             f"unbounded as {self.step} → 0")
        a0 = a.coefficient(0)
        delta = _truncate({p: c for p, c in a.terms.items() if p != 0}, a.prec)
        prec = min(limit, a.prec)
        result = _series_of({0: g.subs(x, a0)}, _EXACT)
        power = _series_of({0: 1}, _EXACT)
        derivative = g
        for k in range(1, prec + 1):
            power = _mul(power, delta, prec)
            derivative = sp.diff(derivative, x)
            coeff = _Poly.of(derivative.subs(x, a0) / math.factorial(k))
            result = _add(result, _times(power, coeff))
        return _truncate(result.terms, prec)

    def _coefficient(self, cls, argument: sp.Expr, limit: int) -> _Series:
        """c(s) of the exponential retraction (:mod:`symvi.groupoids.analytic`) through its
        exact Taylor series in s; its argument s = θ²(hξ) is O(h²)."""
        a = self.series(argument, max(limit, 0))
        if a.terms.get(0) or a.valuation() < 1:
            raise ModelError(f"cannot expand {cls.__name__}({argument}): its argument does "
                             f"not vanish as {self.step} → 0")
        v, prec = a.valuation(), min(limit, a.prec)
        result = _series_of({0: cls.series[0]}, _EXACT)
        power = _series_of({0: 1}, _EXACT)
        for j in range(1, prec // v + 1):
            if j >= len(cls.series):
                raise ModelError(f"{cls.__name__}: {len(cls.series)} Taylor terms are not "
                                 f"enough for h^{limit}")
            power = _mul(power, a, prec)
            result = _add(result, _times(power, _Poly.of(cls.series[j])))
        return _truncate(result.terms, prec)


def _is_zero(expr: sp.Expr) -> bool:
    """Whether ``expr`` vanishes identically.

    ``expand`` decides polynomial identities; otherwise the expression is evaluated at two
    random points (exact rational arithmetic where it applies, 50 digits otherwise), which
    rejects a non-zero expression at once — ``simplify`` on a large non-zero coefficient
    (an inconsistent residual) can take minutes. An expression that vanishes at both
    points is confirmed by ``simplify`` when small, and taken to be zero when large (a
    polynomial or rational function vanishing at random rational points is zero with
    probability 1; transcendental ones to 50 digits). Large expressions the points cannot
    decide go to ``cancel``.
    """
    expr = sp.expand(expr)
    if expr == 0:
        return True
    verdicts = [vanishes_at(expr, seed) for seed in (0, 1)]
    if False in verdicts:
        return False
    small = sp.count_ops(expr) < 400
    if small:
        return sp.simplify(expr) == 0
    if None in verdicts:      # large, and the random points did not decide
        return sp.cancel(expr) == 0
    return True


def vanishes_at(expr: sp.Expr, seed: int) -> bool | None:
    """Whether ``expr`` is zero at a random point (None: could not tell)."""
    import random
    rng = random.Random(seed * 7919 + 17)
    values = {s: sp.Rational(rng.randint(2000, 9000), 6007)
              for s in sorted(expr.free_symbols, key=str)}
    terms = [term.xreplace(values) for term in sp.Add.make_args(expr)]
    total = sp.Add(*terms)
    if total == 0:
        return True
    if total.is_Rational:
        return False
    value = total.evalf(50)
    if not value.is_Number or value.has(sp.zoo, sp.nan, sp.oo, -sp.oo):
        return None
    scale = max((abs(t.evalf(50)) for t in terms), default=sp.Integer(0))
    if not scale.is_Number:
        return None
    return bool(abs(value) <= sp.Float("1e-35", 50) * max(scale, sp.Float("1e-300", 50)))
