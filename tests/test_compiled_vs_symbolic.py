"""Compiled kernels against their SymPy expressions, and Jacobians against differences.

Reference evaluation. Each kernel's SymPy expressions (outputs and ``definitions``, the
named intermediate quantities of action-groupoid kernels, evaluated in order) are walked
once as a graph — every distinct subexpression visited once, a definition symbol standing
for its evaluated expression — in NumPy float64 over a whole batch of points at a time.
This shares nothing with the C path (no CSE, no C printer, no ``lambdify``): it is the
expression tree itself, evaluated node by node. Analytic coefficients c(s) of the
exponential retraction (``symvi.groupoids.analytic``) are evaluated from their own data:
the exact Taylor series below ``SWITCH``, the closed form in θ = √s above it.

Error measure. The C code (common subexpressions eliminated, powers expanded) and the
reference evaluate the same tree in different orders, so they differ by rounding only. With
unit roundoff u, each is within γ_k·mag(e) of the exact value, γ_k = ku/(1 − ku), where
mag(e) is e evaluated with every sum replaced by the sum of the absolute values of its
terms, and k bounds the number of rounding factors (1 + δ)^{±1} along any term (Higham,
*Accuracy and Stability*, §3.1–3.4). The walk computes both alongside the value:

* sum of n terms: mag = Σ mag, k = max k + n − 1; product of n factors: mag = Π mag,
  k = Σ k + n − 1 (either bound holds for every association, so also after CSE);
* bⁿ: mag(b)ⁿ, k = n·k_b + n − 1; b⁻ⁿ carries the relative error of b:
  mag = n·|b⁻ⁿ|·mag(b)/|b|, k = n·k_b + n;
* sin, cos (libm, ≤ 1 ulp): mag = 1 + mag(x), k = k_x + 2; cot = 1/tan:
  mag = |cot x| + (1 + cot²x)·mag(x), k = k_x + 3;
* numbers: k = 0 if exact in binary (integers, dyadic rationals), else 1;
* a coefficient c(s): mag = E_c(s) + |c′(s)|·mag(s), k = max(k_s, k_E) — the error of s
  propagated by c′ (``analytic.derivative``) plus c's own evaluation error E_c. Below the
  switch E_c(s) = Σ|a_j|·s^j (Horner on the series, k_E = 2·terms + 1; the C keeps only the
  terms that ``c_definition`` keeps, and the dropped tail is checked to be below u·E_c at
  every point); above it E_c is the running magnitude of the closed form at θ = √s (θ with
  k = 1, its own rounding). Where s is within its own error bound of the switch the C may
  take the other branch; there the larger of the two magnitudes and depths is used.

So |C − reference| ≤ 2γ_k·mag(e) for every entry, and every kernel checks that
2γ_k < TOL = 1e-12 for its deepest output (k is a few hundred at most) and that
|C − reference| ≤ TOL·mag(e). Entries with mag(e) = 0 are constants and must agree exactly.
A tolerance relative to max(1, |value|) would not do: the three-point residual of a cubic
spline is (1/h³)·(a fourth difference), with terms of size 1e6·|q| at h = 0.01, and wherever
the random point makes the difference small its absolute rounding error (1e-10) would exceed
1e-12·max(1, |value|) though both evaluations are right. mag(e) is at least |e| and, away
from such cancellations, of the same size, so any real discrepancy (a coefficient, a sign,
a parameter in the wrong slot, a wrong branch of a coefficient) is an O(1) relative error.

Points: z uniform in [−1, 1]; half the points take h ∈ [0.01, 0.2] and half h ∈ [2, 3].
With the exponential retraction θ = h·|ω| then reaches ~5 (below the pole of dexp⁻¹ at
2π), so both branches of every coefficient (s < SWITCH = 4 and s ≥ SWITCH) are exercised;
the test records each coefficient's arguments and asserts that both branches were reached.

Finite differences. Points z are rounded to multiples of 2⁻³⁰ and δ = 2⁻¹⁷ ≈ u^{1/3}, so
z ± δ and 2δ are exact and the central difference (R̂(z + δ) − R̂(z − δ))/(2δ) differs from
∂R/∂z_i by at most δ²/6·|∂³R/∂z_i³(ξ)| (truncation) + γ_{k_R}·(mag R(z + δ) +
mag R(z − δ))/(2δ) (rounding of the two compiled residuals) + u·|difference|, and the
compiled Jacobian from the exact one by γ_{k_J}·mag(J). The third derivative is computed
by degree-3 Taylor arithmetic in the same graph walk (through the definitions, which
``sp.diff`` cannot see through), at z and z ± δ; twice the sum of the terms (the factor for
ξ anywhere in [z − δ, z + δ]) is the tolerance of each entry, and the test checks that it
is below 1e-6 of the Jacobian's row, so that the comparison is discriminating.
"""
from __future__ import annotations

