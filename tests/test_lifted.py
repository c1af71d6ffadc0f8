"""The lifted whole-trajectory Newton system (issue 20, item 2; ``templates/lifted.c.j2``).

The node formulation's Newton matrix is a fourth difference (κ ∝ N⁴): from N ≈ 10⁵ its
LU has no correct digit. The lifted system — node corrections, the elements' increments
and momenta as unknowns, composability as rows — gives the same Newton step with κ ∝ N²,
and its inertia decides minimum or saddle where J's Cholesky cannot (at a saddle:
tests/test_robustness.py). Convergence at N = 10⁵ is hunted in tests/test_false_success.py.
"""
from __future__ import annotations

import numpy as np
import pytest

from symvi.models import get

from test_bvp_merit import dense_jacobian, runtime_of
from test_false_success import REST_TO_REST, cubic

LIFTED = ["cubic_spline", "so3_cubic", "rigid_body_oc", "double_pendulum_oc", "cart_pole_oc",
          "heavy_top_rotors_oc_variational"]


def boundary(name: str, N: int) -> tuple:
    """(start, end, h) over the horizon 1: the exact cubic's end nodes for cubic_spline,
    the rigid-body quarter turn for the models on SO(3), else the example's own data."""
    h = 1.0 / N
    if name == "cubic_spline":
        exact = cubic(h * np.arange(N + 1))
        return exact[:2], exact[-2:], h
    ex = get(REST_TO_REST if name == "so3_cubic" else name).example
    return ex.start, ex.end, (ex.h * ex.n_steps / N if name != "so3_cubic" else h)


def systems(mod, name: str, N: int, guess="chord"):
    """The node and the lifted Problem, both assembled at the same initial path."""
    start, end, h = boundary(name, N)
    p = mod.model.params(None)
    path = runtime_of(mod, "core.paths").initial_path(mod.model, start, end, N, guess, p, h)
    out = []
    for lifted in (False, True):
        problem = runtime_of(mod, "bvp.assembly").Problem(mod.model, p, h, lifted=lifted)
        res, ab, bw, finite = problem.assemble(path, True)
        assert finite and (problem.lifted_system is not None) is lifted
        out.append((problem, res, ab, bw))
    return out


@pytest.mark.parametrize("name", LIFTED)
def test_lifted_steps_are_the_newton_steps(compiled, name):
    """Pair groupoid (increments measured from the nodes), SO(3) with its curvature terms,
    constraints with their multipliers, an action groupoid (base points moving with the
    nodes) times a pair groupoid with an exactly dependent constraint (its gauge rows),
    with and without the inertia correction's shift: the same correction as J η = −R."""
    mod = compiled(name)
    assert mod.INFO.lifted
    (node, res, ab, bw), (lifted, _, _, _) = systems(mod, name, 40)
    for shift in (0.0, 3.0):
        expected = node.solve(ab, bw, -res, shift)
        got = lifted.solve(ab, bw, -res, shift)
        assert np.abs(got - expected).max() <= 1e-9 * np.abs(expected).max(), shift


def barrier_systems(mod, N: int, seed: int = 0):
    """The node and the lifted Problem of a bounded model at its example's cubic guess,
    with random bound multipliers z and slacks s: each assembled with the barrier's
    weights z/s, the node band given GᵀΣG and Gᵀ(zc + μ)/s by ``add_barrier``."""
    ex, model = get(mod.model.name).example, mod.model
    h, p = ex.h * ex.n_steps / N, model.params(None)
    paths = runtime_of(mod, "core.paths")
    path = paths.initial_path(model, ex.start, ex.end, N, None, p, h)
    rng, s_count = np.random.default_rng(seed), model.constraints
    z = rng.uniform(0.1, 1.0, path.lam[:, s_count:].shape)
    path.lam[:, s_count:] = z
    slack = rng.uniform(0.1, 1.0, z.shape)
    inequalities = runtime_of(mod, "bounded.barrier").Inequalities(model, N + 1)
    out = []
    for lifted in (False, True):
        problem = runtime_of(mod, "bvp.assembly").Problem(model, p, h, lifted=lifted)
        res, ab, bw, finite = problem.assemble(path, True, z / slack)
        assert finite and inequalities.add_barrier(path, p, h, z, slack, 0.1, res, ab)
        out.append((problem, res, ab, bw))
    return out


