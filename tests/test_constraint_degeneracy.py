"""Why the heavy top with rotors is hard to solve away from planar motions (paper §3.3.5).

The top's unactuated equations Φ = EL(l)_Ω conserve the vertical angular momentum:
d/dt(Γ·∂l/∂Ω) = Γ·Φ exactly, since the rotor torques are internal. So the continuous
constraints are dependent along v = Γ, and their multipliers are free up to c·Γ(t). The
paper's discretisation (midpoint Ω, Γ at the middle node) keeps this only approximately:
Σ_w Γ_w·Φ_d(w) telescopes up to O(h⁴) relative to J_Φ. The discrete constraints are then
nearly dependent, σ_min(J_Φ)/σ_max ∝ N⁻⁴ against the generic N⁻² of the next singular
value, the multipliers grow like N² along Γ, and from N ≈ 100 the optimality system is
singular in double precision. This test measures that structure on the feasible non-planar
path of ``test_optimal_control.top_path``.
"""
from __future__ import annotations

import numpy as np
import pytest

from symvi.models import get
from test_bvp_merit import dense_jacobian, runtime_of
from test_optimal_control import top_path

NAME = "heavy_top_rotors_oc"


def path_through(mod, x, g, h):
    """The run-time Path with the nodes (x, g), its ends fixed as a solve would take them."""
    p = mod.model.params(None)
    return runtime_of(mod, "core.paths").initial_path(
        mod.model, (x[:2], g[:2]), (x[-2:], g[-2:]), len(g) - 1, (x[2:-2], g[2:-2]), p, h)


def feasible_system(mod, n_steps: int):
    """(problem, path, res, ab, bw): the Newton system assembled at the feasible
    non-planar path of ``n_steps`` steps over the example's horizon (mod's own Φ_d)."""
    name, p = mod.model.name, mod.model.params(None)
    ex = get(name).example
    h = ex.n_steps * ex.h / n_steps
    x, g = top_path(name, dict(zip(mod.model.parameter_names, p)), n_steps, h)
    path = path_through(mod, x, g, h)
    problem = runtime_of(mod, "bvp.assembly").Problem(mod.model, p, h)
    res, ab, bw, finite = problem.assemble(path, True)
    assert finite and np.abs(res[problem.constraint_rows(path)]).max() < 1e-10   # feasible
    return problem, path, res, ab, bw


def constraint_jacobian(problem, path, ab, bw):
    """(J_Φ dense, v): the constraint rows of the assembled Jacobian over the node
    unknowns, and v = Γ at the middle node of every window, in the same row layout."""
    rows = problem.constraint_rows(path)
    # constraint block t holds window t − 1, whose middle node is t
    gamma = path.x[problem._blocks(path), :3].reshape(-1)
    return dense_jacobian(ab, bw)[rows][:, ~rows], gamma


@pytest.fixture(scope="module")
def measured(compiled):
    """Per N: (‖J_Φᵀv‖/(‖v‖σ_max), σ_min/σ_max, σ_{min+1}/σ_max, |cos| of the angle
    between v and the left singular vector of σ_min)."""
    mod, out = compiled(NAME), {}
    for n_steps in (24, 48, 96):
        problem, path, _, ab, bw = feasible_system(mod, n_steps)
        jac, v = constraint_jacobian(problem, path, ab, bw)
        left, sigma, _ = np.linalg.svd(jac)
        out[n_steps] = (np.linalg.norm(v @ jac) / np.linalg.norm(v) / sigma[0],
                        sigma[-1] / sigma[0], sigma[-2] / sigma[0],
                        abs(left[:, -1] @ v) / np.linalg.norm(v))
    return out


def orders(values):
    return np.log2(np.array(values[:-1]) / np.array(values[1:]))


def test_vertical_momentum_nearly_annihilates_the_constraint_jacobian(measured):
    """‖J_Φᵀ Γ‖ falls at order 4 in h relative to ‖J_Φ‖ (measured 3.97, 3.99)."""
    rates = orders([measured[n][0] for n in sorted(measured)])
    np.testing.assert_allclose(rates, 4.0, atol=0.1)
    assert measured[24][0] < 1e-4


def test_smallest_singular_value_is_the_vertical_momentum_one(measured):
    """σ_min/σ_max falls at order 4 like ‖J_Φᵀ Γ‖, the next singular value at the generic
    order 2, and the left singular vector of σ_min is Γ: 1 − |cos| is 4.3e-6, 3.1e-7 and
    2.1e-8 at N = 24, 48, 96."""
    ns = sorted(measured)
    np.testing.assert_allclose(orders([measured[n][1] for n in ns]), 4.0, atol=0.15)
    np.testing.assert_allclose(orders([measured[n][2] for n in ns]), 2.0, atol=0.2)
    misalignment = [1.0 - measured[n][3] for n in ns]
    assert misalignment[0] < 1e-5 and all(np.diff(np.log(misalignment)) < -2.0)
