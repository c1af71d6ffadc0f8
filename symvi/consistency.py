"""Consistency of discrete Euler–Lagrange residuals with the continuous equations (DESIGN.md §5).

The discrete residual at the middle node of a stencil, R(z; h), is expanded in h along a
smooth curve. The coefficient of the lowest power of h that survives must be the continuous
Euler–Lagrange (Euler–Poincaré, Lagrange–Poincaré) expression; the power of the next
surviving term measures how well the residual approximates it.

Conventions. Every expected expression is the *variational derivative* of the action,
E = δS/δ(node), with one sign for every groupoid and order:

* pair groupoid, :func:`euler_lagrange`: E(L) = ∂L/∂q − d/dt ∂L/∂q̇ + d²/dt² ∂L/∂q̈,
  which is minus the usual first-order expression d/dt ∂L/∂q̇ − ∂L/∂q and equal to the
  usual second-order one;
* on a Lie algebroid (q, y; anchor ρ, structure functions C), E = −EL_r(L) with
  the operator of Appendix C.2 (:func:`symvi.control.euler_lagrange_operator`)

      EL₁(L)_α = d/dt ∂L/∂y^α − ρ^i_α ∂L/∂q^i + C^γ_{αβ} y^β ∂L/∂y^γ

  and its second-order version (paper eq. ``ecuacionesvakonomoalgebroides2``, times −1),
  with P_γ = ∂L̃/∂y^γ − d/dt ∂L̃/∂ẏ^γ,

      EL₂(L̃)_α = d/dt P_α − ρ^i_α ∂L̃/∂q^i + C^γ_{αβ} y^β P_γ,

  where d/dt F = ∂F/∂q^i ρ^i_β y^β + Σ_k ∂F/∂y^{(k)} y^{(k+1)}. It is the first-order
  operator with ∂L/∂y replaced by the second-order momentum P (δy = η̇ + [y, η] enters the
  action through P after one integration by parts). On TQ (ρ = I, C = 0) EL_r = −E(L) of
  the pair groupoid; on so(3) with L̃ = ½|Ω̇ − f(Ω)|² it is −(d/dt + Ω×)(u̇ + Df(Ω)ᵀu),
  u = Ω̇ − f(Ω) (ERRATA.md, "Agree"). With constraints Φ^A and multipliers λ_A(t) the
  expected expression is E(L̃ + λ_A Φ^A) with λ a function of time, so that d/dt acts on
  it (the corrected form of ERRATA.md item 8: −d/dt(∂L̃/∂y^α + λ_A ∂Φ^A/∂y^α)).

With these the residual is ∂S_d/∂(node) and a node carries a time span h of the action, so
R = h·E(t_node) + O(h²). For a symmetric rule (midpoint, trapezoid, three-point, the Lie
rules with a symmetric retraction τ(−x) = τ(x)⁻¹) the residual is odd in h and the next
term is O(h³): the relative consistency error is O(h²).

Sampling. The stencil of the residual at node c (the middle one) is K = 2r consecutive
elements (x_0, f_0, …, f_{K−1}) with node j at time t + (j − c)h:

* pair groupoid (and pair factors of products): the fibre part of element i is its target
  node, f_i = q(t + (i + 1 − c)h), and x_0 = q(t − ch);
* Lie groups and action groupoids (and their factors): f_i = ξ_i, the group increment
  divided by h, sampled at the middle of the element, ξ_i = y(t + (i + ½ − c)h) (for a
  symmetric retraction τ⁻¹(g(t_i)⁻¹g(t_{i+1}))/h = y(t_i + h/2) + O(h²), so either choice
  has the same leading term and the same parity in h);
* the base point of an action groupoid is x_0 = q(t − ch); the later base points follow
  from the kernel's definitions x_j = β(x_{j−1}, f_{j−1}) = φ(x_{j−1}, τ(hξ_{j−1}));
* multipliers λ^w of window w (constrained models) are sampled at the window's middle
  node, λ^w = λ(t + (w + r/2 − c)h).

Jets: the pair groupoid's expansion uses the derivatives q^{(k)}(t) as symbols. On an
algebroid the independent quantities are the base point q(t) and the derivatives y^{(k)}(t)
of the fibre curve; derivatives of q follow from the anchor, q̇ = ρ(q) y (for a pair factor
y = q̇, so q^{(k+1)} = y^{(k)}). Results are reported as functions of t: base coordinates
q_i(t), fibre coordinates y_α(t) and their derivatives (a pair factor's y^{(k)} as q^{(k+1)}).

Method. The expansion is a small truncated Laurent-series arithmetic over the residual's
expression tree (sums, products, integer powers, analytic functions of one argument — the
exponential retraction's coefficient functions through their exact Taylor series) that
tracks up to which power every intermediate result is exact. It never calls
``sympy.series`` on the substituted residual, which is slow for trigonometric Lagrangians,
and derivatives are plain *jet* symbols until the result is reported, so the identities
needed are polynomial ones. The coefficients are sparse Laurent polynomials with rational
coefficients in the atoms they contain (jets, parameters, values such as sin(q)) rather
than SymPy expressions — ``sympy.expand`` of products of large sums was the cost — and are
tested for zero as expressions at the end (:func:`_is_zero`: random points, then
``simplify`` when small).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import sympy as sp
from sympy.core.function import AppliedUndef
from sympy.polys.domains import QQ

from .derive import DerivedModel, derive
from .discretise import discretise
from .errors import ModelError
from .groupoids.analytic import AnalyticCoefficient
from .model import Model

#: Time variable of the continuous curve the nodes are sampled from.
TIME = sp.Symbol("t", real=True)

_EXACT = 10**9  # "exact to every power": precision of expressions free of h


# --------------------------------------------------------------------------------------
# Coefficients: sparse Laurent polynomials in the atoms of the expressions
# --------------------------------------------------------------------------------------
_QQ = QQ.dtype
#: Generators of the coefficient polynomials (jets, parameters, transcendental values such
#: as sin(q), anything not built by +, ×, integer powers): expression ↔ index.
_GENERATORS: list[sp.Expr] = []
_GENERATOR_INDEX: dict[sp.Expr, int] = {}
_MONOMIAL_PRODUCTS: dict[tuple, tuple] = {}


def _generator(expr: sp.Expr) -> int:
    index = _GENERATOR_INDEX.get(expr)
    if index is None:
        index = _GENERATOR_INDEX[expr] = len(_GENERATORS)
        _GENERATORS.append(expr)
    return index


def _monomial_product(a: tuple, b: tuple) -> tuple:
    if not a:
        return b
    if not b:
        return a
    key = (a, b)
    result = _MONOMIAL_PRODUCTS.get(key)
    if result is None:
        exponents = dict(a)
        for i, e in b:
            total = exponents.get(i, 0) + e
            if total:
                exponents[i] = total
            else:
                del exponents[i]
        result = _MONOMIAL_PRODUCTS[key] = tuple(sorted(exponents.items()))
        if len(_MONOMIAL_PRODUCTS) > 300_000:
            _MONOMIAL_PRODUCTS.clear()
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
        return sp.Add(*[QQ.to_sympy(c) * sp.Mul(*[_GENERATORS[i]**e for i, e in m])
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
            return int(expr.exp) * self._true_order(expr.base)
        return 0  # analytic function of an argument that is O(1)

    def _true_order(self, expr: sp.Expr) -> int:
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
        w = self._true_order(base)
        # base = c h^w (1 + u), u = O(h): base^{-m} = c^{-m} h^{-mw} Σ_j binom(−m, j) u^j.
        need = limit + m * w
        if need < 0:  # base^{-m} = O(h^{-mw}) has no term through h^limit
            return _Series({}, limit)
        b = self.series(base, w + need)
        inverse = b.terms[w].inverse()
        # (terms below h^w are zero: non-canonical forms of 0 that _true_order skipped)
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
    verdicts = [_vanishes_at(expr, seed) for seed in (0, 1)]
    if False in verdicts:
        return False
    small = sp.count_ops(expr) < 400
    if small:
        return sp.simplify(expr) == 0
    if None in verdicts:      # large, and the random points did not decide
        return sp.cancel(expr) == 0
    return True


def _vanishes_at(expr: sp.Expr, seed: int) -> bool | None:
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
# Jets on a Lie algebroid: q(t), y^{(k)}(t) and multipliers λ^{(k)}(t) as plain symbols
# --------------------------------------------------------------------------------------
def _layout(groupoid) -> list[tuple[str, int | None]]:
    """How each fibre coordinate of ``groupoid`` is sampled along a curve.

    ``("node", i)``: a pair factor's fibre part is the target node, base coordinate i;
    ``("mid", None)``: a group increment ξ, sampled at the middle of the element.
    """
    kind = groupoid.kind
    if kind == "product":
        out, offset = [], 0
        for factor in groupoid.factors:
            out += [(k, None if i is None else i + offset) for k, i in _layout(factor)]
            offset += factor.source_dim
        return out
    if kind == "pair":
        return [("node", i) for i in range(groupoid.fibre_dim)]
    if kind in ("lie", "action"):
        return [("mid", None)] * groupoid.fibre_dim
    raise ModelError(f"consistency expansions do not know how to sample the fibre of a "
                     f"{kind!r} groupoid along a curve")


def unsupported(groupoid) -> str | None:
    """Why the expansion cannot sample ``groupoid`` along a curve, or None if it can."""
    try:
        _layout(groupoid)
    except ModelError as exc:
        return str(exc)
    return None


def component_names(groupoid) -> tuple[str, ...]:
    """Names of the residual's components (the fibre directions e_α): a pair factor's
    coordinate names, a group factor's Lie algebra coordinates."""
    if groupoid.kind == "pair":
        return tuple(groupoid.names)
    algebroid = groupoid.algebroid()
    base = [str(s) for s in algebroid.q]
    return tuple(base[i] if kind == "node" else str(y)
                 for (kind, i), y in zip(_layout(groupoid), algebroid.y))


