"""Named base points in kernels: the chain rule through x_j = β(x_{j−1}, f_{j−1}).

Kernels of action groupoids keep later base points as named intermediate quantities
(``Kernel.definitions``) and differentiate through them by the chain rule. Here the
stencil Jacobian so obtained is compared, at random points, with the derivative of the
fully substituted residual by Richardson-extrapolated central differences (an oracle
independent of any symbolic differentiation; error ≈ δ⁴ + ε/δ ≈ 1e-11).
"""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from symvi.derivation.derive import _Engine, _stencil
from symvi.derivation.differentiate import jacobian
from symvi.discretisation.discretise import discretise
from symvi.models import get
from symvi.declaration.rank import sequential_lambdify


def _differences(f, point: np.ndarray, unknowns: int, delta: float = 1e-3) -> np.ndarray:
    """∂f/∂z at ``point`` (its first ``unknowns`` entries) by central differences with
    steps δ and δ/2, combined by Richardson's extrapolation (error O(δ⁴))."""
    def central(step):
        columns = []
        for k in range(unknowns):
            up, down = point.copy(), point.copy()
            up[k] += step
            down[k] -= step
            columns.append((np.array(f(*up), float) - np.array(f(*down), float)).reshape(-1)
                           / (2 * step))
        return np.stack(columns, axis=1)
    return (4 * central(delta / 2) - central(delta)) / 3


@pytest.mark.parametrize("name", ["heavy_top", "spherical_pendulum_exp"])
def test_stencil_jacobian_through_named_base_points(name):
    dm = discretise(get(name))
    st = _stencil(dm, 2 * dm.order)
    assert st.definitions, "action groupoids name their later base points"
    residual = _Engine(dm).variation(st, dm.order, range(dm.order + 1))
    chained = st.total_jacobian(residual)
    substituted = residual
    for symbol, expr in reversed(st.definitions):
        substituted = substituted.xreplace({symbol: expr})
    args = list(st.z) + list(dm.parameters) + [dm.step]
    f_chained = sequential_lambdify(args, st.definitions + st.jacobian_definitions, chained)
    f_substituted = sp.lambdify(args, substituted, "numpy", cse=True)
    rng = np.random.default_rng(3)
    for _ in range(5):
        point = np.array(list(rng.uniform(-0.8, 0.8, len(st.z))) + list(dm.defaults) + [0.1])
        a = np.array(f_chained(*point), float)
        b = _differences(f_substituted, point, len(st.z))
        assert np.abs(a).max() > 0.1  # a non-trivial Jacobian
        np.testing.assert_allclose(a, b, rtol=1e-8, atol=1e-8 * np.abs(b).max())
    # and the chain rule is needed: the direct derivative ignoring x_j's dependence differs
    naive = np.array(sequential_lambdify(args, st.definitions, jacobian(residual, st.z))(*point),
                     float)
    assert np.abs(naive - b).max() > 1e-3 * np.abs(b).max()
