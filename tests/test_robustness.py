"""Robust whole-trajectory solves from poor guesses, and SUCCESS only at minima (issue 20,
item 3).

The battery (:mod:`battery`): chord, zero and 20 smooth random perturbations of the
default guess, per bundled optimal-control problem. Every SUCCESS must be a minimum: the
solver's second-order test (W + ρAᵀA positive definite, :mod:`symvi._runtime.bvp.optimality`)
is checked here against the eigenvalues of the reduced Hessian ZᵀWZ, Z a basis of ker A
computed densely by SciPy.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import null_space

import battery
from symvi._runtime.bvp.optimality import second_order
from symvi.models import get

#: Success rate required at N = 100 and 1000 (issue 20 asks 100 % for the first three and
#: ≥ 90 % for the heavy top with rotors in variational form; 100 % measured for all four). The paper's non-variational forms of the
#: heavy top with rotors (2 of 22) are left to that script: their failures are reported.
REQUIRED = {"rigid_body_oc": 1.0, "double_pendulum_oc": 1.0, "cart_pole_oc": 1.0,
            "heavy_top_rotors_oc_variational": 1.0}


def banded(J: np.ndarray, bw: int) -> np.ndarray:
    """J in the band storage of ``Problem.assemble`` (:mod:`symvi._runtime.bvp.assembly`):
    ab[2 bw + row − col, col]."""
    n = J.shape[0]
    ab = np.zeros((3 * bw + 1, n))
    for row in range(n):
        for col in range(max(0, row - bw), min(n, row + bw + 1)):
            ab[2 * bw + row - col, col] = J[row, col]
    return ab


def reduced_hessian_minimum(J: np.ndarray, rows: np.ndarray) -> float:
    """The smallest eigenvalue of ZᵀWZ, dense: the independent verdict."""
    W = J[~rows][:, ~rows]
    W = 0.5 * (W + W.T)
    A = J[rows][:, ~rows]
    Z = null_space(A) if A.size else np.eye(W.shape[0])
    return float(np.linalg.eigvalsh(Z.T @ W @ Z).min())


def test_second_order_test_tells_minima_from_saddles():
    """W indefinite but positive on ker A is a minimum; negative curvature on ker A is
    not, however large ρ; an unconstrained W is judged by itself."""
    rng = np.random.default_rng(0)
    n, s = 6, 2
    A = rng.standard_normal((s, n))
    Z = null_space(A)
    Y = null_space(Z.T)                     # complement: the rows' space
    for lowest, expected in ((0.5, True), (-0.5, False)):
        W = Z @ np.diag([lowest, 1.0, 2.0, 3.0]) @ Z.T - 4.0 * Y @ Y.T   # indefinite
        J = np.block([[W, A.T], [A, np.zeros((s, s))]])
        rows = np.r_[np.zeros(n, bool), np.ones(s, bool)]
        verdict = second_order(banded(J, n + s - 1), n + s - 1, rows)
        assert verdict.minimum is expected, verdict
        assert (reduced_hessian_minimum(J, rows) > 0) is expected
    for W, expected in ((np.diag([1.0, 2.0]), True), (np.diag([1.0, -2.0]), False)):
        assert second_order(banded(W, 1), 1, np.zeros(2, bool)).minimum is expected


@pytest.mark.parametrize("N", [100, pytest.param(1000, marks=pytest.mark.slow)])
@pytest.mark.parametrize("name", [*REQUIRED, "rigid_body_oc_exp"])
def test_battery_succeeds_at_minima_only(compiled, name, N):
    mod = compiled(name)
    outcomes = battery.run(mod, name, N, count=20)
    rate = sum(r.success for r in outcomes.values()) / len(outcomes)
    print(f"\n{name}, N = {N}: {rate:.0%} of {len(outcomes)} guesses; failures: "
          f"{ {k: r.status.name for k, r in outcomes.items() if not r.success} }")
    for label, result in outcomes.items():
        assert result.success or result.message, label
        if result.success and N <= 100 and label in ("chord", "perturbed 0", "perturbed 1"):
            J, rows = battery.newton_matrix(mod, name, N, result)
            assert reduced_hessian_minimum(J, rows) > 0, (label, result.message)
    assert rate >= REQUIRED.get(name, 0.0), rate


def test_a_saddle_is_never_a_success(compiled, monkeypatch):
    """The battery found it: double_pendulum_oc at N = 1000 from perturbed guess 12, with
    the inertia correction switched off (the globalisation before it), converges to a
    stationary point of cost 1598 whose Hessian has eigenvalue −6.0 — which was SUCCESS.
    It is SADDLE now, and so is a solve started at it; with the correction the solver
    finds the minimum (cost 24.35)."""
    name, N = "double_pendulum_oc", 1000
    mod, ex = compiled(name), get(name).example
    guess = battery.guesses(mod, name, N)["perturbed 12"]
    with monkeypatch.context() as patch:
        patch.setattr(battery.runtime(mod, "bvp.globalisation"), "convexifying_shift",
                      lambda definite, start, first=0.0: start)
        saddle = mod.solve_bvp(ex.start, ex.end, N, ex.h * ex.n_steps / N, guess=guess,
                               maxiter=2000)
    assert saddle.status == mod.Status.SADDLE, saddle.message
    assert "not to a verified minimum" in saddle.message and "Cholesky pivot -" in saddle.message
    J, rows = battery.newton_matrix(mod, name, N, saddle)
    assert reduced_hessian_minimum(J, rows) < -1.0
    # the lifted system's inertia (tests/test_lifted.py) finds its one negative eigenvalue
    # (−6.0), and none once shifted by 10
    lifted = battery.assembled(mod, name, N, saddle, lifted=True)[0].lifted_system
    assert lifted.minimum() == (False, 1) and lifted.minimum(10.0) == (True, 0)
    again = mod.solve_bvp(ex.start, ex.end, N, ex.h * ex.n_steps / N, guess=saddle)
    assert again.status == mod.Status.SADDLE, again.message
    found = mod.solve_bvp(ex.start, ex.end, N, ex.h * ex.n_steps / N, guess=guess)
    assert found.success and found.cost < saddle.cost / 50, (found.message, found.cost)
