"""Compiled kernels against their SymPy expressions, and Jacobians against differences.

Error measure. The C code (common subexpressions eliminated, powers expanded) and
``lambdify`` evaluate the same expression in different orders, so they differ by rounding
only. Each is within γ_k·mag(e) of the exact value, where mag(e) is e evaluated with every
sum replaced by the sum of the absolute values of its terms (the standard running bound for
sums and products; a sine or cosine adds at most u(1 + mag(argument))) and γ_k ≈ k·u for an
evaluation k operations deep, ≈1e-14 here. So every entry is compared relative to its own
mag(e) and must agree to 1e-12. A tolerance relative to max(1, |value|) would not do: the
three-point residual is (1/h³)·(a fourth difference), with terms of size 1e6·|q| at
h = 0.01, and wherever the random point makes the difference small its absolute rounding
error (1e-10) would exceed 1e-12·max(1, |value|) though both evaluations are right. mag(e)
is at least |e| and, away from such cancellations, of the same size, so any real
discrepancy (a coefficient, a sign, a parameter in the wrong slot) is an O(1) relative
error.

Finite differences: central differences with δ_i = u^{1/3}·max(1, |z_i|) have error
δ_i²/6·|∂³R/∂z_i³| (truncation, with the third derivative taken symbolically) plus
2·γ·mag(R)/(2δ_i) (rounding of the two compiled residuals, γ = 32u generously); the test
uses twice that sum as the tolerance of each entry and checks that it is below 1e-6 of the
Jacobian's row, so that the comparison is discriminating.
"""
from __future__ import annotations

import zlib

import numpy as np
import pytest
import sympy as sp

from conftest import BUNDLED

U = np.finfo(float).eps
TOL = 1e-12
POINTS = 100


def magnitude(e: sp.Expr) -> sp.Expr:
    """Running-error magnitude of ``e``: sums of absolute values (see module docstring)."""
    if e.is_Number:
        return abs(e)
    if e.is_Symbol:
        return sp.Abs(e)
    if e.is_Add:
        return sp.Add(*[magnitude(a) for a in e.args])
    if e.is_Mul:
        return sp.Mul(*[magnitude(a) for a in e.args])
    if e.is_Pow and e.exp.is_Integer:
        if e.exp > 0:
            return magnitude(e.base)**e.exp
        # 1/b^m carries the relative error of b: mag(b)/|b|.
        return -e.exp * sp.Abs(e) * magnitude(e.base) / sp.Abs(e.base)
    if isinstance(e, (sp.sin, sp.cos)):
        return 1 + magnitude(e.args[0])
    raise NotImplementedError(f"no magnitude rule for {type(e).__name__}: {e}")


class Reference:
    """lambdified outputs and magnitudes of one kernel; args (z, parameters, h)."""

    def __init__(self, dm, kernel):
        self.args = list(kernel.z) + list(dm.parameters) + [dm.step]
        self.names = [name for name, _ in kernel.outputs]
        self.shapes = [M.shape for _, M in kernel.outputs]
        flat = [e for _, M in kernel.outputs for e in M]
        self.sizes = [len(M) for _, M in kernel.outputs]
        self._value = sp.lambdify(self.args, flat, modules="math")
        self._magnitude = sp.lambdify(self.args, [magnitude(e) for e in flat], modules="math")

    def _split(self, flat):
        out, start = [], 0
        for size in self.sizes:
            out.append(np.array(flat[start:start + size], dtype=float))
            start += size
        return out

    def value(self, z, p, h):
        return self._split(self._value(*z, *p, h))

    def magnitude(self, z, p, h):
        return self._split(self._magnitude(*z, *p, h))


def _points(rng, nz, count=POINTS):
    return rng.uniform(-1.0, 1.0, (count, nz)), rng.uniform(0.01, 0.2, count)


def _compare(mod, dm, kernel, zs, hs, values, params_arg):
    ref = Reference(dm, kernel)
    worst, worst_plain = 0.0, 0.0
    for z, step in zip(zs, hs):
        compiled = [np.asarray(o).ravel() for o in mod.evaluate(kernel.name, z, step,
                                                                 params=params_arg)]
        assert [c.size for c in compiled] == ref.sizes
        for c, s, m in zip(compiled, ref.value(z, values, step), ref.magnitude(z, values, step)):
            if np.size(c) == 0:  # e.g. the target of a groupoid over a point
                continue
            assert np.all(m >= np.abs(s) * (1 - 1e-12)), "magnitude must bound the value"
            err = np.abs(c - s) / np.maximum(m, np.finfo(float).tiny)
            worst = max(worst, float(err.max()))
            worst_plain = max(worst_plain,
                              float((np.abs(c - s) / np.maximum(1.0, np.abs(s))).max()))
    return worst, worst_plain


