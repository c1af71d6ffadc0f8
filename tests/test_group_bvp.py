"""Whole-trajectory solve on matrix Lie groups (DESIGN.md §4).

With the first and last r configurations fixed (r the order), ``solve_bvp`` solves the
discrete Euler–Poincaré equations at the free nodes g_r … g_{N−r} by Newton on
multiplicative corrections g_j ← g_j τ(η_j). Everything below is checked independently of
the solver, with NumPy/SciPy Lie-group helpers (hat map, Cayley map, its inverse, expm and
SciPy's rotation vector as the inverse of exp):

1. Riemannian cubics on SO(3) (L̃ = ½|ξ̇|², Cayley and exp) with generic boundary data and
   a large end rotation: converged; every free node's residual, evaluated on its own
   through the compiled ``stencil`` kernel, at the rounding level; the increments
   reconstruct every configuration and the product g₀ τ(hξ₀)⋯τ(hξ_{N−1}) reproduces g_N;
   the fixed configurations are returned bit for bit.
2. Exact discrete solutions: ξ ≡ X makes ξ̇ ≡ 0, so the one-parameter subgroup
   g_k = τ(hX)^k is a solution; from its four boundary configurations the solve must
   return ξ_k = X from the default and from a perturbed guess.
3. First-order rigid body: the BVP solution, stepped forward from its own first increment
   with the step map, is reproduced entirely (the two runtimes agree).
4. Robustness: convergence to the known solution from noisy guesses (line search), and a
   number of Newton iterations independent of N (100, 1000, 10000).
5. Errors: half-turns (outside the Cayley chart; the default guess needs τ⁻¹ of the
   relative rotation between the fixed ends), shapes of start/end/guess, ``increments``.

Round-off scales used in the tolerances: increments recovered from configurations carry
an error ≈ ε/h (τ⁻¹ of a matrix known to ε, divided by h), and a product of N rotations
≈ N ε.
"""
from __future__ import annotations

import time

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

import symvi
from symvi.build import compile_model
from so3 import I3, cay, cay_inv, hat, vee

EPS = np.finfo(float).eps
RETRACTIONS = ("cayley", "exp")


# ---------------------------------------------------------------------------------------
# NumPy helpers, independent of the generated code
# ---------------------------------------------------------------------------------------
def tau(retraction: str, v) -> np.ndarray:
    """τ(Σ v_a E_a)."""
    return cay(hat(v)) if retraction == "cayley" else expm(hat(v))


def tau_inv(retraction: str, W) -> np.ndarray:
    """Coordinates of τ⁻¹(W) (Cayley inverse, resp. the rotation vector of W)."""
    return vee(cay_inv(W)) if retraction == "cayley" else Rotation.from_matrix(W).as_rotvec()


def relative(g) -> np.ndarray:
    """g_k⁻¹ g_{k+1} of a path of rotations (K, 3, 3)."""
    return np.einsum("kji,kjl->kil", g[:-1], g[1:])


def reconstruct(retraction: str, g0, xi, h) -> np.ndarray:
    """g_0, g_0 τ(hξ_0), g_0 τ(hξ_0) τ(hξ_1), … (the product, one factor at a time)."""
    out = [np.asarray(g0, dtype=float)]
    for x in xi:
        out.append(out[-1] @ tau(retraction, h * x))
    return np.array(out)


def interpolation(retraction: str, ga, gb, count: int) -> np.ndarray:
    """ga τ(s·τ⁻¹(ga⁻¹ gb)) at count interior points s of [0, 1] (the default guess)."""
    v = tau_inv(retraction, ga.T @ gb)
    s = np.linspace(0.0, 1.0, count + 2)[1:-1]
    return np.array([ga @ tau(retraction, si * v) for si in s])


def perturb(g, eta) -> np.ndarray:
    """g_j expm(η̂_j) node by node."""
    return np.array([gj @ expm(hat(e)) for gj, e in zip(g, eta)])


def xi_tolerance(h: float) -> float:
    """Attainable agreement of the increments with the configurations: ≈ ε/h from τ⁻¹ of
    configurations known to ε (the solve composes ξ exactly; the configurations carry the
    rounding of a few matrix products per iteration)."""
    return 50 * EPS / h


def stencil_residuals(mod, xi, h) -> np.ndarray:
    """Residuals at the free nodes j = r … N−r, each from its own 2r increments."""
    r, N = mod.model.order, xi.shape[0]
    return np.array([mod.evaluate("stencil", xi[j - r:j + r].ravel(), h)[0]
                     for j in range(r, N - r + 1)])


