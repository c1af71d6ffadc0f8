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
* sin, cos (libm and NumPy, ≤ 1 ulp): mag = 1 + mag(x), k = k_x + 2; cot = 1/tan:
  mag = |cot x| + (1 + cot²x)·mag(x), k = k_x + 3;
* numbers: k = 0 if exact in binary (integers, dyadic rationals), else 1;
* a coefficient c(s): mag = E_c(s) + |c′(s)|·mag(s), k = max(k_s, k_E) — the error of s
  propagated by c′ (``analytic.derivative``) plus c's own evaluation error E_c. Below the
  switch E_c(s) = Σ|a_j|·s^j (Horner on the series; k_E = 2·terms + 2 for Horner, the
  rounded coefficients and the terms the C drops: it keeps those ``c_definition`` keeps,
  and the dropped tail is checked to be below u·E_c at every point); above it E_c is the
  running magnitude of the closed form at θ = √s (θ with k = 1, its own rounding). Where s
  is within its own error bound of the switch the C may take the other branch; there the
  larger of the two magnitudes and depths is used.

So |C − reference| ≤ 2γ_k·mag(e) for every entry. Every kernel checks that 2γ_k < TOL =
1e-12 for its deepest output (k ≤ 517, in se3_body_exp) and that |C − reference| ≤
TOL·mag(e); entries with mag(e) = 0 are constants and must agree exactly. A tolerance
relative to max(1, |value|) would not do: the three-point residual of a cubic spline is
(1/h³)·(a fourth difference), with terms of size 1e6·|q| at h = 0.01, and wherever the
random point makes the difference small its absolute rounding error (1e-10) would exceed
1e-12·max(1, |value|) though both evaluations are right. mag(e) is at least |e| and, away
from such cancellations, of the same size, so any real discrepancy (a coefficient, a sign,
a parameter in the wrong slot) is an O(1) relative error.