@pytest.mark.parametrize("name", BUNDLED)
def test_every_kernel_matches_sympy(name, compiled, derived):
    mod, dm = compiled(name), derived(name)
    assert set(mod.INFO["kernels"]) == {k.name for k in dm.kernels}
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    for kernel in dm.kernels:
        zs, hs = _points(rng, len(kernel.z))
        worst, _ = _compare(mod, dm, kernel, zs, hs, list(dm.defaults), None)
        assert worst < TOL, f"{name}.{kernel.name}: relative error {worst:.2e}"


@pytest.mark.parametrize("name", [n for n in BUNDLED if n != "cubic_spline"])
def test_parameters_are_passed_at_run_time(name, compiled, derived):
    """Random, distinct parameter values reach the right slots of every kernel."""
    mod, dm = compiled(name), derived(name)
    assert dm.parameters, name
    rng = np.random.default_rng(7)
    values = [d * rng.uniform(0.5, 2.0) if d else rng.uniform(0.5, 2.0) for d in dm.defaults]
    by_name = {str(s): v for s, v in zip(dm.parameters, values)}
    for kernel in dm.kernels:
        zs, hs = _points(rng, len(kernel.z), 20)
        for params_arg in (by_name, values):  # mapping and full sequence
            worst, _ = _compare(mod, dm, kernel, zs, hs, values, params_arg)
            assert worst < TOL, f"{name}.{kernel.name}: relative error {worst:.2e}"
        # The comparison discriminates: where a kernel depends on the parameters, running
        # it with the defaults instead would be an error far above TOL.
        if not any(M.has(*dm.parameters) for _, M in kernel.outputs):
            continue
        ref, effect = Reference(dm, kernel), 0.0
        for z, step in zip(zs, hs):
            new = mod.evaluate(kernel.name, z, step, params=by_name)
            old = mod.evaluate(kernel.name, z, step)
            for a, b, m in zip(new, old, ref.magnitude(z, values, step)):
                effect = max(effect, float((np.abs(np.ravel(a) - np.ravel(b)) / m).max()))
        assert effect > 1e3 * TOL, (kernel.name, effect)


def _third_derivatives(dm, kernel, residual):
    args = list(kernel.z) + list(dm.parameters) + [dm.step]
    third = [[sp.diff(e, s, 3) for s in kernel.z] for e in residual]
    return sp.lambdify(args, third, modules="math")


@pytest.mark.parametrize("name", BUNDLED)
@pytest.mark.parametrize("which", ["step", "stencil"])
def test_jacobians_match_central_differences(name, which, compiled, derived):
    mod, dm = compiled(name), derived(name)
    kernel = dm.kernel(which)
    residual = dict(kernel.outputs)["residual"]
    ref = Reference(dm, kernel)
    third = _third_derivatives(dm, kernel, residual)
    nz, n = len(kernel.z), dm.fibre_dim
    columns = range(nz - n, nz) if which == "step" else range(nz)
    p = list(dm.defaults)
    rng = np.random.default_rng(zlib.crc32(f"{name}:{which}".encode()))
    zs, hs = _points(rng, nz, 50)
    worst = 0.0
    for z, step in zip(zs, hs):
        _, jac = mod.evaluate(which, z, step)
        assert jac.shape == (n, len(columns))
        mag = ref.magnitude(z, p, step)[0]
        for col, i in enumerate(columns):
            delta = U ** (1 / 3) * max(1.0, abs(z[i]))
            plus, minus = z.copy(), z.copy()
            plus[i] += delta
            minus[i] -= delta
            fd = (mod.evaluate(which, plus, step)[0] - mod.evaluate(which, minus, step)[0]) \
                / (plus[i] - minus[i])
            # |∂³R/∂z_i³| on [z − δ, z + δ], where the remainder's intermediate point lies
            d3 = np.max([np.abs(np.array(third(*w, *p, step), dtype=float)[:, i])
                         for w in (minus, z, plus)], axis=0)
            bound = 2 * (delta**2 / 6 * d3 + 32 * U * mag / delta)
            err = np.abs(jac[:, col] - fd)
            assert np.all(err <= bound), (name, which, i, err, bound)
            row = np.abs(jac).max(axis=1)
            assert np.all(bound <= 1e-6 * np.maximum(row, 1.0)), (bound, row)
            worst = max(worst, float((err / np.maximum(row, 1.0)).max()))
    assert worst < 1e-7
