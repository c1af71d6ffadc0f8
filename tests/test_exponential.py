"""The exponential retraction: analytic coefficients, τ and dτ⁻¹ of SO(3), SE(2), SE(3), chart.

1. Coefficient functions (:mod:`symvi.groupoids.analytic`). When M^a (M² + s)^b = 0,
   f(M) = Σ_k c_k(s) M^k where P(z) = Σ_k c_k z^k is the Hermite interpolant of f at 0
   (multiplicity a) and ±iθ, θ = √s (multiplicity b). The reference solves that confluent
   Vandermonde system in mpmath at 250 digits, with f = exp or f(z) = z/(e^z − 1) and its
   derivative written out by hand — nothing of symvi's closed forms, series or SymPy
   solve is used — and gets dc/ds, d²c/ds² by central differences of the reference at
   δ = 1e-20 (truncation δ²·|c'''| ≲ 1e-40; the system's condition number is at worst
   ≈ θ^−2(a+2b) ≈ 1e100 at s = ±δ, so 250 digits leave ≥ 100 correct; recomputing with
   400 digits and δ = 1e-30 changes no reference value by more than 2e-44 relative).
   At s = 0 the reference value is the Taylor coefficient f⁽ᵏ⁾(0)/k! (1/k!, resp.
   B_k/k! with B_1 = −1/2).

   Checked, for every (family, a, b) the three groups use and every c_k, dc_k/ds and
   d²c_k/ds² (the derivation engine differentiates through them: residuals contain c and
   c', step Jacobians c' and c''):

   * ``numeric(s)`` (float64; series below SWITCH, closed form above) agrees with the
     reference within a first-order running-error bound of the very expression it
     evaluates: for the closed form, propagated through the expression tree (every
     operation and libm call rounds to ≤ 1 ulp, sums of terms of mixed sign amplify it by
     Σ|terms|/|sum| — the cancellation of each closed form near SWITCH is thereby
     accounted for, not guessed); for the series, the Horner bound Σ_j (2j+2)·u·|c_j s^j|.
     Points on both sides of SWITCH (its float neighbours included), at s = 0, and up to
     the chart's edge π².
   * SymPy's ``evalf`` of c(s) (the path taken by high-precision checks, 40-term series
     below SWITCH) agrees with the reference to 1e-30: the series has converged and the
     closed form is the right function on both sides.
   * The series, summed exactly in mpmath, has converged to below 1e-17 at s = SWITCH (the
     claim in analytic.py that justifies the switch point).
2. τ(X) of SO(3), SE(2), SE(3) with ``exp`` equals ``scipy.linalg.expm``; dτ⁻¹_X equals the
   Bernoulli series Σ_j B_j/j! ad_X^j (B_1 = −1/2) summed until its terms are below 1e-22;
   Cayley's τ equals (I − X/2)⁻¹(I + X/2) and its dτ⁻¹_X(Y) = (I − X/2) Y (I + X/2). For
   both, dτ⁻¹ inverts the right-trivialised derivative measured by finite differences,
   (d/dε τ(X + εY)) τ(X)⁻¹ = dτ_X(Y) — the convention the variations of lie.py rely on.
3. Errors: ``retraction="exp"`` on a group without the closed-form structure (the
   Heisenberg algebra: X nilpotent, no θ) is refused naming the cause; an increment that
   is or becomes outside the exp chart (θ ≥ π) ends the integration with status
   OUTSIDE_CHART and a message naming the chart, with finite arrays.
"""
from __future__ import annotations

import math

import mpmath as mp
import numpy as np
import pytest
import sympy as sp
from scipy.linalg import expm

from symvi import SE2, SE3, SO3, MatrixLieGroup, ModelError
from symvi.groupoids.analytic import DEXPINV, EXP, SWITCH, THETA, coefficients, derivative

U = np.finfo(float).eps / 2          # unit round-off of float64 (0.5 ulp of 1)

