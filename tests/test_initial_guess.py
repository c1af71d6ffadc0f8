"""The default initial guess of the whole-trajectory solve: the cubic that interpolates
the boundary positions and velocities (``_runtime/core/paths.py``).

With r = 2 the fixed nodes carry velocities; the chord between g_1 and g_{N−1} ignores
them, so the guess starts with a velocity jump of O(1), whose O(1/h) accelerations put
the first Newton iterate far from feasibility. The cubic matches them: exactly on a pair
groupoid, in τ-coordinates at g_1 on a group.
"""
from __future__ import annotations

import numpy as np
import pytest

from so3 import I3, cay, hat
from symvi.models import get
from test_bvp_merit import runtime_of


def guess(mod, start, end, N, kind=None, h=0.05):
    """Nodes (x, g) of the initial path of ``kind`` (None: the default)."""
    p = mod.model.params(None)
    path = runtime_of(mod, "core.paths").initial_path(mod.model, start, end, N, kind, p, h)
    return path.x, path.g.reshape(N + 1, *(3, 3) if mod.model.matrix_dims else (0,))


def hermite(s, a, b, va, vb):
    """Cubic c on [0, 1] with c(0) = a, c(1) = b, c'(0) = va, c'(1) = vb."""
    s = s[:, None]
    return ((1 + 2 * s) * (1 - s) ** 2 * a + s**2 * (3 - 2 * s) * b
            + s * (1 - s) ** 2 * va - s**2 * (1 - s) * vb)


def test_pair_groupoid_guess_is_the_hermite_cubic(compiled):
    """Double pendulum, ends with velocities: nodes 1 … N−1 lie on the cubic through
    q_1, q_{N−1} whose end derivatives are (N − 2) times the end differences."""
    mod, N = compiled("double_pendulum_oc"), 30
    start, end = np.array([[0.0, 0.1], [0.02, 0.13]]), np.array([[1.0, -0.5], [0.97, -0.5]])
    x, _ = guess(mod, start, end, N)
    M, s = N - 2, np.linspace(0.0, 1.0, N - 1)
    cubic = hermite(s, start[1], end[0], M * (start[1] - start[0]), M * (end[1] - end[0]))
    np.testing.assert_allclose(x[1:-1], cubic, rtol=0, atol=1e-14)
    chord, _ = guess(mod, start, end, N, "chord")
    np.testing.assert_allclose(chord[1:-1], start[1] + s[:, None] * (end[0] - start[1]),
                               rtol=0, atol=1e-14)


def test_rest_to_rest_guess_on_a_group_eases_in_and_out(compiled):
    """Rigid body at rest at both ends: g_j = g_1 τ(σ(s) η), σ(s) = 3s² − 2s³ (zero end
    velocities), η = τ⁻¹(g_1⁻¹ g_{N−1}); the first and last free increments are O(1/N²)
    of the whole turn, not 1/(N − 2) as on the chord."""
    mod, N = compiled("rigid_body_oc"), 40
    R = cay(hat(np.array([0.4, -0.3, 0.5])))
    _, g = guess(mod, [I3] * 2, [R] * 2, N)
    s = np.linspace(0.0, 1.0, N - 1)
    expected = [cay(hat((3 * t**2 - 2 * t**3) * np.array([0.4, -0.3, 0.5]))) for t in s]
    np.testing.assert_allclose(g[1:-1], expected, rtol=0, atol=1e-13)


def test_end_velocity_outside_the_chart_is_named(compiled):
    """A half-turn as the last fixed element has no τ⁻¹, so no end velocity: the result
    names that element (the cubic is not formed; the chord between g_1 and g_{N−1} is)."""
    mod, N = compiled("rigid_body_oc"), 40
    r = mod.solve_bvp([I3] * 2, [I3, np.diag([1.0, -1.0, -1.0])], N, 1 / N)
    assert r.status == mod.Status.OUTSIDE_CHART and not r.success
    assert f"w_{N - 1} = g_{N - 1}⁻¹ g_{N}" in r.message and "chart" in r.message


def test_unknown_guess_is_refused(compiled):
    mod, ex = compiled("rigid_body_oc"), get("rigid_body_oc").example
    with pytest.raises(ValueError, match="guess must be .*'cubic', 'chord'.*'spline'"):
        mod.solve_bvp(ex.start, ex.end, 20, 0.05, guess="spline")