# ---------------------------------------------------------------------------------------
# models
# ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cubic(compiled, build_dir):
    """cubic(retraction) -> the Riemannian-cubic module on SO(3) with that retraction."""
    G = symvi.SO3(retraction="exp")
    exp_model = symvi.Model("so3_cubic_exp", G, lagrangian=sum(v**2 for v in G.xidot) / 2)
    modules = {"cayley": compiled("so3_cubic"), "exp": compile_model(exp_model, build_dir)}
    for mod in modules.values():
        assert mod.model.order == 2 and mod.model.n == 3 and mod.model.matrix_dims == (3,)
    return modules.__getitem__


@pytest.fixture(scope="module")
def rigid_body(compiled):
    return {"cayley": compiled("rigid_body"), "exp": compiled("rigid_body_exp")}.__getitem__


def cubic_boundary(retraction: str, N: int, end_rotation):
    """g_0 = I, g_1 = τ(hξ_a); g_N = exp(end_rotation), g_{N−1} = g_N τ(−hξ_b), T = 1."""
    h = 1.0 / N
    g_N = expm(hat(end_rotation))
    start = np.stack([I3, tau(retraction, h * np.array([0.3, -0.2, 0.5]))])
    end = np.stack([g_N @ tau(retraction, -h * np.array([0.4, 0.6, -0.1])), g_N])
    return start, end, h


def subgroup(retraction: str, X, N: int, h: float) -> np.ndarray:
    """g_k = τ(hX)^k, k = 0 … N: Cayley powers, resp. exp(k h X̂) directly."""
    if retraction == "exp":
        return np.array([expm(k * h * hat(X)) for k in range(N + 1)])
    return reconstruct("cayley", I3, np.tile(X, (N, 1)), h)


#: A generic rotation of 2.55 rad (146°) for the end configuration of test 1.
LARGE_ROTATION = [1.5, -1.8, 1.0]
#: 1.41 rad, for the N-scaling runs.
MODERATE_ROTATION = [0.8, -1.0, 0.6]
#: Constant body velocity of the exact solutions (|X| = 1.29 rad over T = 1).
X_SUBGROUP = np.array([0.6, -0.9, 0.7])


# ---------------------------------------------------------------------------------------
# 1. Riemannian cubics: acceptance
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("retraction", RETRACTIONS)
def test_riemannian_cubic_bvp(cubic, retraction):
    """Generic boundary data, g_N a rotation of 2.55 rad: the default guess needs τ⁻¹ of
    g_1⁻¹ g_99 (≈ 2.55 rad), inside both charts (exp: θ < π)."""
    mod, N = cubic(retraction), 100
    start, end, h = cubic_boundary(retraction, N, LARGE_ROTATION)
    assert np.linalg.norm(tau_inv("exp", start[1].T @ end[0])) > 2.5  # a large rotation
    result = mod.solve_bvp(start, end, N, h)
    assert result.success, result.message
    assert result.status == 0
    g, xi = result.g, result.f
    assert g.shape == (N + 1, 3, 3) and xi.shape == (N, 3) and result.q is None
    np.testing.assert_allclose(result.t, h * np.arange(N + 1), rtol=0, atol=1e-15)
    # the fixed configurations come back bit for bit
    np.testing.assert_array_equal(g[:2], start)
    np.testing.assert_array_equal(g[-2:], end)

    # (a) every free node's residual, evaluated on its own by the compiled stencil kernel
    res = stencil_residuals(mod, xi, h)
    worst = float(np.abs(res).max())
    # the solver's reported residual is the same quantity
    assert worst == pytest.approx(result.residual_norms[-1], rel=1e-12)
    # (b) reconstruction: one step at a time and as the whole product
    steps = max(float(np.abs(g[k] @ tau(retraction, h * xi[k]) - g[k + 1]).max())
                for k in range(N))
    product = float(np.abs(reconstruct(retraction, g[0], xi, h)[-1] - end[-1]).max())
    orthogonality = float(np.abs(np.einsum("kji,kjl->kil", g, g) - I3).max())
    # (c) the increments are τ⁻¹ of the relative configurations: NumPy's logarithm, and
    # the model's own ``increments`` (the C logarithm the solver uses)
    logs = np.array([tau_inv(retraction, W) for W in relative(g)]) / h
    log_gap = float(np.abs(logs - xi).max())
    own_gap = float(np.abs(mod.model.increments(g, h) - xi).max())
    print(f"\nso3_cubic ({retraction}), N = {N}: {result.message}; residual norms "
          f"{np.array2string(result.residual_norms, precision=2)}; max stencil residual "
          f"{worst:.2e}; per-step reconstruction {steps:.1e}; product vs g_N {product:.1e}; "
          f"orthogonality {orthogonality:.1e}; ξ vs τ⁻¹(g_k⁻¹g_k+1)/h: NumPy {log_gap:.1e}, "
          f"model.increments {own_gap:.1e}")
    # a genuinely nonlinear solve: the default guess is far from solving the equations
    assert result.residual_norms[0] > 1e3
    assert worst <= 1e-10
    assert steps <= 1e-13
    assert product <= 1e-13
    assert orthogonality <= 1e-13
    # The logarithm of a matrix known to ε is exact to ≈ ε/h (NumPy's 2(W − I)(W + I)⁻¹
    # suffers the cancellation in W − I: up to ~10 ε/h observed).
    assert own_gap <= xi_tolerance(h)
    assert log_gap <= 100 * EPS / h