# ---------------------------------------------------------------------------------------
# 1. Coefficient functions
# ---------------------------------------------------------------------------------------
#: (family, a, b) of exp(X) and dexp⁻¹ = f(ad_X) for so(3), se(2) (both (1, 1)) and se(3)
#: (X: (2, 1); ad_X: (1, 2)); test_structures_of_the_groups keeps this list honest.
STRUCTURES = [(EXP, 1, 1), (EXP, 2, 1), (DEXPINV, 1, 1), (DEXPINV, 1, 2)]
IDS = [f"{f.name}_{a}_{b}" for f, a, b in STRUCTURES]
S_POINTS = [0.0, 1e-12, 1e-6, 0.01, 0.5, 2.0, 3.5, float(np.nextafter(SWITCH, 0)), SWITCH,
            float(np.nextafter(SWITCH, np.inf)), 4.5, 6.0, 8.0, 9.5, 0.999 * math.pi ** 2]
DPS = 250
DELTA = mp.mpf("1e-20")
#: Accuracy of the reference (see the module docstring), relative to max(1, |c|).
REF_ACCURACY = mp.mpf("1e-40")


def _f_values(family, z, count):
    """f(z), f'(z) (the first ``count``), written out by hand."""
    if family is EXP:
        return [mp.exp(z)] * count
    e = mp.exp(z)
    return [z / (e - 1), 1 / (e - 1) - z * e / (e - 1) ** 2][:count]


def _taylor_at_zero(family, k):
    return 1 / mp.factorial(k) if family is EXP else mp.bernoulli(k) / mp.factorial(k)


def hermite(family, a, b, s):
    """c_0(s) … c_{a+2b−1}(s) from the confluent Vandermonde system (mpmath)."""
    degree = a + 2 * b
    if s == 0:
        return [_taylor_at_zero(family, k) for k in range(degree)]
    theta = mp.sqrt(mp.mpc(s))              # s < 0 (for the differences at 0): real nodes
    rows, rhs = [], []
    for j in range(a):                     # P⁽ʲ⁾(0)/j! = c_j
        rows.append([1 if k == j else 0 for k in range(degree)])
        rhs.append(_taylor_at_zero(family, j))
    for z in (1j * theta, -1j * theta):
        values = _f_values(family, z, b)
        for j in range(b):                 # P⁽ʲ⁾(z) = f⁽ʲ⁾(z)
            rows.append([mp.factorial(k) / mp.factorial(k - j) * z ** (k - j) if k >= j else 0
                         for k in range(degree)])
            rhs.append(values[j])
    solution = mp.lu_solve(mp.matrix(rows), mp.matrix(rhs))
    return [mp.re(c) for c in solution]


def reference(family, a, b, s, order):
    """d^order c_k/ds^order at s, every k (mpmath, DPS digits)."""
    with mp.workdps(DPS):
        s = mp.mpf(s)
        if order == 0:
            return hermite(family, a, b, s)
        plus, minus = hermite(family, a, b, s + DELTA), hermite(family, a, b, s - DELTA)
        if order == 1:
            return [(p - m) / (2 * DELTA) for p, m in zip(plus, minus)]
        mid = hermite(family, a, b, s)
        return [(p - 2 * c + m) / DELTA ** 2 for p, c, m in zip(plus, mid, minus)]


def nth_derivative(cls, order):
    for _ in range(order):
        cls = derivative(cls)
    return cls