@pytest.mark.parametrize("name", ["cart_pole_swing_up", "spacecraft_slew", "planar_flyer"])
def test_lifted_barrier_steps_are_the_interior_point_steps(compiled, name):
    """With inequalities the lifted windows carry z·∇²c and the eliminated slack and
    multiplier steps JᵀΣJ in the windows' coordinates: the interior point's reduced
    step is the node system's, J + GᵀΣG, on a pair groupoid with constraints (the
    swing-up: the pole's equation per window, force and track limits), on SO(3) (the
    slew's torque and rate limits) and on an action groupoid (the flyer's keep-out disc
    on its base point), with and without the inertia correction's shift."""
    mod = compiled(name)
    assert mod.INFO.lifted and mod.INFO.inequalities
    (node, res, ab, bw), (lifted, _, _, _) = barrier_systems(mod, 40)
    for shift in (0.0, 3.0):
        expected = node.solve(ab, bw, -res, shift)
        got = lifted.solve(ab, bw, -res, shift)
        assert np.abs(got - expected).max() <= 1e-8 * np.abs(expected).max(), shift


def test_lifted_barrier_inertia_counts_the_reduced_eigenvalues(compiled):
    """The lifted verdict on J + GᵀΣG + s·I, at shifts s = −cut between its smallest
    eigenvalues and below them (the slew at the cubic guess, random z and s): exactly the
    eigenvalues below the cut are counted — the interior point's inertia test where J's
    band Cholesky cannot resolve W's smallest eigenvalue (N ≥ 2000)."""
    mod = compiled("spacecraft_slew")
    (_, _, ab, bw), (lifted, _, _, _) = barrier_systems(mod, 30, seed=1)
    J = dense_jacobian(ab, bw)
    eigenvalues = np.linalg.eigvalsh(0.5 * (J + J.T))
    gaps = 0.5 * (eigenvalues[:-1] + eigenvalues[1:])
    for cut in [*gaps[:4], eigenvalues[0] - 1.0]:
        minimum, excess = lifted.lifted_system.minimum(-cut)
        below = int((eigenvalues < cut).sum())
        assert (excess, minimum) == (below, below == 0), (cut, excess, below)


def equilibrated(A: np.ndarray, sweeps: int = 30) -> np.ndarray:
    """Ruiz's row and column equilibration: the scaling a pivoting LU does not feel."""
    r, c = np.ones(A.shape[0]), np.ones(A.shape[1])
    for _ in range(sweeps):
        r /= np.sqrt(np.abs(A * r[:, None] * c).max(axis=1))
        c /= np.sqrt(np.abs(A * r[:, None] * c).max(axis=0))
    return A * r[:, None] * c


@pytest.mark.parametrize("name", ["cubic_spline", "rigid_body_oc"])
def test_conditioning_grows_like_N_squared(compiled, name):
    """κ₁ of the equilibrated matrices at N = 50, 100, 200: the node matrix's grows like
    N⁴, the lifted one's like N² (measured exponents 4.04 and 2.01 on cubic_spline, 4.02
    and 1.79 on rigid_body_oc; 4.0 and 1.9 on N = 100 … 800)."""
    mod = compiled(name)
    Ns, kappas = [50, 100, 200], []
    for N in Ns:
        (_, _, ab, bw), (lifted, _, _, _) = systems(mod, name, N, guess="cubic")
        system = lifted.lifted_system
        kappas.append([np.linalg.cond(equilibrated(dense_jacobian(band, width)), 1)
                       for band, width in ((ab, bw), (system.band, system.bw))])
    node, lifted = np.polyfit(np.log(Ns), np.log(kappas), 1)[0]
    print(f"\n{name}: κ ∝ N^{node:.2f} (nodes), N^{lifted:.2f} (lifted)")
    assert 3.7 <= node <= 4.3 and 1.7 <= lifted <= 2.3, (node, lifted)


def test_inertia_counts_the_newton_matrix_eigenvalues(compiled):
    """The lifted verdict for J + s·I at shifts s between J's eigenvalues: exactly the
    eigenvalues below −s are counted, at a path where J is indefinite."""
    name, N = "double_pendulum_oc", 60
    mod = compiled(name)
    (_, _, ab, bw), (lifted, _, _, _) = systems(mod, name, N)
    J = dense_jacobian(ab, bw)
    eigenvalues = np.linalg.eigvalsh(0.5 * (J + J.T))
    assert eigenvalues[0] < 0, "the chord path should be a saddle of the cost"
    gaps = 0.5 * (eigenvalues[:-1] + eigenvalues[1:])
    for cut in [*gaps[:4], eigenvalues[0] - 1.0]:
        shift = -cut
        minimum, excess = lifted.lifted_system.minimum(shift)
        below = int((eigenvalues < cut).sum())
        assert (excess, minimum) == (below, below == 0), (shift, excess, below)


