"""Cubic exactness of the second-order pair-groupoid integrator (DESIGN.md §5).

For L = ½|q̈|² with the three-point rule, L_d = |q₂ − 2q₁ + q₀|²/(2h³) and the discrete
Euler–Lagrange equation is the fourth difference q_{k+2} − 4q_{k+1} + 6q_k − 4q_{k−1} +
q_{k−2} = 0 (times 1/h³). Samples of any cubic satisfy it exactly, so both runtimes (the
step map and the whole-trajectory solve) must return the cubic's samples up to round-off.

Round-off is not negligible here and the tolerances below say why:

* step map: the characteristic polynomial of the recurrence is (z − 1)⁴, so a perturbation
  made at one step grows like C(m+3, 3) ≈ m³/6 after m further steps. With generic real
  data a relative error O(ε·k³) after k steps is the best float64 can do (the plain
  recurrence q_{k+2} = 4q_{k+1} − … does 10–100× worse than the Newton step map). The
  1e-10-over-1000-steps requirement is therefore checked on a cubic whose samples and
  every intermediate value are exactly representable (integer coefficients, h = 2⁻⁶), where
  the computation is exact; generic real cubics are checked against the O(ε·k³) envelope.
* whole-trajectory solve: the Jacobian is h⁻³ times the clamped fourth-difference matrix,
  whose condition number κ grows like N⁴ (κ ≈ 3·10¹⁰ at N = 1000). A backward-stable banded
  solve gives relative errors ≤ κ·ε, so the tolerance is max(1e-10, κ·ε).
"""
from __future__ import annotations

import functools

import numpy as np
import pytest

EPS = np.finfo(float).eps