# ---------------------------------------------------------------------------------------
# 2. Exact discrete solutions: one-parameter subgroups
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("guess_kind", ["default", "perturbed"])
@pytest.mark.parametrize("retraction", RETRACTIONS)
def test_one_parameter_subgroup_is_recovered(cubic, retraction, guess_kind):
    """ξ_k ≡ X is an exact discrete solution (ξ̇ ≡ 0); the solve must return it to the
    attainable accuracy of increments (``xi_tolerance``: 1.4e-12 at h = 0.01)."""
    mod, N = cubic(retraction), 100
    h = 1.0 / N
    exact = subgroup(retraction, X_SUBGROUP, N, h)
    guess = None
    if guess_kind == "perturbed":
        # smooth (0.5 rad) plus node-to-node (0.01 rad) rotations of the exact solution
        rng = np.random.default_rng(11)
        s = h * np.arange(2, N - 1)[:, None]
        eta = (0.5 * np.sin(np.pi * s) * np.array([0.6, 0.0, -0.8])
               + 0.5 * np.sin(2 * np.pi * s) * np.array([0.0, 1.0, 0.0])
               + rng.normal(scale=0.01, size=(N - 3, 3)))
        guess = perturb(exact[2:-2], eta)
    result = mod.solve_bvp(exact[:2], exact[-2:], N, h, guess=guess)
    assert result.success, result.message
    xi_err = float(np.abs(result.f - X_SUBGROUP).max())
    g_err = float(np.abs(result.g - exact).max())
    print(f"\nsubgroup ({retraction}, {guess_kind} guess): {result.message}; "
          f"max |ξ_k − X| {xi_err:.1e}; max |g_k − τ(hX)^k| {g_err:.1e}")
    if guess_kind == "perturbed":
        assert result.residual_norms[0] > 1e4   # the guess was far from a solution
    assert xi_err <= xi_tolerance(h)
    assert g_err <= 1e-13


# ---------------------------------------------------------------------------------------
# 3. First-order rigid body: BVP and step map agree
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("N", [100, 1000])
@pytest.mark.parametrize("retraction", RETRACTIONS)
def test_rigid_body_bvp_agrees_with_step_map(rigid_body, retraction, N):
    mod = rigid_body(retraction)
    h = 1.0 / N
    g_N = expm(hat([0.9, -1.2, 0.6]))            # 1.61 rad in T = 1
    result = mod.solve_bvp(I3[None], g_N[None], N, h)
    assert result.success, result.message
    np.testing.assert_array_equal(result.g[0], I3)
    np.testing.assert_array_equal(result.g[-1], g_N)
    residual = float(np.abs(stencil_residuals(mod, result.f, h)).max())
    stepped = mod.integrate((result.g[0], result.f[:1]), N, h)
    assert stepped.success, stepped.message
    assert stepped.g.shape == result.g.shape
    g_gap = float(np.abs(stepped.g - result.g).max())
    xi_gap = float(np.abs(stepped.f - result.f).max())
    print(f"\nrigid body ({retraction}), N = {N}: {result.message}; max stencil residual "
          f"{residual:.1e}; step map vs BVP: configurations {g_gap:.1e}, increments "
          f"{xi_gap:.1e}")
    assert residual <= 1e-12
    assert g_gap <= 1e-10
    assert xi_gap <= 1e-9