def closed_form_error_bound(expr, theta) -> tuple[mp.mpf, mp.mpf]:
    """(value, first-order bound on the absolute error of evaluating ``expr`` in float64)
    at θ = ``theta``, propagated through the expression tree.

    θ itself carries u·θ (it is √s rounded); every arithmetic operation adds u·|result|,
    every libm call 2u·|result| (1 ulp; 3u for cot, evaluated as 1/tan); a sum adds
    (n − 1)·u·Σ|terms| — the cancellation —
    and passes its terms' errors on; a product passes Σ_i e_i Π_{j≠i}|v_j|; a power b^p,
    |p||b|^{p−1}·e_b.
    """
    if expr == THETA:
        return theta, U * theta
    if expr.is_Number:
        v = mp.mpf(sp.Float(expr, 40))
        return v, U * abs(v)
    args = [closed_form_error_bound(arg, theta) for arg in expr.args]
    values = [v for v, _ in args]
    if expr.is_Add:
        v = mp.fsum(values)
        magnitude = mp.fsum(abs(x) for x in values)
        return v, mp.fsum(e for _, e in args) + (len(args) - 1) * U * magnitude
    if expr.is_Mul:
        v = mp.fprod(values)
        error = mp.fsum(e * mp.fprod(abs(x) for j, x in enumerate(values) if j != i)
                        for i, (_, e) in enumerate(args))
        return v, error + (len(args) - 1) * U * abs(v)
    if expr.is_Pow:
        (base, e_base), (p, _) = args
        v = base ** p
        return v, abs(p) * abs(base) ** (p - 1) * e_base + U * abs(v)
    (x, e_x), = args
    function = {sp.sin: (mp.sin, mp.cos), sp.cos: (mp.cos, lambda t: -mp.sin(t)),
                sp.cot: (mp.cot, lambda t: -mp.csc(t) ** 2),
                sp.tan: (mp.tan, lambda t: mp.sec(t) ** 2)}[expr.func]
    v = function[0](x)
    libm = 3 * U if expr.func is sp.cot else 2 * U      # ≤ 1 ulp per libm call
    return v, abs(function[1](x)) * e_x + libm * abs(v)


def series_error_bound(cls, s) -> mp.mpf:
    """Horner evaluation of Σ c_j s^j in float64 (coefficients rounded, 2 ops per degree)."""
    return mp.fsum((2 * j + 2) * U * abs(mp.mpf(sp.Float(c, 40))) * mp.mpf(s) ** j
                   for j, c in enumerate(cls.series))


def test_structures_of_the_groups():
    """The (family, a, b) above are the ones SO(3), SE(2), SE(3) actually use, and the
    quadratic form θ² is the rotation angle squared."""
    used = set()
    for G in (SO3(retraction="exp"), SE2(retraction="exp"), SE3(retraction="exp")):
        r = G.retraction
        used |= {(EXP.name, *r.matrix_structure), (DEXPINV.name, *r.adjoint_structure)}
        assert [c.__name__ for c in r.coefficient_functions()] == \
            [c.__name__ for c in coefficients(EXP, *r.matrix_structure)]
    assert used == {(f.name, a, b) for f, a, b in STRUCTURES}
    x = sp.symbols("x0:6", real=True)
    assert sp.expand(SE3(retraction="exp").retraction.theta_squared(x)
                     - (x[0] ** 2 + x[1] ** 2 + x[2] ** 2)) == 0
    assert sp.expand(SE2(retraction="exp").retraction.theta_squared(x[:3]) - x[0] ** 2) == 0


@pytest.mark.parametrize("family, a, b", STRUCTURES, ids=IDS)
def test_closed_forms_and_series_are_well_formed(family, a, b):
    for c in coefficients(family, a, b):
        for cls in (c, derivative(c), derivative(derivative(c))):
            assert cls.closed.free_symbols <= {THETA}, cls.__name__
            assert len(cls.series) >= 30 and all(isinstance(v, sp.Rational) for v in cls.series)
            # the value at 0 is the series' constant term, exactly
            assert float(cls.numeric(0.0)) == float(cls.series[0])
    # c_k(0) = f⁽ᵏ⁾(0)/k!: 1/k! for exp, B_k/k! (B_1 = −1/2) for dexp⁻¹
    expected = [sp.Rational(1, math.factorial(k)) if family is EXP
                else (sp.Rational(-1, 2) if k == 1 else sp.bernoulli(k) / sp.factorial(k))
                for k in range(a + 2 * b)]
    assert [c.series[0] for c in coefficients(family, a, b)] == expected


@pytest.mark.parametrize("order", [0, 1, 2])
@pytest.mark.parametrize("family, a, b", STRUCTURES, ids=IDS)
def test_coefficients_match_high_precision_reference(family, a, b, order):
    with mp.workdps(60):
        _check_coefficients(family, a, b, order)


