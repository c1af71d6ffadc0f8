"""The merit of the whole-trajectory solve for constrained optimal control (DESIGN.md §4).

Newton's step on the optimality system [R_η; Φ_d] = 0 keeps the linearised constraints,
J_Φ d = −Φ_d; along it the cost S = Σ L_d changes at the rate R_η·d + λ·Φ_d (R_η the node
rows of the residual, the gradient of S + λ·Φ_d), so the ℓ1 exact penalty
φ = S + ν‖Φ_d‖₁ decreases for ν above the new multipliers (Nocedal & Wright §18.3). The
solver's slope is checked here against finite differences of S and ‖Φ_d‖₁ along the
step, from an infeasible chord guess of the heavy top with rotors. Without constraints the
merit is S itself, and a step that climbs it is shifted until it descends.
"""
from __future__ import annotations

import importlib

import numpy as np
import pytest
from scipy.sparse import dia_matrix

from symvi.models import get

NAME, N = "heavy_top_rotors_oc", 24


def runtime_of(mod, stage: str):
    """The generated package's own copy of a run-time module."""
    return importlib.import_module(f"{mod.__name__}._runtime.{stage}")


def dense_jacobian(ab: np.ndarray, bw: int) -> np.ndarray:
    """The Jacobian from the assembler's band storage, ab[2 bw + row − col, col]: the
    diagonals ab[bw:] at offsets col − row = bw … −bw."""
    n = ab.shape[1]
    return dia_matrix((ab[bw:], bw - np.arange(2 * bw + 1)), shape=(n, n)).toarray()


def chord_problem(mod, n_steps: int, horizon: float):
    """(problem, path at the chord guess, res, ab, bw) for the bundled example's boundary
    data over ``horizon`` in ``n_steps`` steps."""
    ex = get(mod.model.name).example
    h, p = horizon / n_steps, mod.model.params(None)
    path = runtime_of(mod, "core.paths").initial_path(mod.model, ex.start, ex.end, n_steps,
                                                 "chord", p, h)
    problem = runtime_of(mod, "bvp.assembly").Problem(mod.model, p, h)
    res, ab, bw, finite = problem.assemble(path, True)
    assert finite
    return problem, path, res, ab, bw


@pytest.fixture(scope="module")
def newton_step(compiled):
    """(problem, path, res, delta) at the chord guess of the bundled example at N steps,
    with random multipliers."""
    mod, ex = compiled(NAME), get(NAME).example
    problem, path, _, _, _ = chord_problem(mod, N, ex.n_steps * ex.h)
    path.lam[:] = np.random.default_rng(3).normal(size=path.lam.shape)
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


def test_ascent_direction_is_shifted_not_abandoned(compiled):
    """Far from the optimum the Hessian of S can be indefinite and Newton's step climb S.
    At the chord guess of the double pendulum over T = 3 it does (R·d > 0); the descent
    step must then shift the Hessian until it descends, and return a path of lower cost,
    not give up and hand over to the residual-norm line search, which climbs S (with
    that interleaving Newton stalled here after 179 iterations)."""
    mod = compiled("double_pendulum_oc")
    problem, path, res, ab, bw = chord_problem(mod, 300, 3.0)
    delta = problem.solve(ab, bw, -res)
    assert res @ delta > 0.0                        # the Newton step ascends
    globalisation = runtime_of(mod, "bvp.globalisation")
    moved, taken = globalisation.descent_step(problem, path, res, ab, bw, delta)
    assert taken is not None and problem.shift > 0.0
    assert problem.merit(moved)[0] < problem.merit(path)[0]


def test_double_pendulum_over_a_longer_horizon_converges_to_a_minimum(compiled):
    """From the chord over T = 3 (N = 300), within the default 50 iterations; the
    converged path is a minimum of S: the Jacobian of the residual (the Hessian of S on
    the free nodes) is positive definite there."""
    mod, ex = compiled("double_pendulum_oc"), get("double_pendulum_oc").example
    result = mod.solve_bvp(ex.start, ex.end, 300, 0.01)
    assert result.success, result.message
    problem = runtime_of(mod, "bvp.assembly").Problem(mod.model, mod.model.params(None), 0.01)
    path = runtime_of(mod, "core.paths").initial_path(mod.model, ex.start, ex.end, 300,
                                                 result.x[2:-2], problem.p, 0.01)
    dense = dense_jacobian(*problem.assemble(path, True)[1:3])
    hessian = (dense + dense.T) / 2
    assert np.abs(dense - dense.T).max() < 1e-8 * np.abs(dense).max()
    assert np.linalg.eigvalsh(hessian)[0] > 0.0


def test_curvature_is_the_quadratic_form_of_the_node_block(compiled, newton_step):
    """The descent step's curvature test reads d_ηᵀ(W + μI)d_η off the band storage: the
    node block W of the dense Jacobian, d_η the step's node part."""
    problem, path, res, delta = newton_step
    _, ab, bw, _ = problem.assemble(path, True)
    nodes = ~problem.constraint_rows(path)
    W, d = dense_jacobian(ab, bw)[np.ix_(nodes, nodes)], delta[nodes]
    assert problem.curvature(ab, bw, delta, nodes, 0.5) == pytest.approx(d @ W @ d + 0.5 * d @ d, rel=1e-12)