# ---------------------------------------------------------------------------------------
# 4. Robustness
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("retraction", RETRACTIONS)
def test_convergence_from_noisy_guess(cubic, retraction):
    """The default interpolation with independent random rotations of 0.01 rad per node:
    for h = 0.01 that is node-to-node jitter of the size of a whole step hξ, and a residual
    of order 1e5 (against ≈ 1e-12 at the solution). Newton with the line search must reach
    the exact solution ξ ≡ X, for several draws."""
    mod, N = cubic(retraction), 100
    h = 1.0 / N
    exact = subgroup(retraction, X_SUBGROUP, N, h)
    base = interpolation(retraction, exact[1], exact[-2], N - 3)
    report = []
    for seed in range(5):
        rng = np.random.default_rng(seed)
        guess = perturb(base, rng.normal(scale=0.01, size=(N - 3, 3)))
        result = mod.solve_bvp(exact[:2], exact[-2:], N, h, guess=guess)
        assert result.success, f"seed {seed}: {result.message}"
        err = float(np.abs(result.f - X_SUBGROUP).max())
        report.append(f"seed {seed}: {result.iterations} iterations, residual "
                      f"{result.residual_norms[0]:.1e} -> {result.residual_norms[-1]:.1e}, "
                      f"|ξ − X| {err:.1e}")
        assert result.residual_norms[0] > 1e4
        assert err <= xi_tolerance(h)
    print(f"\nnoisy guesses ({retraction}):\n  " + "\n  ".join(report))


@pytest.mark.parametrize("retraction", RETRACTIONS)
def test_newton_iterations_do_not_grow_with_N(cubic, retraction):
    """Same continuous boundary data (g_0, ξ_a at t = 0; g_N, ξ_b at t = 1) for
    N = 100, 1000, 10000. The iteration count is set by the nonlinearity, not by N (the
    updates compose ξ exactly, so no rounding floor of ε/h in ξ slows the last
    iterations)."""
    mod = cubic(retraction)
    iterations, lines = [], []
    for N in (100, 1000, 10000):
        start, end, h = cubic_boundary(retraction, N, MODERATE_ROTATION)
        t0 = time.perf_counter()
        result = mod.solve_bvp(start, end, N, h)
        elapsed = time.perf_counter() - t0
        assert result.success, f"N = {N}: {result.message}"
        product = float(np.abs(reconstruct(retraction, start[0], result.f, h)[-1]
                               - end[-1]).max())
        iterations.append(result.iterations)
        lines.append(f"N = {N:5d}: {result.iterations} iterations, {elapsed:.2f} s, residual "
                     f"{result.residual_norms[0]:.1e} -> {result.residual_norms[-1]:.1e}, "
                     f"product vs g_N {product:.1e}")
        assert product <= 10 * N * EPS
    print(f"\niterations vs N ({retraction}):\n  " + "\n  ".join(lines))
    assert max(iterations) <= 8
    assert max(iterations) - min(iterations) <= 3


@pytest.mark.parametrize("retraction", RETRACTIONS)
def test_refinement_converges(cubic, retraction):
    """A reported success is a solution of the continuous problem's discretisation:
    refining the same boundary data 10× must shrink the change of the configurations at
    shared times ≈ 10× (first order in h, because g_1 = τ(hξ_a) fixes ξ at t = h/2, an O(h)
    perturbation of the initial velocity). Ratio ≤ 0.2 asks for order ≥ 0.7.

    Not beyond N = 10000: the Jacobian's condition number grows like N⁴ (as for the pair
    cubic), and at N = 100000 the float64 residual no longer determines the configurations
    (Newton steps of 0.05–0.5 rad from residual rounding alone)."""
    mod = cubic(retraction)
    g = {}
    for N in (100, 1000, 10000):
        start, end, h = cubic_boundary(retraction, N, MODERATE_ROTATION)
        result = mod.solve_bvp(start, end, N, h)
        assert result.success, f"N = {N}: {result.message}"
        g[N] = result.g
    coarse = float(np.abs(g[100] - g[1000][::10]).max())
    fine = float(np.abs(g[1000] - g[10000][::10]).max())
    print(f"\nrefinement ({retraction}): max |g^N − g^10N| at shared times: N = 100: "
          f"{coarse:.2e}, N = 1000: {fine:.2e} (ratio {fine / coarse:.3f})")
    assert fine <= 0.2 * coarse


# ---------------------------------------------------------------------------------------
# 5. Charts and errors
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("angle", [0.5, 1.9, 2.1, 2.6, 3.1])
@pytest.mark.parametrize("retraction", RETRACTIONS)
def test_increments_of_rotations_inside_the_chart(rigid_body, retraction, angle):
    """Every rotation but a half-turn is in the Cayley chart, every angle < π in the exp
    chart: ``increments`` must return τ⁻¹ for all of them (h = 1: ξ = τ⁻¹(W))."""
    mod = rigid_body(retraction)
    u = np.array([1.0, 2.0, -2.0]) / 3.0
    W = expm(hat(angle * u))
    expected = 2 * np.tan(angle / 2) * u if retraction == "cayley" else angle * u
    xi = mod.model.increments(np.stack([I3, W]), 1.0)
    np.testing.assert_allclose(xi[0], expected, rtol=1e-12, atol=1e-12)


