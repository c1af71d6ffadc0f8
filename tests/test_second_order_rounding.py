"""The second-order test is not decided by rounding (``optimality.py``): a hunt moved the
cart-pole's verified minimum at N = 150 (smallest eigenvalue of the reduced Hessian
ZᵀWZ +2.5) down by σI on the node block, σ chosen in independent dense algebra so that
the reduced minimum becomes −δ. The plain Cholesky test of W + ρAᵀA accepted such saddles
at ρ = 10⁶ times the scale ratio down to δ = 2.5e-4, its factorisation's rounding
ε·ρ‖AᵀA‖ exceeding δ; the test now asks a margin of that rounding and rejects them, while
still accepting the minimum moved down to a tenth of its curvature."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import null_space

import battery
from symvi.models import get

NAME, N = "cart_pole_oc", 150


@pytest.fixture(scope="module")
def minimum(compiled):
    module, ex = compiled(NAME), get(NAME).example
    r = module.solve_bvp(ex.start, ex.end, N, ex.h * ex.n_steps / N, guess="chord")
    assert r.success, r.message
    J, rows = battery.newton_matrix(module, NAME, N, r)
    pinned = (np.diag(J) == 1.0) & ((J != 0).sum(0) == 1) & ((J != 0).sum(1) == 1)
    keep = ~rows & ~pinned
    W = (J[keep][:, keep] + J[keep][:, keep].T) / 2
    Z = null_space(J[rows][:, keep])
    lowest = np.linalg.eigvalsh(Z.T @ W @ Z)[0]
    _, _, ab, bw = battery.assembled(module, NAME, N, r)
    return module, ab, bw, rows, keep, W, Z, lowest


@pytest.mark.parametrize("reduced", [-2.5e-4, -1e-6, 0.1])
def test_a_minimum_moved_below_zero_is_not_accepted(minimum, reduced):
    module, ab, bw, rows, keep, W, Z, lowest = minimum
    assert lowest > 1.0
    target = reduced * lowest if reduced > 0 else reduced
    sigma = lowest - target
    moved = np.array(ab, order="F")
    moved[2 * bw, keep] -= sigma
    check = np.linalg.eigvalsh(Z.T @ (W - sigma * np.eye(len(W))) @ Z)[0]
    assert abs(check - target) <= 1e-6 * lowest
    verdict = battery.runtime(module, "bvp.optimality").second_order(moved, bw, rows)
    assert verdict.minimum == (target > 0), (target, verdict)


@pytest.mark.parametrize("reduced", [-2.5e-4, -1e-6, 0.1])
def test_the_lifted_inertia_tells_the_same(minimum, reduced):
    """The verdict of the lifted system (from N = 2000 on): its inertia count of J − σI on
    the node corrections, assembled here at N = 150."""
    module, _, _, _, _, W, Z, lowest = minimum
    target = reduced * lowest if reduced > 0 else reduced
    ex = get(NAME).example
    r = module.solve_bvp(ex.start, ex.end, N, ex.h * ex.n_steps / N, guess="chord")
    problem, path, _, _ = battery.assembled(module, NAME, N, r, lifted=True)
    lifted = problem.lifted_system
    assert lifted is not None
    assert lifted.minimum(-(lowest - target))[0] == (target > 0)