import zlib
from functools import lru_cache

import numpy as np
import pytest
import sympy as sp

from conftest import BUNDLED
from symvi.emit import ArrayPrinter
from symvi.groupoids import analytic
from symvi.groupoids.analytic import SWITCH, THETA, AnalyticCoefficient
from symvi.models import get

#: Unit roundoff.
U = np.finfo(float).eps / 2
TOL = 1e-12
POINTS = 100
#: Finite-difference step (exact in binary; ≈ u^{1/3}) and the grid of the FD points.
DELTA = 2.0 ** -17
GRID = 2.0 ** -30


def gamma(k):
    return k * U / (1 - k * U)


def _number_depth(e: sp.Expr) -> int:
    """0 if the number is exact in binary floating point (as printed in C), else 1."""
    if e.is_Integer:
        return 0
    if e.is_Rational and e.q & (e.q - 1) == 0:
        return 0
    return 1


def _walk(expr, memo, node):
    """Evaluate ``expr`` bottom-up, each distinct subexpression once (memo: expr → result)."""
    if expr in memo:
        return memo[expr]
    stack = [expr]
    while stack:
        e = stack[-1]
        if e in memo:
            stack.pop()
            continue
        if e.is_Atom and not e.is_Number:
            raise KeyError(f"no value for {e}")
        pending = [a for a in e.args if a not in memo]
        if pending:
            stack.extend(pending)
            continue
        stack.pop()
        memo[e] = node(e, [memo[a] for a in e.args])
    return memo[expr]


# ---- value, magnitude and depth -------------------------------------------------------


class Rounding:
    """(value, mag, k) of SymPy expressions at a batch of points (see module docstring).

    ``inputs`` maps symbols to value arrays (or scalars), exact unless ``depth`` says
    otherwise. ``arguments`` collects (coefficient class, s) of every coefficient applied.
    """

    def __init__(self, inputs, depth=None):
        depth = depth or {}
        self.memo = {s: (v, np.abs(v), depth.get(s, 0)) for s, v in inputs.items()}
        self.arguments = []

    def define(self, definitions):
        for symbol, expr in definitions:
            self.memo[symbol] = self(expr)

    def __call__(self, expr):
        return _walk(expr, self.memo, self._node)

    def _node(self, e, args):
        if e.is_Number:
            v = float(e)
            return v, abs(v), _number_depth(e)
        if e.is_Add or e.is_Mul:
            v, m, k = args[0]
            for a, b, c in args[1:]:
                v, m = (v + a, m + b) if e.is_Add else (v * a, m * b)
                k = max(k, c) if e.is_Add else k + c
            return v, m, k + len(args) - 1
        if e.is_Pow and e.exp.is_Integer:
            (b, mb, kb), _ = args
            n = int(e.exp)
            if n > 0:
                return b ** n, mb ** n, n * kb + n - 1
            v = 1.0 / b ** -n
            return v, -n * np.abs(v) * mb / np.abs(b), -n * kb - n
        if isinstance(e, (sp.sin, sp.cos)):
            (x, mx, kx), = args
            return (np.sin(x) if isinstance(e, sp.sin) else np.cos(x)), 1 + mx, kx + 2
        if isinstance(e, sp.cot):
            (x, mx, kx), = args
            v = 1 / np.tan(x)
            return v, np.abs(v) + (1 + v * v) * mx, kx + 3
        if isinstance(e, AnalyticCoefficient):
            (s, ms, ks), = args
            cls = type(e)
            self.arguments.append((cls, s))
            # The C may take the other branch where s is within its error of the switch.
            near = np.abs(s - SWITCH) <= gamma(ks) * ms
            v, me, ke = _coefficient(cls, s, near)
            slope = np.abs(_coefficient(analytic.derivative(cls), s)[0])
            return v, me + slope * ms, max(ks, ke)
        raise NotImplementedError(f"no rule for {type(e).__name__}: {e}")