HALF_TURN = np.diag([1.0, -1.0, -1.0])      # rotation by π about e1


@pytest.mark.parametrize("retraction", RETRACTIONS)
def test_half_turn_between_fixed_ends(cubic, rigid_body, retraction):
    """The default guess needs τ⁻¹(g_{r−1}⁻¹ g_{N−r+1}); for a half-turn it does not exist
    (Cayley: I + W singular; exp: θ = π), and the solve says so instead of guessing."""
    N, h = 100, 0.01
    mod = cubic(retraction)
    g1 = tau(retraction, h * np.array([0.3, -0.2, 0.5]))
    start = np.stack([I3, g1])
    g_99 = g1 @ HALF_TURN                      # g_1⁻¹ g_99 is a half-turn
    end = np.stack([g_99, g_99 @ tau(retraction, h * np.array([0.4, 0.6, -0.1]))])
    result = mod.solve_bvp(start, end, N, h)
    assert result.status == 5 and result.status.name == "OUTSIDE_CHART"
    assert not result.success
    assert "chart" in result.message and "half-turn" in result.message
    assert "g_1⁻¹ g_99" in result.message and "guess" in result.message
    with pytest.raises(mod.NewtonError, match="outside the retraction's chart") as info:
        mod.solve_bvp(start, end, N, h, raise_on_failure=True)
    assert info.value.result.status == 5
    # the same problem is solvable from a guess that does not need that logarithm
    guess = interpolation("exp", start[1], end[0], N - 3)
    solved = mod.solve_bvp(start, end, N, h, guess=guess)
    assert solved.success, solved.message
    assert float(np.abs(stencil_residuals(mod, solved.f, h)).max()) <= 1e-10
    # first order: the chord is g_0⁻¹ g_N
    first = rigid_body(retraction).solve_bvp(I3[None], HALF_TURN[None], N, h)
    assert first.status == 5 and "g_0⁻¹ g_100" in first.message


@pytest.mark.parametrize("retraction", RETRACTIONS)
def test_increments_of_half_turn_raise(rigid_body, retraction):
    mod = rigid_body(retraction)
    g1 = expm(hat([0.1, 0.2, 0.3]))
    path = np.stack([I3, g1, g1 @ HALF_TURN, g1 @ HALF_TURN])
    with pytest.raises(ValueError, match=r"w_1 = g_1⁻¹ g_2 .*outside the retraction's chart"):
        mod.model.increments(path, 0.1)
    # the elements before it are fine
    np.testing.assert_allclose(mod.model.increments(path[:2], 0.1)[0],
                               tau_inv(retraction, g1) / 0.1, rtol=1e-12)


@pytest.mark.parametrize("call, pattern", [
    (lambda m: m.solve_bvp(np.stack([I3]), np.stack([I3, I3]), 10, 0.1),
     r"start configurations.*shape \(1, 3, 3\).*expected \(2, 3, 3\)"),
    (lambda m: m.solve_bvp(np.stack([I3, I3]), np.zeros((2, 3)), 10, 0.1),
     r"end configurations.*shape \(2, 3\).*expected \(2, 3, 3\)"),
    (lambda m: m.solve_bvp(np.stack([I3, I3]), np.stack([I3, I3]), 10, 0.1,
                           guess=np.tile(I3, (8, 1, 1))),
     r"guess of the free configurations.*shape \(8, 3, 3\).*expected \(7, 3, 3\)"),
    (lambda m: m.solve_bvp(np.stack([I3, np.full((3, 3), np.nan)]), np.stack([I3, I3]), 10, 0.1),
     r"start configurations.*non-finite"),
    (lambda m: m.solve_bvp(np.zeros((2, 4, 4)), np.stack([I3, I3]), 10, 0.1),
     r"start configurations.*shape \(2, 4, 4\)"),
    (lambda m: m.solve_bvp(np.stack([I3, I3]), np.stack([I3, I3]), 3, 0.1),
     r"n_steps must be at least 4 \(2 fixed nodes at each end.*free node.*\), got 3"),
    (lambda m: m.model.increments(I3, 0.1),
     r"configurations g must have shape \(K ≥ 2, 3, 3\), got \(3, 3\)"),
    (lambda m: m.model.increments(np.zeros((2, 2, 2)), 0.1),
     r"configurations g has shape \(2, 2, 2\), expected \(2, 3, 3\)"),
])
def test_bad_arguments(cubic, call, pattern):
    with pytest.raises(ValueError, match=pattern):
        call(cubic("cayley"))
