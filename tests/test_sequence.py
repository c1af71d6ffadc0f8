"""Long horizons (issue 50, items 1 and 5): the bounded solve on the lifted system, and mesh
sequencing (``_runtime/bvp/sequence.py``).

From N = 2000 the interior point solves its steps with the lifted system (κ ∝ N²), the
barrier's GᵀΣG in the windows' coordinates, and tests the inertia there: on the node
system its band Cholesky asked for a shift at every iteration from N ≈ 4000, and the
cart-pole swing-up STALLED (N = 4000) or ran out of iterations (N = 10⁴). Mesh
sequencing starts a solve at N ≥ 8·coarse from the solution at ``coarse`` steps,
resampled on the groupoid with its multipliers and active set: each test compares with
the solve from the guess on the same discrete problem, or with the exact optimum.
"""
from __future__ import annotations

import importlib

import numpy as np
import pytest

from symvi.models import get


def solve(mod, N: int, **keywords):
    """The bundled example at N steps over its own horizon."""
    ex = get(mod.model.name).example
    start, end = keywords.pop("start", ex.start), keywords.pop("end", ex.end)
    return mod.solve_bvp(start, end, N, ex.h * ex.n_steps / N, **keywords)


def test_bounded_long_horizon_iterations_do_not_grow(compiled):
    """The swing-up from its default guess without sequencing: at N = 4000 (on the node
    system: STALLED after 307 iterations) SUCCESS at the lower minimum, in at most 1.5
    times the iterations at N = 100 (58 and 52 measured)."""
    mod = compiled("cart_pole_swing_up")
    small, large = solve(mod, 100, coarse=0), solve(mod, 4000, coarse=0)
    assert small.success and large.success, large.message
    assert "mesh sequencing" not in large.message
    assert large.iterations <= 1.5 * small.iterations, (small.iterations, large.iterations)
    assert large.cost < 21.0                # the lower minimum: 20.39 (the upper one 32)
    assert (large.bound_multipliers >= 0).all()


@pytest.mark.parametrize("name", ["cart_pole_swing_up", "cart_pole_catch"])
def test_sequenced_solve_is_the_solve_from_the_guess(compiled, name):
    """At N = 2000 the sequenced solve (nodes at rest at both ends; the catch's end
    conditions, its last nodes unknowns started from the coarse solution's) ends at the
    optimum the solve from the guess reaches, in fewer iterations, counting the coarse
    ones: the swing-up 45 against 69, the catch 33 against 121."""
    mod = compiled(name)
    sequenced, direct = solve(mod, 2000), solve(mod, 2000, coarse=0)
    assert sequenced.success and direct.success
    assert sequenced.message.startswith("mesh sequencing: from the solution at 250 steps")
    assert np.abs(sequenced.x - direct.x).max() <= 1e-7 * (1 + np.abs(direct.x).max())
    assert sequenced.iterations < direct.iterations


def test_sequenced_minimum_time_from_states_is_exact(compiled):
    """States as boundary data (nodes at the half steps) and the horizon an unknown: the
    pure minimum-time double integrator at even N has T* = 2 exactly; sequenced from
    N = 250 at N = 2000, T is 2 to the tolerance and the controls bang–bang."""
    mod = compiled("minimum_time_double_integrator")
    result = solve(mod, 2000)
    assert result.success and "mesh sequencing" in result.message, result.message
    assert abs(result.T - 2.0) <= 1e-9 * 3.0
    u = result.controls[:, 0]
    assert (np.abs(np.abs(u) - 1.0) > 1e-6).sum() <= 1


def test_moving_pair_ends_are_scaled_to_the_coarse_step(compiled):
    """Nodes with a velocity at the start, on a pair groupoid: the coarse problem keeps
    that velocity (its nodes' differences grown by h_c/h) and the sequenced solve is the
    solve from the guess, its fixed nodes the user's."""
    mod = compiled("cart_pole_oc")
    start = np.array([[0.0, 0.3], [0.002, 0.301]])
    sequenced, direct = solve(mod, 2000, start=start), solve(mod, 2000, start=start, coarse=0)
    assert sequenced.success and "mesh sequencing" in sequenced.message
    assert np.array_equal(sequenced.x[:2], start)
    assert np.abs(sequenced.x - direct.x).max() <= 1e-9 * (1 + np.abs(direct.x).max())


def test_which_solves_are_sequenced(compiled):
    """Not a guess of the user's, not below 8·coarse steps, not with coarse=0, not moving
    ends given as nodes on a group (they do not carry to another step)."""
    mod = compiled("rigid_body_oc")
    ex = get("rigid_body_oc").example
    assert "mesh sequencing" in solve(mod, 2000).message
    assert "mesh sequencing" not in solve(mod, 1999).message
    assert "mesh sequencing" not in solve(mod, 2000, coarse=0).message
    guess = solve(mod, 2000, coarse=0).g[2:-2]
    assert "mesh sequencing" not in solve(mod, 2000, guess=guess).message
    turned = np.array([ex.start[0], ex.end[0]])         # R_0 = I, R_1 the end's turn
    moving = mod.solve_bvp(turned, ex.end, 2000, 1 / 2000)
    assert "mesh sequencing" not in moving.message