@lru_cache(maxsize=None)
def _kept_terms(cls) -> int:
    """How many Taylor terms the emitted C keeps."""
    return len(analytic.c_definition(cls, ArrayPrinter({THETA: "theta"}))["series"])


def _coefficient(cls, s, near=None):
    """(value, intrinsic magnitude E_c, depth) of c(s): exact series below SWITCH (checked
    against the C's truncation), closed form above it; both where ``near`` is set."""
    s = np.atleast_1d(np.asarray(s, dtype=float))
    near = np.zeros(s.shape, bool) if near is None else np.broadcast_to(near, s.shape)
    small, large = s < SWITCH, (s >= SWITCH) | near
    value, mag, depth = np.zeros(s.shape), np.zeros(s.shape), 0
    if small.any() or near.any():
        a, kept = [float(c) for c in cls.series] or [0.0], _kept_terms(cls)
        x = np.where(small | near, s, 0.0)
        series = np.polynomial.polynomial.polyval(x, a)
        E = np.polynomial.polynomial.polyval(np.abs(x), np.abs(a))
        tail = np.polynomial.polynomial.polyval(np.abs(x), np.abs(a[kept:] or [0.0]))
        tail *= np.abs(x) ** kept
        assert np.all(tail <= U * E), f"{cls.__name__}: the C's truncated series is short"
        value = np.where(small, series, value)
        mag = np.where(small | near, E, mag)
        depth = 2 * len(a) + 2
    if large.any():
        theta = np.sqrt(np.where(large, s, SWITCH))
        with np.errstate(all="ignore"):
            v, m, k = Rounding({THETA: theta}, {THETA: 1})(cls.closed)
        value = np.where(small, value, v)
        mag = np.where(large, np.maximum(mag, m), mag)
        depth = max(depth, k)
    return value, mag, depth


def _inputs(dm, kernel, zs, params, hs):
    """Symbol → values for a batch (zs: points × coordinates)."""
    n = len(zs)
    out = {s: zs[:, i] for i, s in enumerate(kernel.z)}
    out |= {s: np.full(n, float(v)) for s, v in zip(dm.parameters, params)}
    out[dm.step] = np.asarray(hs, dtype=float) * np.ones(n)
    return out


def reference(dm, kernel, zs, params, hs):
    """[(value, mag) arrays (points × entries) per output], deepest k, coefficient args."""
    ev = Rounding(_inputs(dm, kernel, zs, params, hs))
    ev.define(kernel.definitions)
    n, outputs, depth = len(zs), [], 0
    for _, M in kernel.outputs:
        results = [ev(e) for e in M]
        outputs.append(tuple(np.array([np.broadcast_to(r[j], (n,)) for r in results]
                                      ).T.reshape(n, len(results)) for j in (0, 1)))
        depth = max([depth] + [r[2] for r in results])
    return outputs, depth, ev.arguments