@pytest.mark.parametrize("name", ["cart_pole_oc", "heavy_top_rotors_oc_variational"])
def test_constrained_inertia_decides_the_reduced_hessian(compiled, name):
    """With constraints the lifted verdict for W + s·I is whether ZᵀWZ + s·I is positive
    definite, Z an orthonormal basis of ker A (A the constraints' Jacobian on the free
    nodes, rank deficient for the heavy top's exact dependency): at shifts between the
    reduced Hessian's eigenvalues at the chord path, and below the smallest."""
    N = 30
    mod = compiled(name)
    (node, _, ab, bw), (lifted, _, _, _) = systems(mod, name, N)
    from scipy.linalg import null_space

    J = dense_jacobian(ab, bw)
    n, s = mod.model.n, mod.model.constraints
    blocks = J.shape[0] // (n + s)
    layout = np.arange(J.shape[0]).reshape(blocks, n + s)
    free = layout[1:-1, :n].reshape(-1)      # η of nodes 2 … N − 2 (blocks 1 and N − 1 fixed)
    rows = layout[:, n:].reshape(-1)
    W, A = J[np.ix_(free, free)], J[np.ix_(rows, free)]
    Z = null_space(A)
    reduced = np.linalg.eigvalsh(Z.T @ (0.5 * (W + W.T)) @ Z)
    scale = np.abs(reduced).max()
    cuts = [*(0.5 * (reduced[:-1] + reduced[1:]))[:3], reduced[0] - 0.1 * scale]
    for cut in cuts:
        minimum, _ = lifted.lifted_system.minimum(-cut)
        assert minimum == (cut < reduced[0]), (cut, reduced[:4])


def random_band(rng, size: int, bw: int, diagonal: float = 1.0):
    """(A, its LAPACK band storage ab[2 bw + i − j, j]): a random matrix of bandwidth bw,
    its diagonal scaled by ``diagonal``."""
    A = np.zeros((size, size))
    for d in range(-bw, bw + 1):
        A += np.diag(rng.standard_normal(size - abs(d)) * (diagonal if d == 0 else 1.0), d)
    ab = np.zeros((3 * bw + 1, size), order="F")
    for j in range(size):
        for i in range(max(0, j - bw), min(size, j + bw + 1)):
            ab[2 * bw + i - j, j] = A[i, j]
    return A, ab


def test_band_factor_solve_and_residual_are_lapacks(compiled):
    """The C band LU (``band.factor``) against LAPACK's dgbtrf on a random band matrix
    whose small diagonal forces row exchanges: the same pivots and factors; the C solve
    against a dense solve; the fused backward error terms (``band.residual``) against
    dense products."""
    from scipy.linalg.lapack import dgbtrf

    mod = compiled("cubic_spline")
    band = runtime_of(mod, "bvp.band")
    rng = np.random.default_rng(3)
    size, bw = 200, 7
    A, ab = random_band(rng, size, bw, diagonal=1e-3)
    b, x, d = (rng.standard_normal(size) for _ in range(3))
    r, s = np.empty(size), np.empty(size)
    error = band.residual(mod.model, ab, bw, x, b, (r, s), d)
    np.testing.assert_allclose(r, b - (A + np.diag(d)) @ x, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(s, np.abs(A) @ np.abs(x) + np.abs(d * x) + np.abs(b), rtol=1e-13)
    assert error == pytest.approx(np.max(np.abs(r) / s), rel=1e-15)
    lapack, expected_pivots, info = dgbtrf(ab.copy(order="F"), bw, bw)
    lu = ab.copy(order="F")
    pivots = band.factor(mod.model, lu, bw, "test matrix")
    assert info == 0 and np.any(pivots != np.arange(size))      # rows were exchanged
    np.testing.assert_array_equal(pivots, expected_pivots)
    np.testing.assert_allclose(lu, lapack, rtol=1e-9, atol=1e-9 * np.abs(lapack).max())
    solved = band.lu_solve(mod.model, lu, bw, pivots, b.copy())
    expected = np.linalg.solve(A, b)
    assert np.abs(solved - expected).max() <= 1e-10 * np.abs(expected).max()
    singular = ab.copy(order="F")
    singular[:, 50] = 0.0
    with pytest.raises(np.linalg.LinAlgError, match="test matrix: singular at column 51"):
        band.factor(mod.model, singular, bw, "test matrix")


def test_band_cholesky_decides_definiteness_of_the_symmetric_part(compiled):
    """The C band Cholesky (``band.positive_definite``) of sym(A) + s·I, A a random
    non-symmetric band matrix: positive definite exactly for shifts s above −λ_min of
    sym(A), and never with a non-finite entry."""
    mod = compiled("cubic_spline")
    band = runtime_of(mod, "bvp.band")
    size, bw = 120, 5
    A, ab = random_band(np.random.default_rng(5), size, bw)
    lowest = float(np.linalg.eigvalsh(0.5 * (A + A.T))[0])
    assert lowest < 0
    for shift, expected in ((-lowest - 1e-6, False), (-lowest + 1e-6, True), (0.0, False),
                            (-lowest + 10.0, True)):
        assert band.positive_definite(mod.model, ab, bw, shift) is expected, shift
    ab[2 * bw + 1, 7] = np.inf
    assert band.positive_definite(mod.model, ab, bw, -lowest + 10.0) is False