def _check_coefficients(family, a, b, order):
    worst = 0.0
    for s in S_POINTS:
        ref = reference(family, a, b, s, order)
        for k, c in enumerate(coefficients(family, a, b)):
            cls = nth_derivative(c, order)
            value = float(cls.numeric(s))
            if cls.closed == 0:
                # an identically zero coefficient (e.g. c_3 of dexp⁻¹ on se(3)) is exactly 0
                assert value == 0 and all(v == 0 for v in cls.series), cls.__name__
                assert abs(ref[k]) < REF_ACCURACY
                continue
            if s < SWITCH:
                bound = series_error_bound(cls, s)
            else:
                _, bound = closed_form_error_bound(cls.closed, mp.sqrt(mp.mpf(s)))
            error = abs(mp.mpf(value) - ref[k])
            worst = max(worst, float(error / bound)) if bound else worst
            assert error <= bound + REF_ACCURACY * max(1, abs(ref[k])), (
                f"{cls.__name__}({s!r}) = {value!r}, reference {mp.nstr(ref[k], 20)}: error "
                f"{mp.nstr(error, 3)} exceeds the rounding bound {mp.nstr(bound, 3)}")
            # SymPy's evalf (series below SWITCH, closed form above) at 50 digits
            if s > 0:
                with mp.workdps(60):
                    high = mp.mpf(str(cls(sp.Float(s, 60)).evalf(50)))
                    assert abs(high - ref[k]) <= mp.mpf("1e-30") * max(1, abs(ref[k])), \
                        (cls.__name__, s, high, ref[k])
    print(f"{family.name}_{a}_{b} d^{order}/ds^{order}: max error / rounding bound {worst:.2f}")


@pytest.mark.parametrize("family, a, b", STRUCTURES, ids=IDS)
def test_series_has_converged_at_the_switch(family, a, b):
    """Summed exactly, the Taylor series is within 1e-17 (relative to its terms) of the
    function at s = SWITCH, for c, c' and c'' (their series have 40, 39, 38 terms)."""
    ref = {order: reference(family, a, b, SWITCH, order) for order in (0, 1, 2)}
    for k, c in enumerate(coefficients(family, a, b)):
        for order in (0, 1, 2):
            cls = nth_derivative(c, order)
            with mp.workdps(60):
                terms = [mp.mpf(sp.Float(v, 60)) * mp.mpf(SWITCH) ** j
                         for j, v in enumerate(cls.series)]
                scale = mp.fsum(abs(t) for t in terms)
                if scale == 0:
                    continue
                assert abs(mp.fsum(terms) - ref[order][k]) <= mp.mpf("1e-17") * scale, \
                    (cls.__name__, mp.fsum(terms), ref[order][k])


# ---------------------------------------------------------------------------------------
# 2. τ and dτ⁻¹ of the three groups
# ---------------------------------------------------------------------------------------
GROUPS = {"SO3": SO3, "SE2": SE2, "SE3": SE3}
ANGLES = [1e-6, 0.3, 1.9, 2.1, 3.0]          # θ of X, on both sides of √SWITCH = 2


class NumericGroup:
    """A group's basis, with NumPy τ and dτ⁻¹ lambdified from its SymPy expressions."""

    def __init__(self, make, retraction):
        self.G = make(retraction=retraction)
        self.E = np.array([np.array(E.tolist(), dtype=float) for E in self.G.basis])
        self.n, self.d = len(self.E), self.G.matrix_dim
        self.B = self.E.reshape(self.n, -1).T
        x = sp.symbols(f"x0:{self.n}", real=True)
        self.tau = sp.lambdify([x], self.G.tau(x), "numpy")
        self.dtau_inv = sp.lambdify([x], self.G.dtau_inv(x), "numpy")

    def hat(self, v):
        return np.einsum("a,aij->ij", v, self.E)

    def coords(self, X, tol=1e-12):
        """Coordinates of X in the basis; X must lie in the algebra (to ``tol``)."""
        v, *_ = np.linalg.lstsq(self.B, X.reshape(-1), rcond=None)
        assert np.abs(self.B @ v - X.reshape(-1)).max() <= tol * (1 + np.abs(X).max())
        return v

    def ad(self, v):
        X = self.hat(v)
        return np.array([self.coords(X @ E - E @ X) for E in self.E]).T

    def point(self, rng, theta):
        """A random x whose rotation part has norm θ (θ² of the exp structure)."""
        v = rng.normal(size=self.n)
        rotation = v[:1] if self.G.label == "SE2" else v[:3]
        x = v * theta / np.linalg.norm(rotation)
        if self.G.retraction.name == "exp":
            assert math.isclose(float(self.G.retraction.theta_squared(x)), theta ** 2,
                                rel_tol=1e-12)
        return x