def run_compiled(mod, kernel, zs, hs, params_arg=None):
    """Compiled outputs, each as an array points × entries."""
    per_point = [[np.ravel(o) for o in mod.evaluate(kernel.name, z, h, params=params_arg)]
                 for z, h in zip(zs, hs)]
    return [np.array([p[j] for p in per_point]).reshape(len(zs), -1)
            for j in range(len(kernel.outputs))]


def relative_errors(compiled, ref):
    """|compiled − reference| / mag per output; 0/0 (exact constants) counts as 0."""
    out = []
    for c, (v, m) in zip(compiled, ref):
        assert c.shape == v.shape
        assert np.all(m >= np.abs(v) * (1 - 1e-12)), "the magnitude must bound the value"
        err = np.abs(c - v)
        with np.errstate(divide="ignore", invalid="ignore"):
            out.append(np.where(err == 0, 0.0, err / m))
    return out


def _points(rng, nz, count=POINTS):
    """z ∈ [−1, 1]; h ∈ [0.01, 0.2] for the first half, [2, 3] for the second."""
    small = count // 2
    hs = np.concatenate([rng.uniform(0.01, 0.2, small), rng.uniform(2.0, 3.0, count - small)])
    return rng.uniform(-1.0, 1.0, (count, nz)), hs


def compare(mod, dm, kernel, zs, hs, values, params_arg=None):
    """Worst |C − reference|/mag over every output of ``kernel``; coefficient arguments."""
    ref, depth, arguments = reference(dm, kernel, zs, values, hs)
    assert 2 * gamma(depth) < TOL, f"{kernel.name}: depth {depth} too large for TOL"
    errors = relative_errors(run_compiled(mod, kernel, zs, hs, params_arg), ref)
    return max([0.0] + [float(e.max()) for e in errors if e.size]), arguments


#: Worst relative error per (model, kernel), for reports (``-s`` prints nothing; read it).
WORST: dict[tuple[str, str], float] = {}


@pytest.mark.parametrize("name", BUNDLED)
def test_every_kernel_matches_sympy(name, compiled, derived):
    mod, dm = compiled(name), derived(name)
    assert set(mod.INFO["kernels"]) == {k.name for k in dm.kernels}
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    reached: dict[type, list] = {}
    for kernel in dm.kernels:
        zs, hs = _points(rng, len(kernel.z))
        worst, arguments = compare(mod, dm, kernel, zs, hs, list(dm.defaults))
        WORST[name, kernel.name] = worst
        assert worst < TOL, f"{name}.{kernel.name}: relative error {worst:.2e}"
        for cls, s in arguments:
            reached.setdefault(cls, []).append(np.ravel(s))
    # Both branches of every coefficient (series below SWITCH, closed form above) ran.
    for cls, s in reached.items():
        s = np.concatenate(s)
        assert (s < SWITCH).any() and (s >= SWITCH).any(), (cls.__name__, s.min(), s.max())
    assert bool(reached) == bool(dm.coefficients)


@pytest.mark.parametrize("name", [n for n in BUNDLED if get(n).parameters])
def test_parameters_are_passed_at_run_time(name, compiled, derived):
    """Random, distinct parameter values reach the right slots of every kernel."""
    mod, dm = compiled(name), derived(name)
    assert dm.parameters, name
    rng = np.random.default_rng(7)
    values = [d * rng.uniform(0.5, 2.0) if d else rng.uniform(0.5, 2.0) for d in dm.defaults]
    by_name = {str(s): v for s, v in zip(dm.parameters, values)}
    for kernel in dm.kernels:
        zs, hs = _points(rng, len(kernel.z), 20)
        ref, depth, _ = reference(dm, kernel, zs, values, hs)
        assert 2 * gamma(depth) < TOL
        for params_arg in (by_name, values):  # mapping and full sequence
            errors = relative_errors(run_compiled(mod, kernel, zs, hs, params_arg), ref)
            worst = max([0.0] + [float(e.max()) for e in errors if e.size])
            assert worst < TOL, f"{name}.{kernel.name}: relative error {worst:.2e}"
        # The comparison discriminates: where a kernel depends on the parameters, running
        # it with the defaults instead would be an error far above TOL.
        uses = [M for _, M in kernel.outputs] + [e for _, e in kernel.definitions]
        if not any(e.has(*dm.parameters) for e in uses):
            continue
        effect = max(float(e.max()) for e in relative_errors(run_compiled(mod, kernel, zs, hs),
                                                             ref) if e.size)
        assert effect > 1e3 * TOL, (kernel.name, effect)


