"""Jacobians in SymEngine (symvi.derivation.differentiate) against SymPy's own ``diff``."""
from __future__ import annotations

import numpy as np
import sympy as sp

import symvi.derivation.derive as derive_module
import symvi.derivation.differentiate as differentiate
from symvi.declaration.rank import sequential_lambdify
from symvi.discretisation.discretise import discretise
from symvi.groupoids.analytic import DEXPINV, coefficients
from symvi.models import get


def _by_sympy(monkeypatch, dm):
    """The kernels of ``dm`` with every Jacobian taken by SymPy."""
    with monkeypatch.context() as m:
        m.setattr(differentiate, "jacobian",
                  lambda F, z, chain=(): differentiate._sympy_jacobian(sp.Matrix(F).reshape(len(F), 1), z, chain))
        m.setattr(differentiate, "gradient_and_hessian", lambda f, z: (
            sp.Matrix([f]).jacobian(z), sp.Matrix([f]).jacobian(z).T.jacobian(z)))
        m.setattr(derive_module, "jacobian", differentiate.jacobian)
        m.setattr(derive_module, "gradient_and_hessian", differentiate.gradient_and_hessian)
        return derive_module._kernels(dm)


def test_every_kernel_agrees_with_sympy(monkeypatch):
    """Every output of every kernel of rigid_body_oc_exp — the step and stencil
    Jacobians, the window Hessian through the exponential's coefficients c(s) and c′(s),
    the variations' curvature — at random points, to rounding. (The chain rule through
    named base points: tests/test_chain_rule.py, against SymPy on the substituted
    residual.)"""
    name = "rigid_body_oc_exp"
    dm = discretise(get(name))
    fast, reference = derive_module._kernels(dm), _by_sympy(monkeypatch, dm)
    assert [k.name for k in fast] == [k.name for k in reference]
    assert {"window_hessian", "step", "stencil"} <= {k.name for k in fast}
    rng = np.random.default_rng(3)
    for k, r in zip(fast, reference):
        for (label, M), (_, R) in zip(k.outputs, r.outputs):
            assert M.shape == R.shape, (k.name, label)
            args = list(k.z) + list(dm.parameters) + [dm.step]
            f = sequential_lambdify(args, k.definitions, M)
            g = sequential_lambdify(list(r.z) + list(dm.parameters) + [dm.step], r.definitions, R)
            for _ in range(3):
                point = list(rng.uniform(-0.6, 0.6, len(k.z))) + list(dm.defaults) + [0.1]
                a = np.asarray(f(*point), dtype=float)
                b = np.asarray(g(*point), dtype=float)
                assert np.allclose(a, b, rtol=1e-12, atol=1e-12 * (1 + np.abs(b).max(initial=0))), \
                    (name, k.name, label)


def test_chain_rule_through_coefficients_and_back_to_the_same_symbols():
    """d/dx of c(x² + y)·sin x, twice: the coefficient's derivatives c′, c″ appear, the
    result is in the caller's own symbols (Dummy included), and equals SymPy's."""
    c = coefficients(DEXPINV, 1, 1)[0]
    x, y = sp.Dummy("x", real=True), sp.Symbol("y", positive=True)
    f = c(x**2 + y) * sp.sin(x) + y**2
    gradient, hessian = differentiate.gradient_and_hessian(f, [x, y])
    assert gradient.free_symbols <= {x, y} and hessian.free_symbols <= {x, y}
    expected = sp.Matrix([f]).jacobian([x, y])
    assert sp.simplify(gradient - expected) == sp.zeros(1, 2)
    assert sp.simplify(hessian - expected.T.jacobian([x, y])) == sp.zeros(2, 2)