def bernoulli_series(ad):
    """Σ_j B_j/j! ad^j (B_1 = −1/2) until its terms are below 1e-22; and Σ|terms|."""
    total, power, size = np.zeros_like(ad), np.eye(len(ad)), 0.0
    for j in range(400):
        coefficient = -0.5 if j == 1 else float(sp.bernoulli(j) / sp.factorial(j))
        term = coefficient * power
        total, size = total + term, size + np.abs(term).max()
        if j > 2 and j % 2 == 0 and np.abs(term).max() < 1e-22:
            return total, size
        power = power @ ad
    raise AssertionError("Bernoulli series did not converge (θ ≥ 2π?)")


@pytest.mark.parametrize("group", list(GROUPS))
def test_exp_tau_and_dtau_inv(group):
    g = NumericGroup(GROUPS[group], "exp")
    rng = np.random.default_rng(2024)
    for theta in ANGLES:
        for _ in range(3):
            x = g.point(rng, theta)
            X = g.hat(x)
            W = np.array(g.tau(x), dtype=float)
            # c_k(s) X^k summed: terms bounded by Σ ‖X‖^k/k! = e^‖X‖ (|c_k| ≤ 1/k!)
            scale = math.exp(np.abs(X).sum(axis=1).max())
            assert np.abs(W - expm(X)).max() <= 16 * U * scale, (group, theta, x)
            D, size = bernoulli_series(g.ad(x))
            assert np.abs(np.array(g.dtau_inv(x), dtype=float) - D).max() <= 16 * U * size, \
                (group, theta, x)


@pytest.mark.parametrize("group", list(GROUPS))
def test_cayley_tau_and_dtau_inv(group):
    g = NumericGroup(GROUPS[group], "cayley")
    rng = np.random.default_rng(7)
    I = np.eye(g.d)
    for theta in ANGLES:
        x = g.point(rng, theta)
        X = g.hat(x)
        A = I - X / 2
        expected = np.linalg.solve(A, I + X / 2)
        scale = np.linalg.cond(A) * np.abs(I + X / 2).max()
        assert np.abs(np.array(g.tau(x), dtype=float) - expected).max() <= 16 * U * scale
        D = np.array([g.coords(A @ E @ (I + X / 2)) for E in g.E]).T
        assert np.abs(np.array(g.dtau_inv(x), dtype=float) - D).max() <= \
            16 * U * (1 + np.abs(X).max()) ** 2


# (d/dε τ(X + εY)) τ(X)⁻¹ by the five-point formula at ε = 1e-3: truncation ε⁴/30·|∂⁵τ|
# (θ ≤ 3 and |Y| ≈ 2: ≲ 1e-11), rounding ≈ 18u/(12ε)·|τ| ≈ 3e-13. A left-trivialised dτ⁻¹
# or a sign error is O(|X|) off.
FD_TOL = 1e-9