Points. z uniform in [−1, 1] and h ∈ [0.01, 0.2], so s ≤ 0.12: the series branch. In the
second half of the points of a kernel with coefficients, the coordinates in each
coefficient argument s = θ² (h² times a quadratic form in them: one element's angular
velocity) are rescaled to θ ∈ [1.5, 4.5] — the closed form (s ≥ SWITCH = 4) mostly, the
series sometimes, each element on its own, at most 3/4 of the way to the pole of dexp⁻¹ at
θ = 2π. The test records every coefficient's arguments and asserts that both branches were
reached. Scaling these coordinates alone keeps the cancellation there as small as it goes:
the expanded closed forms cancel heavily at θ > 2 (mag/|e| up to a few 1e4 in most models,
1.7e11 in se3_body_exp's step), and more so with a larger h (h ∈ [2, 3] gave 1e13). Since
the comparison is then weaker than O(1), the test shows what it still sees: multiplying
any coefficient (other than c ≡ 0) by 1.1 on one branch only, in the reference, changes
some output by more than 100·TOL·mag, on each branch — so a relative error of 4e-5 in
exp_2_1_c3_ds_ds (the least visible, in se3_body_exp's step Jacobian) and of 1e-11 in the
coefficients themselves would be caught. The parameter test likewise checks that running
with the default parameters instead of the given ones would be an error far above TOL.

Finite differences. δ_i = 2^(⌈log₂ max(1, |z_i|)⌉ − 17) ≈ u^{1/3}·max(1, |z_i|), a power of
two, and z_i rounded to a multiple of δ_i·2⁻¹³, so that z ± δ_i·e_i are exact and the
central difference (R̂(z + δe_i) − R̂(z − δe_i))/(2δ) differs from ∂R/∂z_i by at most
δ²/6·|∂³R/∂z_i³(ξ)| (truncation) + γ_{k_R}·(mag R(z + δe_i) + mag R(z − δe_i))/(2δ)
(rounding of the two compiled residuals) + u·|difference|, and the compiled Jacobian from
the exact one by γ_{k_J}·mag(J). The third derivative is computed by degree-3 Taylor
arithmetic in the same graph walk (through the definitions, which ``sp.diff`` cannot see
through), at z and z ± δe_i; twice the sum of the terms (the factor for ξ anywhere in
[z − δ, z + δ]) is the tolerance of each entry, at every point. At every point with all
coefficients on the series branch (all points of models without coefficients) the test
checks that this tolerance is below 1e-6 of the Jacobian's row, so that the comparison is
discriminating; at the rescaled points the rounding term grows with mag/|e| and that holds
for most entries but not all (53 % in se3_body_exp, ≥ 80 % elsewhere).
"""
from __future__ import annotations

import zlib
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pytest
import sympy as sp

from conftest import BUNDLED
from symvi.codegen.emit import ArrayPrinter
from symvi.groupoids import analytic
from symvi.groupoids.analytic import SWITCH, THETA, AnalyticCoefficient
from symvi.models import get

#: Unit roundoff.
U = np.finfo(float).eps / 2
TOL = 1e-12
POINTS = 100
FD_POINTS = 40


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


class _Evaluator:
    """Evaluates SymPy expressions by one graph walk over ``memo`` (symbol → value);
    subclasses give the arithmetic of one node (``_node``)."""

    memo: dict

    def define(self, definitions):
        for symbol, expr in definitions:
            self.memo[symbol] = self(expr)

    def __call__(self, expr):
        return _walk(expr, self.memo, self._node)


# ---- value, magnitude and depth -------------------------------------------------------


class Rounding(_Evaluator):
    """(value, mag, k) of SymPy expressions at a batch of points (see module docstring).

    ``inputs`` maps symbols to value arrays (or scalars), exact unless ``depth`` says
    otherwise. ``arguments`` collects (coefficient class, s) of every coefficient applied.
    ``perturb = (cls, closed, factor)`` multiplies the value of coefficient ``cls`` by
    ``factor`` on one branch (for the discrimination check).
    """

    def __init__(self, inputs, depth=None, perturb=None):
        depth = depth or {}
        self.memo = {s: (v, np.abs(v), depth.get(s, 0)) for s, v in inputs.items()}
        self.arguments = []
        self.perturb = perturb

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
            v, me, ke = _coefficient(cls, s, near, compiled=True)
            slope = np.abs(_coefficient(analytic.derivative(cls), s)[0])
            if self.perturb and self.perturb[0] is cls:
                _, closed, factor = self.perturb
                v = v * np.where((np.asarray(s) >= SWITCH) == closed, factor, 1.0)
            return v, me + slope * ms, max(ks, ke)
        raise NotImplementedError(f"no rule for {type(e).__name__}: {e}")


@lru_cache(maxsize=None)
def _kept_terms(cls) -> int:
    """How many Taylor terms the emitted C keeps."""
    return len(analytic.c_definition(cls, ArrayPrinter({THETA: "theta"}))["series"])


def _coefficient(cls, s, near=None, compiled=False):
    """(value, intrinsic magnitude E_c, depth) of c(s): exact series below SWITCH, closed
    form above it; the larger of both where ``near``. ``compiled``: c is evaluated in the C
    too, whose truncation of the series is checked."""
    s = np.atleast_1d(np.asarray(s, dtype=float))
    near = np.zeros(s.shape, bool) if near is None else np.broadcast_to(near, s.shape)
    small, large = s < SWITCH, (s >= SWITCH) | near
    value, mag, depth = np.zeros(s.shape), np.zeros(s.shape), 0
    if small.any() or near.any():
        a, kept = [float(c) for c in cls.series] or [0.0], _kept_terms(cls) if compiled else 0
        x = np.where(small | near, s, 0.0)
        E = np.polynomial.polynomial.polyval(np.abs(x), np.abs(a))
        tail = np.polynomial.polynomial.polyval(np.abs(x), np.abs(a[kept:] or [0.0]))
        if compiled:
            assert np.all(tail * np.abs(x) ** kept <= U * E), f"{cls.__name__}: C series short"
        value = np.where(small, np.polynomial.polynomial.polyval(x, a), value)
        mag = np.where(small | near, E, mag)
        depth = 2 * len(a) + 2  # Horner, rounded coefficients, the C's truncation
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


@dataclass
class Reference:
    """Reference evaluation of one kernel at a batch of points."""

    outputs: list  # per output: (value, mag), arrays points × entries
    depth: int  # the largest k of any output
    arguments: list  # (coefficient class, s) of every coefficient applied
    nodes: int  # distinct subexpressions evaluated


def reference(dm, kernel, zs, params, hs, perturb=None) -> Reference:
    ev = Rounding(_inputs(dm, kernel, zs, params, hs), perturb=perturb)
    ev.define(kernel.definitions)
    n, outputs, depth = len(zs), [], 0
    for _, M in kernel.outputs:
        results = [ev(e) for e in M]
        outputs.append(tuple(np.array([np.broadcast_to(r[j], (n,)) for r in results]
                                      ).T.reshape(n, len(results)) for j in (0, 1)))
        depth = max([depth] + [r[2] for r in results])
    assert 2 * gamma(depth) < TOL, f"{kernel.name}: depth {depth} too large for TOL"
    return Reference(outputs, depth, ev.arguments, len(ev.memo))


def run_compiled(mod, kernel, zs, hs, params_arg=None):
    """Compiled outputs, each as an array points × entries."""
    per_point = [[np.ravel(o) for o in mod.evaluate(kernel.name, z, h, params=params_arg)]
                 for z, h in zip(zs, hs)]
    return [np.array([p[j] for p in per_point]).reshape(len(zs), -1)
            for j in range(len(kernel.outputs))]


def worst_error(values, ref: Reference) -> float:
    """max |values − reference| / mag over all outputs; 0/0 (exact constants) counts as 0."""
    worst = 0.0
    for c, (v, m) in zip(values, ref.outputs):
        assert c.shape == v.shape
        assert np.all(m >= np.abs(v) * (1 - 1e-12)), "the magnitude must bound the value"
        err = np.abs(c - v)
        if err.size:
            with np.errstate(divide="ignore", invalid="ignore"):
                worst = max(worst, float(np.where(err == 0, 0.0, err / m).max()))
    return worst


def coefficient_arguments(kernel):
    """Distinct arguments s of the coefficients applied in a kernel (a graph walk)."""
    found, seen = [], set()
    stack = [e for _, M in kernel.outputs for e in M] + [e for _, e in kernel.definitions]
    while stack:
        e = stack.pop()
        if e in seen:
            continue
        seen.add(e)
        if isinstance(e, AnalyticCoefficient) and e.args[0] not in found:
            found.append(e.args[0])
        stack.extend(e.args)
    return found


def _points(rng, dm, kernel, count=POINTS):
    """z ∈ [−1, 1], h ∈ [0.01, 0.2]; in the second half of the points, the coordinates in
    each coefficient argument s = θ² (h² times a quadratic form in them) are scaled to
    θ ∈ [1.5, 4.5] (see module docstring)."""
    zs, hs = rng.uniform(-1.0, 1.0, (count, len(kernel.z))), rng.uniform(0.01, 0.2, count)
    wide = np.arange(count // 2, count)
    # an argument may use the kernel's definitions (differences of fibres): in z
    definitions = dict(kernel.definitions)
    for arg in coefficient_arguments(kernel):
        arg = arg.xreplace(definitions)
        columns = [i for i, x in enumerate(kernel.z) if x in arg.free_symbols]
        assert arg.free_symbols <= set(kernel.z) | {dm.step} and columns, arg
        s = Rounding(_inputs(dm, kernel, zs[wide], dm.defaults, hs[wide]))(arg)[0]
        theta = rng.uniform(1.5, 4.5, len(wide))
        zs[np.ix_(wide, columns)] *= np.sqrt(theta ** 2 / s)[:, None]
    return zs, hs


#: Worst |C − reference|/mag per (model, kernel) and coefficient sensitivities, filled in
#: by the tests (for reports).
RECORD: dict = {}


@pytest.mark.parametrize("name", BUNDLED)
def test_every_kernel_matches_sympy(name, compiled, derived):
    mod, dm = compiled(name), derived(name)
    assert set(mod.INFO.kernel_names) == {k.name for k in dm.kernels}
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    runs, reached = [], {}
    for kernel in dm.kernels:
        zs, hs = _points(rng, dm, kernel)
        ref = reference(dm, kernel, zs, dm.defaults, hs)
        worst = worst_error(run_compiled(mod, kernel, zs, hs), ref)
        RECORD[name, kernel.name] = worst
        assert worst < TOL, f"{name}.{kernel.name}: relative error {worst:.2e}"
        runs.append((kernel, zs, hs, ref))
        for cls, s in ref.arguments:
            reached.setdefault(cls, []).append(np.ravel(s))
    assert bool(reached) == bool(dm.coefficients)
    runs.sort(key=lambda run: run[3].nodes)
    for cls, s in reached.items():
        # Both branches of every coefficient (series below SWITCH, closed form above) ran,
        s = np.concatenate(s)
        assert (s < SWITCH).any() and (s >= SWITCH).any(), (cls.__name__, s.min(), s.max())
        # and on each, a 10 % error in a coefficient (other than c ≡ 0) would give an error
        # of more than 100·TOL.
        for closed in (False, True) if cls.closed != 0 or any(cls.series) else ():
            effect = 0.0
            for kernel, zs, hs, ref in runs:
                if effect > 1e2 * TOL or cls not in {c for c, _ in ref.arguments}:
                    continue
                changed = reference(dm, kernel, zs, dm.defaults, hs, perturb=(cls, closed, 1.1))
                effect = max(effect, worst_error([v for v, _ in changed.outputs], ref))
            RECORD[name, cls.__name__, "closed" if closed else "series"] = effect
            assert effect > 1e2 * TOL, (cls.__name__, closed, effect)


@pytest.mark.parametrize("name", [n for n in BUNDLED if get(n).parameters])
def test_parameters_are_passed_at_run_time(name, compiled, derived):
    """Random, distinct parameter values reach the right slots of every kernel."""
    mod, dm = compiled(name), derived(name)
    assert dm.parameters, name
    rng = np.random.default_rng(7)
    values = [d * rng.uniform(0.5, 2.0) if d else rng.uniform(0.5, 2.0) for d in dm.defaults]
    by_name = {str(s): v for s, v in zip(dm.parameters, values)}
    for kernel in dm.kernels:
        zs, hs = _points(rng, dm, kernel, 20)
        ref = reference(dm, kernel, zs, values, hs)
        for params_arg in (by_name, values):  # mapping and full sequence
            worst = worst_error(run_compiled(mod, kernel, zs, hs, params_arg), ref)
            assert worst < TOL, f"{name}.{kernel.name}: relative error {worst:.2e}"
        # The comparison discriminates: where a kernel depends on the parameters, running
        # it with the defaults instead would be an error far above TOL.
        uses = [M for _, M in kernel.outputs] + [e for _, e in kernel.definitions]
        if any(e.has(*dm.parameters) for e in uses):
            effect = worst_error(run_compiled(mod, kernel, zs, hs), ref)
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


class Taylor(_Evaluator):
    """Taylor coefficients to degree 3 in t of SymPy expressions along z + t·e_i, at a
    batch of points (arrays 4 × batch). ``inputs`` maps symbols to such arrays."""

    def __init__(self, inputs):
        self.memo = dict(inputs)

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


def _steps(zs):
    """Exact central differences: δ = 2⁻¹⁷·2^⌈log₂ max(1, |z|)⌉ (≈ u^{1/3}·max(1, |z|), a
    power of two) and z rounded to a multiple of δ·2⁻¹³, so that z ± δ are exact."""
    delta = 2.0 ** (np.ceil(np.log2(np.maximum(1.0, np.abs(zs)))) - 17)
    return np.round(zs / (delta * 2.0 ** -13)) * (delta * 2.0 ** -13), delta


def _taylor_inputs(dm, kernel, w, direction, params, hs):
    """Degree-3 Taylor inputs at points ``w`` along the coordinate ``direction`` (per point)."""
    B = len(w)
    inputs = {}
    for j, x in enumerate(kernel.z):
        series = np.zeros((4, B))
        series[0], series[1] = w[:, j], direction == j
        inputs[x] = series
    for x, v in zip(dm.parameters, params):
        inputs[x] = np.array([v, 0.0, 0.0, 0.0])[:, None]
    inputs[dm.step] = np.stack([hs, 0 * hs, 0 * hs, 0 * hs])
    return inputs


@pytest.mark.parametrize("name", BUNDLED)
def test_jacobians_match_central_differences(name, compiled, derived):
    mod, dm = compiled(name), derived(name)
    kernels = [k for k in dm.kernels if "jacobian" in dict(k.outputs)]
    constrained = {"constraint"} if dm.constraint_count else {"step"}
    bounded = {"inequality"} if dm.inequality_names else set()
    # first order: ∂F⁻L_d/∂z, the discrete Legendre transform's Jacobian (a State start)
    legendre = {"momentum_minus"} if dm.order == 1 and not dm.constraint_count else set()
    # an unknown end: the partial stencils of its last nodes and the end conditions ψ
    ends = {f"stencil_end{j}" for j in range(dm.order)} | (
        {"end_condition"} if dm.end_names else set()) if dm.end_free else set()
    assert {k.name for k in kernels} == constrained | bounded | legendre | ends | (
        {"stencil"} if dm.whole_trajectory else set())
    p = list(dm.defaults)
    for kernel in kernels:
        rng = np.random.default_rng(zlib.crc32(f"{name}:{kernel.name}".encode()))
        assert [n for n, _ in kernel.outputs][1:] == ["jacobian"]
        residual, jacobian = (M for _, M in kernel.outputs)
        nz, n = len(kernel.z), residual.shape[0]
        columns = np.arange(nz - jacobian.shape[1], nz)  # step: f_{K−1}; stencil: all of z
        zs, hs = _points(rng, dm, kernel, FD_POINTS)
        zs, _ = _steps(zs)
        N, C = len(zs), len(columns)
        # A batch of (point, column i) pairs: z − δe_i, z, z + δe_i.
        rows, cols = np.arange(N * C), np.tile(columns, N)
        delta = _steps(np.repeat(zs, C, axis=0)[rows, cols])[1]
        shifted = {}
        for sign in (-1, 0, 1):
            shifted[sign] = np.repeat(zs, C, axis=0)
            shifted[sign][rows, cols] += sign * delta
        assert np.all(shifted[1][rows, cols] - shifted[0][rows, cols] == delta)  # exact
        assert np.all(shifted[0][rows, cols] - shifted[-1][rows, cols] == delta)
        hb = np.repeat(hs, C)
        # |∂³R/∂z_i³| at z − δe_i, z, z + δe_i (Taylor arithmetic through the definitions).
        third = []
        for sign in (-1, 0, 1):
            ev = Taylor(_taylor_inputs(dm, kernel, shifted[sign], cols, p, hb))
            ev.define(kernel.definitions)
            third.append([np.broadcast_to(6 * ev(e)[3], (N * C,)) for e in residual])
        d3 = np.abs(np.array(third)).max(axis=0).T  # (N·C) × n

        def by_point(a):  # (N·C) × n → N × n × C, the layout of the Jacobians
            return a.reshape(N, C, n).transpose(0, 2, 1)
        # Rounding: magnitudes and depths of R at z ± δe_i and of J at z.
        minus, plus = (reference(dm, kernel, shifted[sign], p, hb) for sign in (-1, 1))
        at_z = reference(dm, kernel, zs, p, hs)
        mag_r = by_point(minus.outputs[0][1] + plus.outputs[0][1])
        mag_j = at_z.outputs[1][1].reshape(N, n, C)
        # The compiled central differences and Jacobians.
        r_plus, r_minus = (run_compiled(mod, kernel, shifted[sign], hb)[0] for sign in (1, -1))
        fd = by_point((r_plus - r_minus) / (2 * delta[:, None]))
        jac = run_compiled(mod, kernel, zs, hs)[1].reshape(N, n, C)
        d = by_point(np.repeat(delta[:, None], n, axis=1))
        bound = 2 * (d ** 2 / 6 * by_point(d3) + gamma(minus.depth) * mag_r / (2 * d)
                     + U * np.abs(fd) + gamma(at_z.depth) * mag_j)
        err = np.abs(jac - fd)
        assert np.all(err <= bound), (name, kernel.name, float((err / bound).max()))
        # Discriminating: the bound is below 1e-6 of the Jacobian's row, at every point with
        # all coefficients on the series branch (see module docstring for the others);
        # 1e-5 for optimal-control residuals, whose truncation term δ²/6·|∂³R/∂z³| is
        # larger: L̃ is quadratic in accelerations (q_{k+1} − 2q_k + q_{k−1})/h², so at
        # h = 0.01 the third derivative carries a further 1/h² against the first; so for
        # Lagrangians of order k > 2, quadratic in differences of ξ over h^{k−1}
        # (se3_snap: 1.3e-6).
        row = np.maximum(np.abs(jac).max(axis=2, keepdims=True), 1.0)
        narrow = slice(0, N // 2) if coefficient_arguments(kernel) else slice(None)
        sharp = 1e-5 if dm.control_count or dm.order > 2 else 1e-6
        assert np.all(bound[narrow] <= sharp * row[narrow]), float((bound / row)[narrow].max())
        worst = float((err / row).max())
        RECORD[name, kernel.name, "fd"] = worst, float(np.mean(bound <= 1e-6 * row))
        assert worst < 1e-7
