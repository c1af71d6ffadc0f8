"""The heavy top with rotors under variational controlled equations (symvi.declaration.control): the
vertical-momentum dependency of its constraints becomes exact, and the solver removes it.

With the forced discrete Euler–Lagrange equations of the first-order L_d, the discrete
Noether identity holds exactly: Σ_k Γ_k·Φ_d^k equals the difference of the ends' discrete
vertical momenta on every path between them (the paper's rule keeps it to O(h⁴) only,
tests/test_constraint_degeneracy.py). So J_Φ has an exact left null vector, Γ at each
window's middle node, and the next singular value falls at the generic order 2; the Newton
matrix is singular, and with the gauge of ``_runtime/bvp/gauge.py`` (window w's rows replaced
by (I − ΓΓᵀ)Φ_d^w + ΓΓᵀλ^w) it is regular with the generic fourth-difference conditioning
∝ N⁻⁴. Non-planar problems then converge from the chord guess at every N tried, where
the paper's rule fails from N = 96.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import null_space
from scipy.spatial.transform import Rotation

from symvi import Symmetry, compile_model, optimal_control
from symvi.checks import check
from symvi.models import get
from so3 import cay, hat
from test_bvp_merit import dense_jacobian, runtime_of
from test_constraint_degeneracy import constraint_jacobian, feasible_system, path_through
from test_optimal_control import top_path

NAME, PAPER = "heavy_top_rotors_oc_variational", "heavy_top_rotors_oc"
T = 2.0


def parameters(mod) -> dict:
    return dict(zip(mod.model.parameter_names, mod.model.parameter_defaults))


def vertical_sum(mod, x, g, h) -> tuple[float, float]:
    """(Σ_k Γ_k·Φ_d^k, Σ_k |Γ_k·Φ_d^k|) along the path (Γ at each window's middle node)."""
    path = path_through(mod, x, g, h)
    phi = mod.model.along("constraint", path.x, path.f, h)
    terms = np.einsum("wa,wa->w", path.x[1:-1, :3], phi)
    return float(terms.sum()), float(np.abs(terms).sum())


def random_interior(x, g, seed):
    """(x, g) with every free node (2 … N−2) replaced by a random attitude and rotor angles."""
    rng, x, g = np.random.default_rng(seed), x.copy(), g.copy()
    inner = slice(2, len(g) - 2)
    g[inner] = Rotation.random(len(g) - 4, random_state=seed).as_matrix()
    x[inner, :3] = np.einsum("kji,j->ki", g[inner], [0.0, 0.0, 1.0])
    x[inner, 3:] = rng.normal(size=(len(g) - 4, 2))
    return x, g


@pytest.mark.parametrize("name, exact", [(NAME, True), (PAPER, False)])
def test_vertical_momentum_identity(compiled, name, exact):
    """Σ_k Γ_k·Φ_d^k on three random paths between the same ends: equal to rounding with
    variational equations (spread 2e-7 against Σ|terms| = 5e8), different with the
    paper's rule (3e4 against 1e5)."""
    mod, N = compiled(name), 40
    x, g = top_path(name, parameters(mod), N, T / N)
    sums = [vertical_sum(mod, *random_interior(x, g, seed), T / N) for seed in (1, 2, 3)]
    spread = max(s for s, _ in sums) - min(s for s, _ in sums)
    size = max(a for _, a in sums)
    print(f"\n{name}: spread of Σ Γ·Φ_d {spread:.2e}, Σ|Γ·Φ_d| up to {size:.1e}")
    assert (spread < 1e-12 * size) if exact else (spread > 1e-3 * size)


@pytest.fixture(scope="module")
def spectra(compiled):
    """Per N: (singular values of J_Φ over the node unknowns, |cos| between its last left
    singular vector and the stacked Γ's, σ_min/σ_max of the Newton matrix without and with
    the gauge), at the feasible non-planar path."""
    mod, out = compiled(NAME), {}
    for N in (24, 48, 96):
        problem, path, res, ab, bw = feasible_system(mod, N)
        jac, gamma = constraint_jacobian(problem, path, ab, bw)
        left, sigma, _ = np.linalg.svd(jac)
        gauged = ab.copy()
        problem.gauge.apply(gauged, bw, -res)
        full, fixed = (np.linalg.svd(dense_jacobian(a, bw), compute_uv=False) for a in (ab, gauged))
        out[N] = (sigma, abs(left[:, -1] @ gamma) / np.linalg.norm(gamma),
                  full[-1] / full[0], fixed[-1] / fixed[0])
    return out


def test_constraint_jacobian_has_an_exact_left_null_vector(spectra):
    """σ_min(J_Φ)/σ_max is rounding (< 1e-14) with left singular vector Γ (1 − |cos| <
    1e-12); the next singular value falls at the generic order 2 (measured 1.9–2.0)."""
    ns = sorted(spectra)
    for n in ns:
        sigma, cos = spectra[n][:2]
        assert sigma[-1] / sigma[0] < 1e-14 and 1 - cos < 1e-12
    second = [spectra[n][0][-2] / spectra[n][0][0] for n in ns]
    np.testing.assert_allclose(np.log2(np.array(second[:-1]) / second[1:]), 2.0, atol=0.15)


def test_gauge_makes_the_newton_matrix_regular(spectra):
    """Singular to rounding without the gauge; with it σ_min/σ_max is 5.8e-10, 4.1e-11 and
    2.7e-12 at N = 24, 48, 96: order 4 in h, the conditioning of any fourth-difference
    system."""
    ns = sorted(spectra)
    assert all(spectra[n][2] < 1e-16 for n in ns)
    fixed = np.array([spectra[n][3] for n in ns])
    assert fixed.min() > 1e-13
    np.testing.assert_allclose(np.log2(fixed[:-1] / fixed[1:]), 4.0, atol=0.3)


@pytest.mark.parametrize("N", [96, 192, 400])
def test_non_planar_problem_converges_from_the_default_and_chord_guesses(compiled, N):
    """Boundary data: the ends of the feasible non-planar path. From the default guess,
    the cubic through the end positions and velocities, Newton converges in 7 iterations
    at each N; from the chord, which jumps from the end velocities, within the default
    maxiter (73, 52 and 60), to the same path. The paper's rule, on the ends of its own
    feasible path, does not at N = 96, even in 150."""
    mod, h = compiled(NAME), T / N
    x, g = top_path(NAME, parameters(mod), N, h)
    ends = (x[:2], g[:2]), (x[-2:], g[-2:])
    r, chord = mod.solve_bvp(*ends, N, h), mod.solve_bvp(*ends, N, h, guess="chord")
    print(f"\nN = {N}: {r.message}; from the chord {chord.message}; cost {r.cost:.10f}")
    for result in (r, chord):
        assert result.success and result.residual_norms[-1] < 1e-8
        assert np.abs(result.multipliers).max() < 1e3
    assert r.iterations <= 10
    np.testing.assert_allclose(chord.g, r.g, rtol=0, atol=1e-9)
    if N == 96:
        paper = compiled(PAPER)
        xp, gp = top_path(PAPER, parameters(paper), N, h)
        assert not paper.solve_bvp((xp[:2], gp[:2]), (xp[-2:], gp[-2:]), N, h,
                                   maxiter=150).success


def tangent_curvatures(mod, result, h: float) -> np.ndarray:
    """Eigenvalues of the Hessian W of S + λ·Φ_d on the null space of A = ∂Φ_d/∂η (the
    constraints' tangent space; Nocedal & Wright, Theorem 12.6) at ``result``: all
    positive at a strict local minimum, some negative at a saddle. W and A are taken on
    the free nodes: the layout's first and last blocks carry the fixed nodes 1 and N − 1,
    whose rows are the identity."""
    path = path_through(mod, result.x, result.g, h)
    path.lam[:] = result.multipliers
    problem = runtime_of(mod, "bvp.assembly").Problem(mod.model, mod.model.params(None), h)
    J = dense_jacobian(*problem.assemble(path, True)[1:3])
    rows, n = problem.constraint_rows(path), mod.model.n
    free = ~rows
    free[:n] = free[-n - mod.model.constraints:-mod.model.constraints] = False
    W, A = J[np.ix_(free, free)], J[np.ix_(rows, free)]
    assert np.abs(W - W.T).max() < 1e-12 * np.abs(W).max()    # symmetric at a KKT point
    Z = null_space(A)
    return np.linalg.eigvalsh(Z.T @ W @ Z)


@pytest.mark.parametrize("turn, N", [(0.05, 96), (0.3, 40)])
def test_rest_to_rest_turns_converge_to_minima(compiled, turn, N):
    """From rest upright to rest tilted by (0.2, 0.1, 0) then turned about the vertical,
    rotors to (−1, 0.5), T = 2: a non-planar problem far from its guess (the second
    Newton step asks for multipliers ~7·10⁴, the solution's are ~2·10³). Both converge
    within the default maxiter (about 70 and 30 iterations) to a minimum: residual at the
    rounding level, every window's constraint met, W positive definite on the
    constraints' tangent space. Without the curvature test of the descent step both
    ended on saddles of the cost (curvatures −1.8 and −4.6 there, costs 689.5 and 568.3
    against 293.5 and 319.4), the second after 208 iterations."""
    mod, h, e3 = compiled(NAME), T / N, np.array([0.0, 0.0, 1.0])
    R = Rotation.from_rotvec([0.0, 0.0, turn]) * Rotation.from_rotvec([0.2, 0.1, 0.0])
    R = R.as_matrix()
    start = (np.array([np.r_[e3, 0.0, 0.0]] * 2), np.stack([np.eye(3)] * 2))
    end = (np.array([np.r_[R.T @ e3, -1.0, 0.5]] * 2), np.stack([R] * 2))
    r = mod.solve_bvp(start, end, N, h)
    print(f"\nturn {turn}, N = {N}: {r.message}, cost {r.cost:.10f}")
    assert r.success and r.residual_norms[-1] < 1e-8
    phi = mod.model.along("constraint", r.x, r.f, h)
    assert np.abs(phi).max() < 1e-9
    curvatures = tangent_curvatures(mod, r, h)
    print(f"least curvature on the tangent space {curvatures[0]:.3e}")
    assert curvatures[0] > 0.0


def test_inconsistent_vertical_momentum_is_refused(compiled):
    """Ends whose discrete vertical momenta differ admit no solution: ValueError naming the
    symmetry and the mismatch, before any iteration."""
    mod, N = compiled(NAME), 40
    h = T / N
    x, g = top_path(NAME, parameters(mod), N, h)
    g[-1] = g[-2] @ cay(hat(h * np.array([0.0, 0.0, 0.01])))     # spin the last element
    x[-1, :3] = g[-1].T @ [0.0, 0.0, 1.0]
    with pytest.raises(ValueError, match="inconsistent boundary data.*'vertical_momentum'"):
        mod.solve_bvp((x[:2], g[:2]), (x[-2:], g[-2:]), N, h)
    assert get(NAME).control_system.equations == "variational"


def cart_pole_with_a_wrong_symmetry():
    """The bundled cart-pole with variational equations, declaring the pole-angle shift,
    which gravity and the cos θ coupling break."""
    base = get("cart_pole_oc")
    system = base.control_system
    return optimal_control(
        name="cart_pole_wrong_symmetry", groupoid=base.groupoid, lagrangian=system.lagrangian,
        cost=system.cost, controls=system.controls, actuated=system.actuated,
        parameters=dict(base.parameters), equations="variational",
        symmetries=[Symmetry("pole_shift", [0, 1])])


def test_a_symmetry_that_is_not_exact_is_refused(build_dir):
    """Σ_k Z·Φ_d^k differs between two paths with the same ends, so the solver refuses to
    drop a constraint on the wrong symmetry's account (no silent success with an unmet
    constraint)."""
    mod = compile_model(cart_pole_with_a_wrong_symmetry(), build_dir)
    with pytest.raises(ValueError, match="'pole_shift' is not an exact dependency"):
        mod.solve_bvp(np.zeros((2, 2)), np.array([[1.0, 0.0]] * 2), 40, 0.05)


def test_noether_check_verifies_the_symmetries_the_solver_relies_on():
    """`symvi check`'s noether check tests them on the first-order L_d of L: exact for the
    heavy top's vertical rotation, and the wrong one fails with its leading defect, the
    1/h coupling term ℓm(θ₁ − θ₀)(x₁ − x₀) sin θ̄ / h."""
    assert check(get(NAME), only=["noether"])["noether"].status == "pass"
    result = check(cart_pole_with_a_wrong_symmetry(), only=["noether"])["noether"]
    assert result.status == "fail" and "pole_shift" in result.summary
    leading = next(d for d in result.details if "leading term" in d)
    assert "/h" in leading and "zoo" not in leading
