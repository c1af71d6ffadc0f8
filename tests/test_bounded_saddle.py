"""A false SUCCESS a hunt found (issue 21): the cart-pole swing-up at N = 150 from the chord
guess ended at a saddle — feasible, a KKT point, but with a negative eigenvalue of the
Hessian of the Lagrangian on the tangent space of the equalities and active bounds — that
the final second-order test accepted at a penalty of 10⁶ times W's scale, where its
Cholesky factorisation's rounding exceeds that eigenvalue. Checked here in independent
code: the reduced Hessian, by differences of complex-step gradients of the NumPy problem
on the null space of the constraints' gradients, is positive definite at every SUCCESS.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import null_space

from symvi.models import get
from test_bounded_cart_pole import NAME, BoundedSwingUp
from test_bounded_oc import complex_step_gradient


def reduced_eigenvalues(prob, r) -> np.ndarray:
    """Eigenvalues of Zᵀ∇²ℒ Z, ℒ = S + z·c + ν·Φ (ν fitted), Z spanning the null space of
    the gradients of Φ and of the active inequalities, at symvi's path."""
    z, mult = prob.from_symvi(r), r.bound_multipliers

    def grad(f, x):
        return complex_step_gradient(f, x, 4)

    def phi(v):
        return prob.phi(v)[..., 0]

    def flat(v):
        return prob.values(v).reshape(v.shape[:-1] + (-1,))

    active = np.where((prob.values(z) > -1e-7).reshape(-1))[0]
    A = grad(phi, z)
    Z = null_space(np.concatenate([A, grad(flat, z)[:, active]], 1).T)

    def with_bounds(v):
        return prob.cost(v) + (mult * prob.values(v)).sum((-2, -1))
    nu = np.linalg.lstsq(A, -grad(with_bounds, z), rcond=None)[0]

    def lagrangian(v):
        return with_bounds(v) + (phi(v) * nu).sum(-1)
    HZ = np.stack([(grad(lagrangian, z + 1e-4 * Z[:, j]) - grad(lagrangian, z - 1e-4 * Z[:, j]))
                   / 2e-4 for j in range(Z.shape[1])], 1)
    return np.linalg.eigvalsh((Z.T @ HZ + (Z.T @ HZ).T) / 2)


@pytest.mark.parametrize("guess", ["chord", "perturbed 0"])
def test_no_saddle_is_a_success(compiled, guess):
    import battery
    model, module = get(NAME), compiled(NAME)
    N = 150
    prob = BoundedSwingUp(model, N, 14.0, 0.8)
    start = guess if guess == "chord" else battery.guesses(module, NAME, N, count=1)[guess]
    r = module.solve_bvp(*prob.boundary, N, prob.h, guess=start)
    if not r.success:
        assert r.status.name != "SUCCESS" and r.message
        return
    eigenvalues = reduced_eigenvalues(prob, r)
    print(f"\n{guess}: cost {r.cost:.10f}, reduced eigenvalues {eigenvalues[0]:.3g}, "
          f"{eigenvalues[1]:.3g} … {eigenvalues[-1]:.3g}")
    assert eigenvalues[0] > 0.0, (r.cost, eigenvalues[:3])
