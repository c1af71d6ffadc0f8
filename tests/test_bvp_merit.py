"""The merit of the whole-trajectory solve for constrained optimal control (DESIGN.md §4).

Newton's step on the optimality system [R_η; Φ_d] = 0 keeps the linearised constraints,
J_Φ d = −Φ_d; along it the cost S = Σ L_d changes at the rate R_η·d + λ·Φ_d (R_η the node
rows of the residual, the gradient of S + λ·Φ_d), so the ℓ1 exact penalty
φ = S + ν‖Φ_d‖₁ decreases for ν above the new multipliers (Nocedal & Wright §18.3). The
solver's slope is checked here against finite differences of S and ‖Φ_d‖₁ along the
step, from an infeasible chord guess of the heavy top with rotors.
"""
from __future__ import annotations

import sys

import numpy as np
import pytest

from symvi.models import get

NAME, N = "heavy_top_rotors_oc", 24


@pytest.fixture(scope="module")
def newton_step(compiled):
    """(problem, path, res, delta) at the chord guess of the bundled example at N steps."""
    mod = compiled(NAME)
    package = mod.__name__
    runtime = sys.modules[f"{package}._runtime.bvp"]
    paths = sys.modules[f"{package}._runtime.paths"]
    ex = get(NAME).example
    h, p = ex.n_steps * ex.h / N, mod.model.params(None)
    path = paths.initial_path(mod.model, ex.start, ex.end, N, None, p, h)
    path.lam[:] = np.random.default_rng(3).normal(size=path.lam.shape)
    problem = runtime._Problem(mod.model, p, h)
    res, ab, bw, finite = problem.assemble(path, True)
    assert finite
    return problem, path, res, problem.solve(ab, bw, -res)


def along(problem, path, delta, alpha):
    """(S, Φ_d in the block layout) after the step α·delta."""
    trial = problem.moved(path, delta, alpha)
    rows = problem.constraint_rows(path)
    return problem.merit(trial)[0], problem.assemble(trial, False)[0][rows]


def test_newton_step_keeps_the_linearised_constraints(newton_step):
    problem, path, res, delta = newton_step
    rows = problem.constraint_rows(path)
    eps = 1e-6
    ahead, behind = along(problem, path, delta, eps)[1], along(problem, path, delta, -eps)[1]
    rate = (ahead - behind) / (2 * eps)
    assert np.abs(res[rows]).max() > 1e-3          # the chord guess is infeasible
    np.testing.assert_allclose(rate, -res[rows], atol=1e-6 * np.abs(res[rows]).max())


def test_cost_slope_along_the_step(newton_step):
    problem, path, res, delta = newton_step
    rows = problem.constraint_rows(path)
    predicted = res[~rows] @ delta[~rows] + problem.multipliers(path) @ res[rows]
    eps = 1e-6
    measured = (along(problem, path, delta, eps)[0] - along(problem, path, delta, -eps)[0]) \
        / (2 * eps)
    assert measured == pytest.approx(predicted, rel=1e-6)
    # the multipliers matter: the slope of S alone is not R_η·d
    assert abs(res[~rows] @ delta[~rows] - measured) > 1e-3 * abs(measured)


def test_multipliers_in_the_block_layout(newton_step):
    """The multiplier of each constraint row is the one the residual was assembled with:
    moving λ by Δ changes the node rows by J_Φᵀ Δ, linear in Δ, and leaves Φ_d alone."""
    problem, path, res, _ = newton_step
    rows = problem.constraint_rows(path)
    assert problem.multipliers(path).size == rows.sum()
    step = np.zeros_like(res)
    step[rows] = 1.0
    moved = problem.moved(path, step, 1.0)
    np.testing.assert_allclose(problem.multipliers(moved), problem.multipliers(path) + 1.0)
    np.testing.assert_allclose(problem.assemble(moved, False)[0][rows], res[rows], atol=1e-14)
