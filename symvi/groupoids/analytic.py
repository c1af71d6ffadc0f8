"""Analytic functions of a matrix whose minimal polynomial is z^a (z² + θ²)^b.

The exponential retraction needs exp(X) and dexp⁻¹_X = ad_X / (e^{ad_X} − 1) (DESIGN.md
§2). For so(3), se(2) and se(3) both X and ad_X satisfy p(M) = M^a (M² + θ²)^b = 0 with
θ² = s(x) a quadratic form in the coordinates, so any analytic f gives

    f(M) = Σ_{k < a+2b} c_k(s) M^k,

with coefficients c_k analytic in s (Hermite interpolation of f at 0 and ±iθ). Their closed
forms divide by powers of θ, so each c_k is a SymPy function :class:`AnalyticCoefficient`
that carries both its closed form (used for s ≥ ``SWITCH``) and its exact Taylor series in
s (used below it): nothing divides by zero near ξ = 0, in SymPy, NumPy or the emitted C.
Derivatives are coefficients of the same kind, so the derivation engine differentiates
through them.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache
from typing import Callable

import numpy as np
import sympy as sp

#: θ = √s in closed forms.
THETA = sp.Symbol("theta", positive=True)
#: Below this s the Taylor series is used, above it the closed form. Just above π², the
#: exponential's chart θ < π: inside the chart only the series is used (the closed forms
#: of the derivatives cancel badly at moderate θ; the series of dexp⁻¹, with radius 4π² in
#: s, converges like (s/4π²)^j, below 1e-20 with the 40 terms kept).
SWITCH = 10.0
_Z, _R, _U, _S = sp.symbols("z r u s")
_TERMS = 40


@dataclass(frozen=True)
class Family:
    """An analytic f(z) = E(z²) + z·O(z²), given by E and O as expressions in r = √u."""

    name: str
    even: sp.Expr
    odd: sp.Expr
    taylor: Callable[[int], sp.Rational]


def _bernoulli_over_factorial(n: int) -> sp.Rational:
    # z/(e^z − 1) = Σ B_n zⁿ/n! with B_1 = −1/2 (SymPy ≥ 1.12 returns +1/2 for n = 1).
    return sp.Rational(-1, 2) if n == 1 else sp.bernoulli(n) / sp.factorial(n)


EXP = Family("exp", sp.cosh(_R), sp.sinh(_R) / _R, lambda n: 1 / sp.factorial(n))
#: The Cayley map (1 + z/2)/(1 − z/2): its coefficients are rational in s.
CAYLEY = Family("cay", (1 + _R**2 / 4) / (1 - _R**2 / 4), 1 / (1 - _R**2 / 4),
                lambda n: sp.S.One if n == 0 else sp.Rational(1, 2 ** (n - 1)))
DEXPINV = Family("dexpinv", _R / 2 * sp.coth(_R / 2), sp.Rational(-1, 2),
                 _bernoulli_over_factorial)


#: The families by name (a coefficient's label starts with it).
FAMILIES = {f.name: f for f in (EXP, CAYLEY, DEXPINV)}
_LABEL = re.compile(r"(?P<family>[a-z]+)_(?P<a>\d+)_(?P<b>\d+)_c(?P<k>\d+)(?P<ds>(?:_ds)*)")


class AnalyticCoefficient(sp.Function):
    """c(s), analytic in s = θ² ≥ 0: closed form in θ above SWITCH, Taylor series below."""

    nargs = 1
    closed: sp.Expr = sp.S.Zero
    series: tuple[sp.Rational, ...] = ()

    def fdiff(self, argindex=1):
        return derivative(type(self))(self.args[0])

    def _eval_evalf(self, prec):
        # Arbitrary precision: the series only where its 40 terms exceed any precision
        # asked for, else the closed form with guard digits against its cancellation.
        s = self.args[0].evalf(prec + 100)
        if not s.is_Number:
            return None
        if abs(s) < 1e-2:
            return sp.Float(sum(c * s ** j for j, c in enumerate(self.series)), prec)
        return sp.Float(self.closed.xreplace({THETA: sp.sqrt(s)}).evalf(prec + 100), prec)

    @classmethod
    def numeric(cls, s):
        """NumPy evaluation (used by ``lambdify`` through ``_imp_``)."""
        s = np.asarray(s, dtype=float)
        small = np.polynomial.polynomial.polyval(s, [float(c) for c in cls.series])
        with np.errstate(all="ignore"):
            large = _closed_numeric(cls)(np.sqrt(np.maximum(s, SWITCH)))
        return np.where(s < SWITCH, small, large)


@lru_cache(maxsize=None)
def _closed_numeric(cls):
    return sp.lambdify(THETA, cls.closed, "numpy")


def _make(label: str, closed: sp.Expr, series) -> type[AnalyticCoefficient]:
    cls = type(label, (AnalyticCoefficient,), {"closed": closed, "series": tuple(series)})
    cls._imp_ = staticmethod(cls.numeric)
    return cls


@lru_cache(maxsize=None)
def derivative(cls: type[AnalyticCoefficient]) -> type[AnalyticCoefficient]:
    """dc/ds, again an :class:`AnalyticCoefficient` (d/ds = (1/2θ) d/dθ)."""
    closed = sp.diff(cls.closed, THETA) / (2 * THETA)
    series = [j * c for j, c in enumerate(cls.series)][1:]
    return _make(f"{cls.__name__}_ds", closed, series)


def _hermite(data_at_zero, expr_in_r, m0: int, m1: int) -> list[sp.Expr]:
    """Coefficients of the polynomial P(u), deg < m0 + m1, with P⁽ʲ⁾(0) = data (j < m0)
    and P⁽ʲ⁾(−θ²) equal to the u-derivatives of the expression at r = iθ (j < m1)."""
    cs = sp.symbols(f"c0:{m0 + m1}")
    P = sum(c * _U ** k for k, c in enumerate(cs))
    equations = [sp.diff(P, _U, j).subs(_U, 0) - sp.factorial(j) * data_at_zero[j]
                 for j in range(m0)]
    d = sp.sympify(expr_in_r)
    for j in range(m1):
        value = sp.simplify(sp.expand_complex(d.subs(_R, sp.I * THETA)))
        equations.append(sp.diff(P, _U, j).subs(_U, -THETA ** 2) - value)
        d = sp.diff(d, _R) / (2 * _R)
    solution = sp.solve(equations, cs, dict=True)[0]
    return [sp.simplify(solution[c]) for c in cs]


def _closed_forms(family: Family, a: int, b: int) -> list[sp.Expr]:
    """Closed forms of c_0 … c_{a+2b−1} from the even and odd parts separately."""
    m_even, m_odd = (a + 1) // 2, a // 2
    even = _hermite([family.taylor(2 * j) for j in range(m_even)], family.even, m_even, b)
    odd = _hermite([family.taylor(2 * j + 1) for j in range(m_odd)], family.odd, m_odd, b)
    closed = [sp.S.Zero] * (a + 2 * b)
    for j, c in enumerate(even):
        closed[2 * j] = c
    for j, c in enumerate(odd):
        closed[2 * j + 1] = c
    return closed


def _series(family: Family, a: int, b: int) -> list[list[sp.Rational]]:
    """Taylor coefficients in s of every c_k, from zⁿ mod p (p is homogeneous when s has
    weight 2, so the s^j term of c_k comes from n = k + 2j alone)."""
    degree = a + 2 * b
    p = sp.Poly(sp.expand(_Z ** a * (_Z ** 2 + _S) ** b), _Z, domain=sp.QQ[_S])
    remainders, power = [], sp.Poly(1, _Z, domain=sp.QQ[_S])
    for _ in range(degree + 2 * _TERMS):
        remainders.append(power)
        power = (power * sp.Poly(_Z, _Z, domain=sp.QQ[_S])).rem(p)
    out = []
    for k in range(degree):
        coefficients = []
        for j in range(_TERMS):
            n = k + 2 * j
            c = sp.Poly(remainders[n].as_expr(), _Z).coeff_monomial(_Z ** k)
            coefficients.append(family.taylor(n) * sp.Poly(c, _S).coeff_monomial(_S ** j))
        out.append(coefficients)
    return out


@lru_cache(maxsize=None)
def coefficients(family: Family, a: int, b: int) -> tuple[type[AnalyticCoefficient], ...]:
    """The functions c_k(s) with f(M) = Σ c_k(s) M^k when M^a (M² + s)^b = 0."""
    closed, series = _closed_forms(family, a, b), _series(family, a, b)
    return tuple(_make(f"{family.name}_{a}_{b}_c{k}", closed[k], series[k])
                 for k in range(a + 2 * b))


@lru_cache(maxsize=None)
def rational_coefficients(family: Family, a: int, b: int) -> tuple[sp.Expr, ...]:
    """Closed forms c_k as rational functions of s, for families (such as :data:`CAYLEY`)
    where they have no removable singularity at s = 0."""
    return tuple(sp.factor(sp.simplify(c.xreplace({THETA: sp.sqrt(_S)})))
                 for c in _closed_forms(family, a, b))


def minus_identity_coefficients(family: Family, a: int, b: int, s: sp.Symbol) -> list[sp.Expr]:
    """f(M) − I = Σ_k d_k(s) M^k: the rational coefficients of ``family`` in the symbol
    ``s``, d_0 = c_0 − 1 cancelled symbolically (no cancellation in floating point for
    small M, which keeps an increment's relative precision)."""
    values = [c.xreplace({_S: s}) for c in rational_coefficients(family, a, b)]
    values[0] = sp.cancel(values[0] - 1)
    return values


def _polynomial(values, M: sp.Matrix) -> sp.Matrix:
    """Σ_k values[k] M^k."""
    out, power = sp.zeros(*M.shape), sp.eye(M.shape[0])
    for c in values:
        out += c * power
        power = power * M
    return out


def apply_rational(family: Family, a: int, b: int, M: sp.Matrix, s: sp.Expr) -> sp.Matrix:
    """f(M) = Σ_k c_k(s) M^k with the rational coefficients of ``family``."""
    return _polynomial([c.xreplace({_S: s}) for c in rational_coefficients(family, a, b)], M)


def apply(family: Family, a: int, b: int, M: sp.Matrix, s: sp.Expr) -> sp.Matrix:
    """f(M) = Σ_k c_k(s) M^k (the caller guarantees M^a (M² + s)^b = 0)."""
    return _polynomial([c(s) for c in coefficients(family, a, b)], M)


def minimal_structure(M: sp.Matrix, max_degree: int | None = None) -> tuple[int, int, sp.Expr] | None:
    """(a, b, s) with M^a (M² + s I)^b = 0 identically and s = −tr(M²)/(2b), or None.

    The smallest degree a + 2b that works is returned.
    """
    size = M.shape[0]
    M2 = (M * M).applyfunc(sp.expand)
    for degree in range(2, (max_degree or size) + 1):
        for b in range(1, degree // 2 + 1):
            a = degree - 2 * b
            s = sp.expand(-M2.trace() / (2 * b))
            if s == 0:
                continue
            P = (M ** a if a else sp.eye(size)) * (M2 + s * sp.eye(size)) ** b
            if P.applyfunc(sp.expand) == sp.zeros(size):
                return a, b, s
    return None


def c_definition(cls: type[AnalyticCoefficient], printer) -> dict:
    """What ``templates/analytic.c.j2`` needs to define one coefficient in C."""
    series = [float(c) for c in cls.series]
    # Drop trailing terms by their size at the switch, where the series is used at most.
    size = sum(abs(c) * SWITCH ** j for j, c in enumerate(series))
    while len(series) > 1 and abs(series[-1]) * SWITCH ** (len(series) - 1) <= 1e-20 * size:
        series.pop()
    return {"name": cls.__name__, "switch": repr(SWITCH),
            "series": [repr(c) for c in reversed(series)],
            "closed": printer.doprint(cls.closed)}


def used_coefficients(expressions) -> list[type[AnalyticCoefficient]]:
    """Every coefficient class applied in ``expressions``, sorted by name.

    Walks each distinct subexpression once (derived expressions share subtrees heavily).
    """
    found, seen, stack = set(), set(), list(expressions)
    while stack:
        e = stack.pop()
        if e in seen:
            continue
        seen.add(e)
        if isinstance(e, AnalyticCoefficient):
            found.add(type(e))
        stack.extend(e.args)
    return sorted(found, key=lambda c: c.__name__)


def __getattr__(name: str) -> type[AnalyticCoefficient]:
    """The coefficient class labelled ``name`` (``dexpinv_1_1_c0_ds``: family, a, b, k,
    then one ``_ds`` per derivative), created on first use (PEP 562): pickle finds the
    classes :func:`coefficients` creates by name, so derived expressions can be pickled."""
    match = _LABEL.fullmatch(name)
    family = FAMILIES.get(match["family"]) if match else None
    a, b, k = (int(match[g]) for g in "abk") if family else (0, 0, -1)
    if family is None or not 0 <= k < a + 2 * b:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    cls = coefficients(family, a, b)[k]
    for _ in range(len(match["ds"]) // 3):
        cls = derivative(cls)
    return cls