# ---- Taylor arithmetic for third derivatives ------------------------------------------


def _mul(a, b):
    return np.stack([a[0] * b[0], a[0] * b[1] + a[1] * b[0],
                     a[0] * b[2] + a[1] * b[1] + a[2] * b[0],
                     a[0] * b[3] + a[1] * b[2] + a[2] * b[1] + a[3] * b[0]])


def _reciprocal(b):
    r0 = 1.0 / b[0]
    r1 = -b[1] * r0 * r0
    r2 = -(b[1] * r1 + b[2] * r0) * r0
    r3 = -(b[1] * r2 + b[2] * r1 + b[3] * r0) * r0
    return np.stack([r0, r1, r2, r3])


def _compose(f, x):
    """Taylor series of F(x(t)) from F, F′, F″, F‴ at x₀ (``f``) and the series ``x``."""
    return np.stack([f[0], f[1] * x[1], f[1] * x[2] + f[2] * x[1] ** 2 / 2,
                     f[1] * x[3] + f[2] * x[1] * x[2] + f[3] * x[1] ** 3 / 6])


class Taylor:
    """Taylor coefficients to degree 3 in t of SymPy expressions along z + t·e_i, at a
    batch of points (arrays 4 × batch). ``inputs`` maps symbols to such arrays."""

    def __init__(self, inputs):
        self.memo = dict(inputs)

    def define(self, definitions):
        for symbol, expr in definitions:
            self.memo[symbol] = self(expr)

    def __call__(self, expr):
        return _walk(expr, self.memo, self._node)

    def _node(self, e, args):
        if e.is_Number:
            return np.array([float(e), 0.0, 0.0, 0.0])[:, None]
        if e.is_Add:
            return sum(args[1:], args[0])
        if e.is_Mul:
            out = args[0]
            for a in args[1:]:
                out = _mul(out, a)
            return out
        if e.is_Pow and e.exp.is_Integer:
            base, n = args[0], int(e.exp)
            if n < 0:
                base, n = _reciprocal(base), -n
            out = base
            for _ in range(n - 1):
                out = _mul(out, base)
            return out
        x = args[0]
        if isinstance(e, sp.sin):
            s, c = np.sin(x[0]), np.cos(x[0])
            return _compose([s, c, -s, -c], x)
        if isinstance(e, sp.cos):
            s, c = np.sin(x[0]), np.cos(x[0])
            return _compose([c, -s, -c, s], x)
        if isinstance(e, sp.cot):
            c = 1 / np.tan(x[0])
            q = 1 + c * c
            return _compose([c, -q, 2 * c * q, -2 * q * (1 + 3 * c * c)], x)
        if isinstance(e, AnalyticCoefficient):
            derivatives, cls = [], type(e)
            for _ in range(4):
                derivatives.append(_coefficient(cls, x[0])[0])
                cls = analytic.derivative(cls)
            return _compose(derivatives, x)
        raise NotImplementedError(f"no rule for {type(e).__name__}: {e}")


def _jacobian_kernels(dm):
    return [k for k in dm.kernels if "jacobian" in dict(k.outputs)]