def test_a_failed_sequence_says_so_and_counts_every_iteration(compiled):
    """Where the coarse solve fails, the solve from the guess follows: the result is that
    solve's, never a SUCCESS it did not reach, its message names the failed coarse solve
    and its iterations count both."""
    mod = compiled("cart_pole_swing_up")
    result = solve(mod, 2000, maxiter=2)
    assert not result.success
    assert result.message.startswith("the solve at 250 steps failed (MAX_ITERATIONS); "
                                     "from the guess")
    direct = solve(mod, 2000, maxiter=2, coarse=0)
    assert result.iterations > direct.iterations


def test_a_fine_solve_at_its_rounding_limit_is_not_repeated(compiled):
    """xtol = 1e-13 is below rigid_body_oc's rounding at N = 2000 (its correction's
    rounding floor ≈ 1e-13), not at the coarse 250 steps: the fine solve ends
    ILL_CONDITIONED, a verdict on the discrete problem that the solve from the guess
    reaches too — the result is the sequence's, with no second solve (at N = 10⁶ the
    repeat cost 97 s against 18)."""
    mod = compiled("rigid_body_oc")
    result = solve(mod, 2000, xtol=1e-13)
    assert result.status.name == "ILL_CONDITIONED"
    assert result.message.startswith("mesh sequencing: from the solution at 250 steps")
    assert "from the guess" not in result.message
    direct = solve(mod, 2000, xtol=1e-13, coarse=0)
    assert direct.status == result.status
    assert np.abs(result.g - direct.g).max() <= 1e-10


def test_ends_stretched_past_a_bound_skip_sequencing(compiled):
    """A cart 0.4 mm inside its track (d = 0.8), moving out at 0.1 m/s: valid data at
    N = 2000, whose coarse ends (the velocity kept over h_c = 8h) would cross the track's
    end — the solve goes on from the guess instead of refusing the user's data (a hunt:
    a ValueError blaming the start)."""
    mod = compiled("cart_pole_swing_up")
    ex = get("cart_pole_swing_up").example
    N = 2000
    h = ex.h * ex.n_steps / N
    start = np.array([[0.7996, np.pi], [0.7996 + 0.1 * h, np.pi]])
    result = mod.solve_bvp(start, np.array([[0.5, np.pi]] * 2), N, h, maxiter=2)
    assert "mesh sequencing" not in result.message and "250 steps" not in result.message


def test_the_coarse_solve_is_counted_in_every_record(compiled):
    """The coarse solve's residual and step norms and history lead the sequenced
    result's (a hunt: they held the fine solve's alone, empty for the slew's warm
    start), and coarse below 10 steps is refused by name."""
    mod = compiled("spacecraft_slew")
    sequenced, coarse = solve(mod, 2000), solve(mod, 250, coarse=0)
    count = len(coarse.residual_norms)
    assert count and np.array_equal(sequenced.residual_norms[:count], coarse.residual_norms)
    assert np.array_equal(sequenced.step_norms[:len(coarse.step_norms)], coarse.step_norms)
    rows = len(coarse.history["objective"])
    assert np.array_equal(sequenced.history["objective"][:rows], coarse.history["objective"])
    with pytest.raises(ValueError, match=r"^coarse must be at least 10 \(or 0: no mesh "):
        solve(mod, 2000, coarse=3)


def test_the_active_set_newtons_linear_algebra(compiled):
    """Two failures at N = 10⁵ (pure minimum time, sequenced): SuperLU given a matrix with
    an empty row ended the process with a segmentation fault — now refused as singular —
    and the horizon's dense row and column filled its factors past 24 GB — now a
    Schur complement of K₀'s factors, which solves the bordered system exactly."""
    from scipy.sparse import csc_matrix

    mod = compiled("minimum_time_double_integrator")
    polish = importlib.import_module(f"{mod.__name__}._runtime.bounded.polish")
    rng = np.random.default_rng(3)
    A = rng.standard_normal((6, 6)) + 6 * np.eye(6)
    assert polish.sparse_lu(csc_matrix(A)) is not None
    A[2] = 0.0                                      # structurally singular
    assert polish.sparse_lu(csc_matrix(A)) is None
    K0 = rng.standard_normal((7, 7)) + 7 * np.eye(7)
    u, d, at = rng.standard_normal(7), 2.0, 4
    full = np.insert(np.insert(K0, at, u, axis=1), at, np.insert(u, at, d), axis=0)
    rhs = rng.standard_normal(8)
    lu = polish.sparse_lu(csc_matrix(K0))
    x = polish._bordered(lu.solve, u, d, at)(rhs)
    assert np.allclose(full @ x, rhs, rtol=0, atol=1e-12)
