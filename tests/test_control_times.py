"""``res.t_controls``: the times of the discrete controls (issue 22). The rest-to-rest
double integrator ẍ = u on [0, 1] from 0 to 1 with cost ½∫u² has the optimum
x = 3t² − 2t³, u = 6 − 12t. Given the exact end nodes, the three-point rule's discrete
optimum is that cubic exactly (the interior equations are a vanishing fourth difference),
and its control u_w = (q_w − 2q_{w+1} + q_{w+2})/h² is ẍ at the window's middle node — so
the controls equal 6 − 12·t_controls to rounding, where times half a step off would miss
by 6h."""
from __future__ import annotations

import numpy as np
import sympy as sp

from symvi import Example, PairGroupoid, optimal_control
from symvi.build import compile_model


def test_controls_are_given_at_the_windows_middle_nodes(build_dir):
    G = PairGroupoid("x")
    (v,) = G.qdot
    u = sp.Symbol("u", real=True)
    N = 50
    h = 1.0 / N

    def x(t):
        return 3 * t**2 - 2 * t**3
    start, end = np.array([[x(0.0)], [x(h)]]), np.array([[x(1.0 - h)], [x(1.0)]])
    model = optimal_control(name="double_integrator", groupoid=G, lagrangian=v**2 / 2,
                            cost=u**2 / 2, controls=[u],
                            example=Example(h=h, n_steps=N, start=start, end=end))
    r = compile_model(model, build_dir).solve_bvp(start, end, N, h)
    assert r.success, r.message
    np.testing.assert_allclose(r.x[:, 0], x(r.t), rtol=0, atol=1e-10)
    assert r.t_controls.shape == (N - 1,) and r.t_controls[0] == h
    error = np.abs(r.controls[:, 0] - (6 - 12 * r.t_controls)).max()
    assert error <= 1e-9, error