@pytest.mark.parametrize("name", BUNDLED)
def test_jacobians_match_central_differences(name, compiled, derived):
    mod, dm = compiled(name), derived(name)
    kernels = _jacobian_kernels(dm)
    assert {k.name for k in kernels} == {"step"} | ({"stencil"} if dm.whole_trajectory else set())
    p = list(dm.defaults)
    for kernel in kernels:
        rng = np.random.default_rng(zlib.crc32(f"{name}:{kernel.name}".encode()))
        names = [n for n, _ in kernel.outputs]
        assert names == ["residual", "jacobian"]
        residual, jacobian = (M for _, M in kernel.outputs)
        nz, n = len(kernel.z), residual.shape[0]
        columns = np.arange(nz - jacobian.shape[1], nz)  # step: f_{K−1}; stencil: all of z
        zs, hs = _points(rng, nz, 20)
        zs = np.round(zs / GRID) * GRID
        N, C = len(zs), len(columns)
        # Batch of (point, column) pairs, with z − δe_i, z, z + δe_i.
        shifted = {}
        for sign in (-1, 0, 1):
            w = np.repeat(zs, C, axis=0)
            w[np.arange(N * C), np.tile(columns, N)] += sign * DELTA
            shifted[sign] = w
        hb = np.repeat(hs, C)
        assert np.all(shifted[1] - shifted[-1] == 2 * DELTA)  # exact
        # Reference magnitudes and depths of R at z ± δe_i and of J at z.
        minus, k_r, _ = reference(dm, kernel, shifted[-1], p, hb)
        plus, _, _ = reference(dm, kernel, shifted[1], p, hb)
        at_z, k_j, _ = reference(dm, kernel, zs, p, hs)
        assert 2 * gamma(k_r) < TOL
        # Third derivatives along e_i at z − δ, z, z + δ.
        third = []
        for sign in (-1, 0, 1):
            B = N * C
            inputs = {}
            for j, s in enumerate(kernel.z):
                series = np.zeros((4, B))
                series[0] = shifted[sign][:, j]
                series[1] = np.tile(columns, N) == j
                inputs[s] = series
            for s, v in zip(dm.parameters, p):
                inputs[s] = np.array([v, 0.0, 0.0, 0.0])[:, None]
            inputs[dm.step] = np.stack([hb, 0 * hb, 0 * hb, 0 * hb])
            ev = Taylor(inputs)
            ev.define(kernel.definitions)
            third.append(np.stack([np.broadcast_to(6 * ev(e)[3], (B,)) for e in residual],
                                  axis=1))
        d3 = np.max(np.abs(third), axis=0)  # (N·C) × n
        # Compiled residuals at z ± δe_i and Jacobians at z.
        r_plus = run_compiled(mod, kernel, shifted[1], hb)[0]
        r_minus = run_compiled(mod, kernel, shifted[-1], hb)[0]
        jac = run_compiled(mod, kernel, zs, hs)[1].reshape(N, n, C)
        fd = ((r_plus - r_minus) / (2 * DELTA)).reshape(N, C, n).transpose(0, 2, 1)
        mag_r = (plus[0][1] + minus[0][1]).reshape(N, C, n).transpose(0, 2, 1)
        mag_j = at_z[1][1].reshape(N, n, C)
        d3 = d3.reshape(N, C, n).transpose(0, 2, 1)
        bound = 2 * (DELTA ** 2 / 6 * d3 + gamma(k_r) * mag_r / (2 * DELTA)
                     + U * np.abs(fd) + gamma(k_j) * mag_j)
        err = np.abs(jac - fd)
        assert np.all(err <= bound), (name, kernel.name, float((err / bound).max()))
        row = np.maximum(np.abs(jac).max(axis=2, keepdims=True), 1.0)
        assert np.all(bound <= 1e-6 * row), (name, kernel.name, float((bound / row).max()))
        worst = float((err / row).max())
        WORST[name, f"{kernel.name}/fd"] = worst
        assert worst < 1e-7