class _AlgebroidJets:
    """Jet symbols on the algebroid of ``groupoid``: the base point q (values only), the
    derivatives y^{(k)} of the fibre curve (k ≤ depth) and of ``multipliers`` functions
    λ_A; the total derivative uses q̇ = ρ(q) y."""

    def __init__(self, groupoid, depth: int, multipliers: int = 0):
        algebroid = groupoid.algebroid()
        self.algebroid, self.depth = algebroid, depth
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
        self.fibre_functions = tuple((self.base_names[i], 1) if kind == "node" else (str(y), 0)
                                     for (kind, i), y in zip(self.layout, algebroid.y))
        self.multiplier_names = tuple(f"lambda{a}" for a in range(multipliers))
        self._base_derivatives = [[s] for s in self.q]

    def symbol_map(self) -> dict:
        """The groupoid's continuous symbols (q, y, ẏ of the algebroid) → jets."""
        a = self.algebroid
        return dict(zip(a.q, self.q)) | {y: c[0] for y, c in zip(a.y, self.y)} \
            | {v: c[1] for v, c in zip(a.ydot, self.y)}

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
        return self.base_derivative_poly(i, k).as_expr()

    def base_derivative_poly(self, i: int, k: int) -> "_Poly":
        """d^k q_i/dt^k as a coefficient polynomial (the product rule on the polynomial's
        terms: far faster than ``sympy.diff`` on the growing expanded expressions)."""
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
                    self._rules[i] = _Poly.of(sp.expand(self.derivative(_GENERATORS[i])))
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
    """EL_r(L) on jets (module doc): d/dt P_α − ρ^i_α ∂L/∂q^i + C^γ_{αβ} y^β P_γ with
    P = ∂L/∂y (r = 1) or ∂L/∂y − d/dt ∂L/∂ẏ (r = 2)."""
    y0 = [column[0] for column in jets.y]
    P = []
    for c, column in enumerate(jets.y):
        p = sp.diff(lagrangian, y0[c])
        if order == 2:
            p -= jets.derivative(sp.diff(lagrangian, column[1]))
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
    ``t`` (module doc): EL₁ of Appendix C.2 for ``order`` 1 (the same as
    :func:`symvi.control.euler_lagrange_operator`), the second-order operator EL₂ for
    ``order`` 2. ``lagrangian`` (and ``constraints``) are written in the groupoid's
    continuous symbols; with constraints Φ^A the operator acts on L + λ_A(t) Φ^A, the
    multipliers being functions ``lambda0(t)``, ``lambda1(t)``, … of time.

    Base coordinates are functions q_i(t) (never differentiated: q̇ = ρ(q) y), fibre
    coordinates y_α(t) with their derivatives (a pair factor's y^{(k)} is q^{(k+1)}).
    The variational derivative of the action is −EL_r (:func:`euler_lagrange`).
    """
    if order not in (1, 2):
        raise ModelError(f"order must be 1 or 2, got {order!r}")
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


# --------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ResidualExpansion:
    """The Taylor expansion in h of a discrete residual (or any kernel output) along a
    smooth curve.

    Attributes
    ----------
    step, time : the symbols h and t.
    terms : the non-zero coefficients, ((power, column matrix), …) in increasing power,
        in terms of functions of t and their derivatives (module doc).
    through : every power ≤ ``through`` has been computed (absent powers vanish).
    """

    step: sp.Symbol
    time: sp.Symbol
    terms: tuple[tuple[int, sp.Matrix], ...]
    through: int
    _jets: object
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
        sign, rows = self.compare(expected)
        return sign if sign is not None and not rows else None

    def compare(self, expected: sp.Matrix) -> tuple[int | None, list[int]]:
        """(s, rows): the sign s = ±1 for which the leading coefficient agrees with
        s·``expected`` in the most components, and the components where it does not
        ((None, every row) when there is no leading term)."""
        expected = sp.Matrix(expected)
        if not self._jet_terms:
            return None, list(range(expected.rows))
        lead = self._jet_terms[0][1]
        target = _to_jets(expected, self._jets, self.time)
        if lead.rows != target.rows:
            raise ModelError(f"the residual has {lead.rows} components, the expected "
                             f"expression {target.rows}")
        best = None
        for sign in (1, -1):
            rows = [i for i, (a, b) in enumerate(zip(lead, target)) if not _is_zero(a - sign * b)]
            if best is None or len(rows) < len(best[1]):
                best = (sign, rows)
            if not rows:
                break
        return best


def _to_jets(expr: sp.Matrix, jets, t: sp.Symbol) -> sp.Matrix:
    """Inverse of the jets' ``to_functions`` (derivatives beyond the jet depth are kept)."""
    return sp.Matrix(expr).applyfunc(lambda e: jets.from_functions(e, t))


def euler_lagrange(model: Model, t: sp.Symbol = TIME, *, multipliers: bool = True) -> sp.Matrix:
    """The variational derivative E of the action along functions of ``t`` (module doc).

    Pair groupoid: E(L) = ∂L/∂q − d/dt ∂L/∂q̇ + d²/dt² ∂L/∂q̈ along q_c(t). Other groupoids:
    E = −EL_r(L) on the algebroid (:func:`euler_lagrange_algebroid`). For a constrained
    model with ``multipliers``, E(L̃ + λ_A(t) Φ^A), the multipliers being functions
    ``lambda0(t)``, … Needs a model declared with a continuous Lagrangian.
    """
    if model.lagrangian is None:
        raise ModelError(f"model {model.name!r} has no continuous Lagrangian")
    constraints = tuple(model.constraints) if multipliers else ()
    if model.groupoid.kind == "pair" and not constraints:
        jets = _Jets.make(model.groupoid.names, 2 * model.order)
        return _variational_derivative(model.groupoid, model.lagrangian, model.order,
                                       jets).applyfunc(lambda e: jets.to_functions(e, t))
    return -euler_lagrange_algebroid(model.groupoid, model.lagrangian, model.order, t,
                                     constraints)


def _collect(columns: Sequence[_Series], jets, step, t, through) -> ResidualExpansion:
    powers = sorted({p for s in columns for p in s.terms})
    jet_terms = []
    for p in powers:
        entries = [s.coefficient(p) for s in columns]
        entries = [sp.Integer(0) if _is_zero(c) else sp.expand(c) for c in entries]
        if any(c != 0 for c in entries):
            jet_terms.append((p, sp.Matrix(entries)))
    terms = tuple((p, M.applyfunc(lambda e: jets.to_functions(e, t))) for p, M in jet_terms)
    return ResidualExpansion(step=step, time=t, terms=terms, through=through, _jets=jets,
                             _jet_terms=tuple(jet_terms))


def expand_residual(residual: sp.Matrix, nodes: Sequence[Sequence[sp.Symbol]],
                    step: sp.Symbol, names: Sequence[str], *, centre: int,
                    through: int, t: sp.Symbol = TIME) -> ResidualExpansion:
    """Expand ``residual`` in ``step`` with node i set to q(t + (i − centre)·h).

    ``nodes[i]`` are the coordinate symbols of node i; ``names`` name the coordinate
    functions. Every power of h up to ``through`` is computed; the node Taylor polynomials
    are lengthened until that precision is reached.
    """
    residual = sp.Matrix(residual)
    # Lower bound of the residual's order with O(1) nodes: a pole h^{-p} (the 1/h² of
    # the three-point rule's acceleration) costs p orders of the Taylor polynomials.
    probe = _Expander(step, {s: _series_of({0: s}, _EXACT) for node in nodes for s in node})
    first = through + 1 - min([0] + [probe.valuation(e) for e in residual])
    for degree in range(first, first + 11):
        jets = _Jets.make(names, degree)
        atoms = {}
        for i, node in enumerate(nodes):
            offset = i - centre
            for c, s in enumerate(node):
                atoms[s] = _series_of({k: sp.Rational(offset**k, math.factorial(k))
                                      * jets.symbols[c][k] for k in range(degree + 1)}, degree)
        expander = _Expander(step, atoms)
        columns = [expander.series(e, through) for e in residual]
        if min(s.prec for s in columns) >= through:
            break
    else:
        raise ModelError(f"could not reach precision h^{through} in the residual expansion")
    return _collect(columns, jets, step, t, through)


def _taylor(values: Sequence, offset: sp.Rational, degree: int) -> _Series:
    """Σ_k (offset·h)^k/k! values[k] (expressions or coefficient polynomials), exact
    through h^degree."""
    return _truncate({k: (v if isinstance(v, _Poly) else _Poly.of(v)).scale(
        _QQ(int((offset**k).p), int((offset**k).q) * math.factorial(k)))
        for k, v in enumerate(values[:degree + 1])}, degree)


def _stencil_atoms(jets: _AlgebroidJets, groupoid, z: Sequence[sp.Symbol], *, elements: int,
                   centre: int, order: int, degree: int, windows: int, multipliers: int,
                   with_multipliers: bool) -> dict[sp.Symbol, _Series]:
    """The sampled stencil coordinates as Taylor polynomials of degree ``degree``."""
    m, n = groupoid.source_dim, groupoid.fibre_dim
    size = m + elements * n + windows * multipliers
    if len(z) != size:
        raise ModelError(f"a stencil of {elements} elements and {windows} windows of "
                         f"{multipliers} multipliers has {size} coordinates, the kernel "
                         f"has {len(z)}")
    x0 = tuple(z[:m])
    fs = [tuple(z[m + i * n:m + (i + 1) * n]) for i in range(elements)]
    start = m + elements * n
    lams = [tuple(z[start + w * multipliers:start + (w + 1) * multipliers])
            for w in range(windows)]
    layout = _layout(groupoid)
    base = [[jets.base_derivative_poly(i, k) for k in range(degree + 1)] for i in range(m)]
    atoms = {s: _taylor(base[i], sp.Integer(-centre), degree) for i, s in enumerate(x0)}
    for i, f in enumerate(fs):
        for c, s in enumerate(f):
            kind, b = layout[c]
            if kind == "node":      # a pair factor: the target node q(t + (i + 1 − c)h)
                atoms[s] = _taylor(base[b], sp.Integer(i + 1 - centre), degree)
            else:                   # a group increment: y at the element's middle
                atoms[s] = _taylor(jets.y[c], sp.Rational(2 * (i - centre) + 1, 2), degree)
    for w, lam in enumerate(lams):  # multipliers at the window's middle node
        offset = sp.Rational(2 * (w - centre) + order, 2)
        for a, s in enumerate(lam):
            atoms[s] = (_taylor(jets.lam[a], offset, degree) if with_multipliers
                        else _Series({}, _EXACT))
    return atoms


def sample_stencil(groupoid, z: Sequence[sp.Symbol], step: sp.Symbol, *, elements: int,
                   centre: int, order: int, degree: int, windows: int = 0,
                   multipliers: int = 0, t: sp.Symbol = TIME) -> dict[sp.Symbol, sp.Expr]:
    """The values :func:`expand_stencil` gives the stencil coordinates ``z``: polynomials
    of degree ``degree`` in ``step`` whose coefficients are functions of ``t`` (module doc;
    later base points follow from the kernel's definitions)."""
    jets = _AlgebroidJets(groupoid, degree + 2 * order + 1, multipliers)
    atoms = _stencil_atoms(jets, groupoid, z, elements=elements, centre=centre, order=order,
                           degree=degree, windows=windows, multipliers=multipliers,
                           with_multipliers=True)
    return {s: jets.to_functions(sp.Add(*[c.as_expr() * step**p for p, c in a.terms.items()]), t)
            for s, a in atoms.items()}


def expand_stencil(outputs: sp.Matrix, z: Sequence[sp.Symbol], groupoid, step: sp.Symbol, *,
                   elements: int, centre: int, order: int, through: int,
                   definitions: Sequence[tuple[sp.Symbol, sp.Expr]] = (),
                   windows: int = 0, multipliers: int = 0, with_multipliers: bool = True,
                   t: sp.Symbol = TIME) -> ResidualExpansion:
    """Expand kernel ``outputs`` in ``step`` along a smooth curve on any groupoid.

    ``z`` = (x_0, f_0, …, f_{K−1}, λ^0, …, λ^{W−1}) is a stencil of K = ``elements``
    consecutive elements (and the ``multipliers`` multipliers of each of W = ``windows``
    windows of ``order`` elements); ``definitions`` are the kernel's named base points.
    Node j is at time t + (j − ``centre``)·h; the sampling is that of the module doc.
    Without ``with_multipliers`` the multipliers are set to zero. Every power through
    h^``through`` is computed.
    """
    outputs = sp.Matrix(outputs)
    definitions = dict(definitions)
    # Lower bound of the outputs' order in h with O(1) coordinates: a pole h^{-p} costs
    # p orders of the Taylor polynomials.
    probe = _Expander(step, {s: _series_of({0: s}, _EXACT) for s in z}, definitions)
    lowest = min([0] + [probe.valuation(e) for e in outputs])
    first = max(through + 1 - lowest, 1)
    for degree in range(first, first + 8):
        jets = _AlgebroidJets(groupoid, degree + 2 * order + 1,
                              multipliers if with_multipliers else 0)
        atoms = _stencil_atoms(jets, groupoid, z, elements=elements, centre=centre,
                               order=order, degree=degree, windows=windows,
                               multipliers=multipliers, with_multipliers=with_multipliers)
        expander = _Expander(step, atoms, definitions)
        columns = [expander.series(e, through) for e in outputs]
        if min(s.prec for s in columns) >= through:
            break
    else:
        raise ModelError(f"could not reach precision h^{through} in the residual expansion")
    return _collect(columns, jets, step, t, through)


def _stencil_kernel(model: Model, dm: DerivedModel):
    """(residual, kernel, windows, multipliers per window) of the residual at the middle
    node: the step kernel, or the stencil kernel of a constrained model."""
    if model.constraints:
        if "stencil" not in [k.name for k in dm.kernels]:
            raise ModelError(f"model {model.name!r} has constraints but no stencil kernel")
        kernel = dm.kernel("stencil")
        return dict(kernel.outputs)["residual"], kernel, dm.order + 1, dm.constraint_count
    kernel = dm.kernel("step")
    return dict(kernel.outputs)["residual"], kernel, 0, 0


def residual_expansion(model: Model, *, derived: DerivedModel | None = None,
                       terms: int = 2, max_power: int = 7, t: sp.Symbol = TIME,
                       multipliers: bool = True) -> ResidualExpansion:
    """Expand the discrete Euler–Lagrange residual of ``model`` in h.

    The residual is the ``step`` kernel of ``derive(discretise(model))`` (pass ``derived``
    to reuse one): on the pair groupoid its stencil is the nodes q_{j−r} … q_{j+r}, on
    other groupoids the 2r elements around the node (module doc). A constrained model has
    no step kernel: its ``stencil`` kernel's residual is expanded, with the multipliers of
    its r+1 windows sampled from smooth λ_A(t) (set to zero without ``multipliers``).
    Powers are computed until ``terms`` non-zero coefficients are found or ``max_power``
    is reached.
    """
    dm = derived if derived is not None else derive(discretise(model))
    if model.groupoid.kind == "pair" and not model.constraints:
        kernel = dm.kernel("step")
        residual = dict(kernel.outputs)["residual"]
        n, r = dm.fibre_dim, dm.order
        nodes = [kernel.z[i * n:(i + 1) * n] for i in range(2 * r + 1)]
        through = min(3, max_power)
        while True:
            expansion = expand_residual(residual, nodes, dm.step, model.groupoid.names,
                                        centre=r, through=through, t=t)
            if len(expansion.terms) >= terms or through >= max_power:
                return expansion
            through = min(max_power, through + 2)
    residual, kernel, windows, count = _stencil_kernel(model, dm)
    r = dm.order
    through = min(3, max_power)
    while True:
        expansion = expand_stencil(residual, kernel.z, model.groupoid, dm.step,
                                   elements=2 * r, centre=r, order=r, through=through,
                                   definitions=kernel.definitions, windows=windows,
                                   multipliers=count, with_multipliers=multipliers, t=t)
        if len(expansion.terms) >= terms or through >= max_power:
            return expansion
        through = min(max_power, through + 2)


def constraint_expansion(model: Model, *, derived: DerivedModel | None = None,
                         terms: int = 2, max_power: int = 5,
                         t: sp.Symbol = TIME) -> ResidualExpansion:
    """Expand the discrete constraints Φ_d of a constrained ``model`` on one window of r
    elements centred at t (its middle node); consistent ones give h·Φ(t) + O(h³)."""
    if not model.constraints:
        raise ModelError(f"model {model.name!r} has no constraints")
    dm = derived if derived is not None else derive(discretise(model))
    kernel = dm.kernel("constraint")
    value = dict(kernel.outputs)["value"]
    r = dm.order
    if r % 2:
        raise ModelError("a window of an odd number of elements has no middle node")
    through = min(3, max_power)
    while True:
        expansion = expand_stencil(value, kernel.z, model.groupoid, dm.step, elements=r,
                                   centre=r // 2, order=r, through=through,
                                   definitions=kernel.definitions, t=t)
        if len(expansion.terms) >= terms or through >= max_power:
            return expansion
        through = min(max_power, through + 2)


@dataclass(frozen=True)
class ConsistencyReport:
    """Outcome of :func:`check_consistency`.

    ``sign`` is +1 when R = h^power·E + …, −1 for −E, None when the leading term is not ±E
    (the residual is inconsistent); ``order`` is the consistency order; ``expected`` is E
    (:func:`euler_lagrange`). For a constrained model ``constraints`` reports the discrete
    constraints Φ_d against h·Φ in the same way.
    """

    model: str
    power: int | None
    sign: int | None
    order: int | None
    expansion: ResidualExpansion
    expected: sp.Matrix | None = None
    constraints: "ConsistencyReport | None" = None

    @property
    def consistent(self) -> bool:
        return self.sign is not None and (self.constraints is None
                                          or self.constraints.consistent)


def check_consistency(model: Model, *, derived: DerivedModel | None = None,
                      lagrangian_model: Model | None = None, multipliers: bool = True,
                      max_power: int = 7) -> ConsistencyReport:
    """Compare the leading term of ``model``'s residual with the continuous equations.

    ``lagrangian_model`` supplies the continuous Lagrangian (and constraints) when
    ``model`` was declared with a discrete one (default: ``model`` itself). For a
    constrained model the residual with smooth multipliers is compared with
    E(L̃ + λ_A Φ^A) (``multipliers=False``: multipliers zero, against E(L̃)), and its
    discrete constraints with h·Φ.
    """
    reference = lagrangian_model if lagrangian_model is not None else model
    dm = derived if derived is not None else derive(discretise(model))
    expansion = residual_expansion(model, derived=dm, multipliers=multipliers,
                                   max_power=max_power)
    expected = euler_lagrange(reference, expansion.time, multipliers=multipliers)
    sign = expansion.sign_against(expected)
    constraints = None
    if model.constraints and reference.constraints:
        c = constraint_expansion(model, derived=dm, t=expansion.time)
        target = constraint_functions(reference, expansion.time)
        constraints = ConsistencyReport(model=model.name, power=c.leading_power,
                                        sign=c.sign_against(target), order=c.order,
                                        expansion=c, expected=target)
    return ConsistencyReport(model=model.name, power=expansion.leading_power, sign=sign,
                             order=expansion.order, expansion=expansion, expected=expected,
                             constraints=constraints)


def compact(expr, t: sp.Symbol = TIME, width: int = 300) -> str:
    """A short text of a coefficient: f(t) → f and its derivatives → f', f'', f''', f^(4), …;
    cut at ``width`` characters."""
    expr = sp.sympify(expr)
    mapping = {}
    for d in expr.atoms(sp.Derivative):
        if isinstance(d.expr, AppliedUndef):
            k = d.derivative_count
            mark = "'" * k if k <= 3 else f"^({k})"
            mapping[d] = sp.Symbol(d.expr.func.__name__ + mark)
    for f in expr.atoms(AppliedUndef):
        if f.args == (t,):
            mapping[f] = sp.Symbol(f.func.__name__)
    text = sp.sstr(expr.xreplace(mapping))
    return text if len(text) <= width else text[:width - 1] + "…"