@pytest.mark.parametrize("retraction", ["exp", "cayley"])
@pytest.mark.parametrize("group", list(GROUPS))
def test_dtau_inv_inverts_the_right_trivialised_derivative(group, retraction):
    g = NumericGroup(GROUPS[group], retraction)
    rng = np.random.default_rng(11)
    eps = 1e-3
    worst = 0.0
    for theta in ANGLES:
        x, y = g.point(rng, theta), rng.normal(size=g.n)
        T = lambda e: np.array(g.tau(x + e * y), dtype=float)
        dW = (-T(2 * eps) + 8 * T(eps) - 8 * T(-eps) + T(-2 * eps)) / (12 * eps)
        right = dW @ np.linalg.inv(T(0.0))           # dτ_X(Y), in the algebra
        back = np.array(g.dtau_inv(x), dtype=float) @ g.coords(right, tol=FD_TOL)
        worst = max(worst, np.abs(back - y).max())
        # the left-trivialised τ(X)⁻¹ dW is a different element: the test can tell them apart
        if theta > 0.1:
            left = g.coords(np.linalg.inv(T(0.0)) @ dW, tol=FD_TOL)
            assert np.abs(np.array(g.dtau_inv(x), dtype=float) @ left - y).max() > 1e-3
    print(f"{group} {retraction}: |dτ⁻¹(dτ Y) − Y| ≤ {worst:.1e}")
    assert worst < FD_TOL


# ---------------------------------------------------------------------------------------
# 3. Errors
# ---------------------------------------------------------------------------------------
HEISENBERG = [[[0, 1, 0], [0, 0, 0], [0, 0, 0]],
              [[0, 0, 0], [0, 0, 1], [0, 0, 0]],
              [[0, 0, 1], [0, 0, 0], [0, 0, 0]]]


def test_exp_without_closed_form_is_refused():
    with pytest.raises(ModelError) as info:
        MatrixLieGroup(HEISENBERG, label="Heisenberg", retraction="exp")
    message = str(info.value)
    assert "Heisenberg" in message and "no closed form" in message and "exponential" in message
    assert "cayley" in message                      # the way out is named
    # the same algebra is a valid group with the Cayley retraction
    G = MatrixLieGroup(HEISENBERG, label="Heisenberg")
    assert G.retraction.name == "cayley"
    assert G.tau([1, 2, 3]) == sp.Matrix([[1, 1, 4], [0, 1, 2], [0, 0, 1]])


def test_unknown_retraction_is_named():
    with pytest.raises(ModelError, match=r"unknown retraction 'log'.*cayley.*exp"):
        SO3(retraction="log")


H_CHART = 1.0


@pytest.mark.parametrize("xi0", [[3.3, 0.0, 0.0], [0.0, 2.5, -2.5], [4.0, 4.0, 4.0],
                                 [2 * math.pi + 0.1, 0.0, 0.0]],
                         ids=["3.3", "3.54", "6.9", "2pi+0.1"])
def test_initial_increment_outside_the_exp_chart(compiled, xi0):
    """|hξ_0| > π: the first reconstruction already leaves the chart (including past 2π,
    where exp wraps round to near the identity and would silently alias)."""
    assert np.linalg.norm(xi0) * H_CHART > math.pi
    res = compiled("rigid_body_exp").integrate((np.eye(3), [xi0]), 20, H_CHART)
    assert res.status == 5 and res.status.name == "OUTSIDE_CHART" and not res.success
    assert "chart" in res.message and "θ(hξ) ≥ π" in res.message and "step 2 of 20" in res.message
    for a in (res.x, res.f, res.g):
        assert np.isfinite(a).all()


def test_newton_iterate_leaving_the_exp_chart(compiled):
    """|hξ_0| = 3 < π, inside the chart, but the step's Newton iterate leaves it: the
    integration stops there with OUTSIDE_CHART (not NaN, not a non-finite status) and
    returns the path up to that step."""
    xi0 = [2.0, 2.0, 1.0]
    assert np.linalg.norm(xi0) * H_CHART < math.pi
    res = compiled("rigid_body_exp").integrate((np.eye(3), [xi0]), 20, H_CHART)
    assert res.status == 5 and "chart" in res.message and "exp: θ(hξ) ≥ π" in res.message
    assert res.f.shape == (1, 3) and res.g.shape == (2, 3, 3)
    np.testing.assert_array_equal(res.f[0], xi0)
    for a in (res.x, res.f, res.g):
        assert np.isfinite(a).all()
    # the same data with the Cayley retraction (chart: all of so(3)) integrates
    assert compiled("rigid_body").integrate((np.eye(3), [xi0]), 20, H_CHART).success