def cubic(coefficients: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Samples (len(t), 2) of c₀ + c₁t + c₂t² + c₃t³ (coefficients shape (4, 2))."""
    c = np.asarray(coefficients, dtype=float)
    tt = t[:, None]
    return c[0] + c[1] * tt + c[2] * tt**2 + c[3] * tt**3


def relative_error(q: np.ndarray, exact: np.ndarray) -> float:
    return float(np.abs(q - exact).max() / np.abs(exact).max())


@functools.lru_cache(maxsize=None)
def fourth_difference_condition(N: int) -> float:
    """κ₂ of the clamped fourth-difference matrix (the BVP Jacobian up to the factor h⁻³)."""
    n = N + 1 - 4
    A = np.zeros((n, n))
    for i in range(n):
        for j, s in enumerate((1.0, -4.0, 6.0, -4.0, 1.0)):
            col = i - 2 + j
            if 0 <= col < n:
                A[i, col] = s
    return float(np.linalg.cond(A))


def bvp_tolerance(N: int) -> float:
    return max(1e-10, fourth_difference_condition(N) * EPS)


# -- step map -------------------------------------------------------------------------------
def test_step_map_reproduces_exactly_representable_cubic(compiled):
    """Integer coefficients and h = 2⁻⁶: every value is a dyadic rational well inside the
    53-bit mantissa, so the step map must reproduce the cubic (to 1e-10 relative; in
    practice exactly) over 1000 steps, in both coordinates."""
    mod = compiled("cubic_spline")
    rng = np.random.default_rng(20240601)
    c = rng.integers(-8, 9, size=(4, 2)).astype(float)
    c[3] = np.where(c[3] == 0, 3.0, c[3])  # a genuine cubic in both coordinates
    h, steps = 2.0**-6, 1000
    exact = cubic(c, h * np.arange(steps + 1))
    result = mod.integrate(exact[:4], steps, h)
    assert result.success, result.message
    assert result.q.shape == exact.shape
    err = relative_error(result.q, exact)
    print(f"\ncubic step map, exactly representable data: max relative error {err:.3e}")
    assert err <= 1e-10


@pytest.mark.parametrize("h", [0.1, 0.01, 0.001])
def test_step_map_reproduces_real_cubic_within_roundoff_envelope(compiled, h):
    """Generic real cubic (both coordinates): relative error ≤ 1e-10 over the first 100
    steps and within the O(ε·k³) round-off envelope of the (z−1)⁴ recurrence over 1000."""
    mod = compiled("cubic_spline")
    rng = np.random.default_rng(7)
    c = rng.uniform(-1.0, 1.0, size=(4, 2))
    steps = 1000
    exact = cubic(c, h * np.arange(steps + 1))
    result = mod.integrate(exact[:4], steps, h)
    assert result.success, result.message
    scale = np.abs(exact).max()
    err_k = np.abs(result.q - exact).max(axis=1) / scale
    k = np.arange(err_k.size)
    envelope = 10.0 * EPS * np.maximum(k, 1) ** 3 / 6.0
    print(f"\ncubic step map, h = {h}: relative error {err_k[:101].max():.3e} after 100 steps, "
          f"{err_k.max():.3e} after {steps} (envelope ε·k³/6 at k = 1000: "
          f"{EPS * 1000**3 / 6:.1e}); worst err/(ε k³/6) = "
          f"{(err_k / (EPS * np.maximum(k, 1) ** 3 / 6)).max():.2f}")
    assert err_k[:101].max() <= 1e-10
    assert np.all(err_k <= envelope + 1e-13)


def test_step_map_is_not_exact_for_non_cubic(compiled):
    """Control: the exactness above is a property of cubics — a quartic's samples are not
    a discrete solution (its fourth difference is 24 c₄ h⁴ ≠ 0), so the path departs."""
    mod = compiled("cubic_spline")
    h, steps = 2.0**-6, 200
    t = h * np.arange(steps + 1)
    exact = np.stack([t**4, 1.0 - t**4], axis=1)
    result = mod.integrate(exact[:4], steps, h)
    assert result.success, result.message
    assert relative_error(result.q, exact) > 1e-3


# -- whole-trajectory solve -----------------------------------------------------------------
@pytest.mark.parametrize("N", [10, 100, 1000])
def test_bvp_with_cubic_boundary_data_returns_cubic(compiled, N):
    """Fix q₀, q₁, q_{N−1}, q_N from a random cubic; the default (linear) guess must converge
    to the cubic's samples."""
    mod = compiled("cubic_spline")
    rng = np.random.default_rng(1000 + N)
    c = rng.uniform(-1.0, 1.0, size=(4, 2))
    h = 1.0 / N
    exact = cubic(c, h * np.arange(N + 1))
    result = mod.solve_bvp(exact[:2], exact[-2:], N, h)
    assert result.success, result.message   # well-posed linear problem: must report solved
    assert result.q.shape == exact.shape
    np.testing.assert_array_equal(result.q[:2], exact[:2])
    np.testing.assert_array_equal(result.q[-2:], exact[-2:])
    err, tol = relative_error(result.q, exact), bvp_tolerance(N)
    print(f"\ncubic BVP N = {N}: max relative error {err:.3e} (tolerance {tol:.1e}, "
          f"κ·ε = {fourth_difference_condition(N) * EPS:.1e}); {result.status.name}: "
          f"{result.message}")
    assert err <= tol
    # The linear guess is far from the cubic, so this really exercised Newton.
    assert result.iterations >= 1


@pytest.mark.parametrize("N", [10, 100, 1000])
@pytest.mark.parametrize("kind", ["noise", "reflected", "zeros"])
def test_bvp_with_bad_guess_returns_cubic(compiled, N, kind):
    mod = compiled("cubic_spline")
    rng = np.random.default_rng(2000 + N)
    c = rng.uniform(-1.0, 1.0, size=(4, 2))
    h = 1.0 / N
    exact = cubic(c, h * np.arange(N + 1))
    scale = np.abs(exact).max()
    guess = {"noise": rng.normal(scale=10 * scale, size=(N - 3, 2)),
             "reflected": 5.0 - exact[2:-2],
             "zeros": np.zeros((N - 3, 2))}[kind]
    assert relative_error(np.concatenate([exact[:2], guess, exact[-2:]]), exact) > 0.5
    result = mod.solve_bvp(exact[:2], exact[-2:], N, h, guess=guess)
    err, tol = relative_error(result.q, exact), bvp_tolerance(N)
    print(f"\ncubic BVP N = {N}, {kind} guess: max relative error {err:.3e} (tolerance {tol:.1e})")
    assert err <= tol


# -- cross-check of the two runtimes on a nonlinear model ----------------------------------
@pytest.mark.parametrize("N", [50, 100])
def test_spline_potential_bvp_solution_satisfies_step_map(compiled, N):
    """Solve the nonlinear spline_potential BVP (non-default parameters), then check the
    solution two independent ways: (1) every interior residual, evaluated by the compiled
    ``stencil`` kernel, is at round-off level; (2) the step map started from the solution's
    first 4 nodes reproduces the whole solution."""
    mod = compiled("spline_potential")
    params = {"alpha": 2.0, "beta": 1.5}
    h = 1.0 / N
    start = np.array([[1.0, 0.0], [1.0, h]])            # at rest-ish at (1, 0), moving up
    end = np.array([[0.0, 1.0], [-h, 1.0]])             # arrive at (0, 1), moving left
    result = mod.solve_bvp(start, end, N, h, params=params)
    q = result.q
    assert q.shape == (N + 1, 2) and np.all(np.isfinite(q))
    np.testing.assert_array_equal(q[:2], start)
    np.testing.assert_array_equal(q[-2:], end)
    # The solution is genuinely nonlinear: far from the straight line between the ends.
    assert result.residual_norms[0] > 1e3 * result.residual_norms[-1]

    # (1) residuals from the compiled stencil kernel, relative to the size of their terms.
    worst = 0.0
    for j in range(2, N - 1):
        z = q[j - 2:j + 3].reshape(-1)
        residual, jacobian = mod.evaluate("stencil", z, h, params)
        scale = np.abs(jacobian).sum(axis=1).max() * np.abs(z).max()
        worst = max(worst, np.abs(residual).max() / scale)
    # (2) the step map from q_0..q_3.
    stepped = mod.integrate(q[:4], N, h, params=params)
    assert stepped.success, stepped.message
    gap = relative_error(stepped.q, q)
    print(f"\nspline_potential BVP N = {N}: {result.status.name} ({result.message}); "
          f"max relative residual {worst:.2e}; step map vs BVP max relative gap {gap:.2e}")
    assert worst <= 1e3 * EPS
    assert gap <= 1e-8


def test_spline_potential_bvp_recovers_step_map_trajectory(compiled):
    """Converse direction: a trajectory of the step map (the model's example) is recovered
    by the whole-trajectory solve from its four boundary nodes and the default guess."""
    from symvi.models import get

    mod = compiled("spline_potential")
    ex = get("spline_potential").example
    path = mod.integrate(ex.initial, ex.n_steps, ex.h)
    assert path.success, path.message
    q = path.q
    N = q.shape[0] - 1
    result = mod.solve_bvp(q[:2], q[-2:], N, ex.h)
    gap = relative_error(result.q, q)
    print(f"\nspline_potential: BVP from the example's boundary nodes, N = {N}: relative gap "
          f"{gap:.2e}; {result.message}")
    assert gap <= 1e-8
