"""Warm starts: ``solve_bvp(..., guess=previous_result)`` (issue 20, item 3).

A previous solve hands over its free nodes, its multipliers and its fibres (where both
nodes are unchanged: recomputed from the configurations they would be rounded to ε/h).
Resolving the same problem must then take the two confirming Newton iterations only, and
a step of a parameter sweep must start nearer (a tenth of the residual) and reach the
same solution as a cold solve, in no more iterations. (Moved boundary data are a different matter: the old free nodes then meet the
new ends with a velocity jump of (move)/h, so a continuation in boundary data takes steps
small against h.)
"""
from __future__ import annotations

import numpy as np
import pytest

from symvi.models import get

#: One problem per kind of unknowns: a Lie group, a pair groupoid, an action groupoid with
#: multipliers.
WARM = ("rigid_body_oc", "double_pendulum_oc", "heavy_top_rotors_oc_variational")


@pytest.mark.parametrize("name", WARM)
def test_warm_start_from_the_solution_and_along_a_continuation(compiled, name):
    mod, ex = compiled(name), get(name).example
    N, h = ex.n_steps, ex.h
    cold = mod.solve_bvp(ex.start, ex.end, N, h)
    assert cold.success, cold.message

    again = mod.solve_bvp(ex.start, ex.end, N, h, guess=cold)
    assert again.success and again.iterations == 1, again.message
    assert abs(again.cost - cold.cost) <= 1e-12 * (1 + abs(cold.cost))

    # a step of a parameter sweep: the first parameter (an inertia, a mass) 5 % larger
    symbol, value = get(name).parameters[0]
    changed = {str(symbol): 1.05 * value}
    reference = mod.solve_bvp(ex.start, ex.end, N, h, changed)
    warm = mod.solve_bvp(ex.start, ex.end, N, h, changed, guess=cold)
    assert reference.success and warm.success, (reference.message, warm.message)
    # it starts nearer (its first residual is smaller) and is never slower
    assert warm.residual_norms[0] < 0.1 * reference.residual_norms[0]
    assert warm.iterations <= reference.iterations, (warm.iterations, reference.iterations)
    assert abs(warm.cost - reference.cost) <= 1e-9 * (1 + abs(reference.cost))
    tol = 1e-8 * (1 + np.abs(reference.f).max())
    assert np.abs(warm.f - reference.f).max() <= tol
    if reference.multipliers is not None:
        scale = 1 + np.abs(reference.multipliers).max()
        assert np.abs(warm.multipliers - reference.multipliers).max() <= 1e-7 * scale


def test_a_previous_result_of_another_size_is_resampled(compiled):
    """A result at N = 40 starts the solve at N = 50 resampled on SO(3) (it was refused):
    the optimum from the default guess."""
    mod, ex = compiled("rigid_body_oc"), get("rigid_body_oc").example
    previous = mod.solve_bvp(ex.start, ex.end, 40, 1 / 40)
    warm = mod.solve_bvp(ex.start, ex.end, 50, 1 / 50, guess=previous)
    cold = mod.solve_bvp(ex.start, ex.end, 50, 1 / 50)
    assert warm.success and cold.success and np.abs(warm.g - cold.g).max() <= 1e-12


def test_a_previous_result_at_another_step_keeps_its_elements(compiled):
    """A warm start at another h (same N, a longer horizon): the kept group fibres are
    rescaled so that they remain the configurations' increments, and the solve reaches
    the cold solve's optimum (it returned SUCCESS 46 % above it while they were kept
    unscaled)."""
    from so3 import cay_inv, vee

    mod, ex = compiled("rigid_body_oc"), get("rigid_body_oc").example
    N = 100
    previous = mod.solve_bvp(ex.start, ex.end, N, 1.0 / N)
    cold = mod.solve_bvp(ex.start, ex.end, N, 1.2 / N)
    warm = mod.solve_bvp(ex.start, ex.end, N, 1.2 / N, guess=previous)
    assert previous.success and cold.success and warm.success, warm.message
    assert abs(warm.cost - cold.cost) <= 1e-9 * cold.cost
    W = warm.g[:-1].transpose(0, 2, 1) @ warm.g[1:]
    xi = np.array([vee(cay_inv(w)) for w in W]) / (1.2 / N)
    assert np.abs(xi - warm.f).max() <= 1e-10 * np.abs(warm.f).max()


def test_fibres_that_are_not_the_nodes_elements_are_not_kept(compiled):
    """A previous result whose fibres disagree with its configurations (edited here:
    doubled) hands over its nodes but not those fibres: the solve reaches the cold
    optimum with fibres that are the configurations' increments."""
    from dataclasses import replace

    from so3 import cay_inv, vee

    mod, ex = compiled("rigid_body_oc"), get("rigid_body_oc").example
    N, h = 60, 1.0 / 60
    cold = mod.solve_bvp(ex.start, ex.end, N, h)
    edited = replace(cold, f=2.0 * cold.f)
    warm = mod.solve_bvp(ex.start, ex.end, N, h, guess=edited)
    assert cold.success and warm.success, warm.message
    assert abs(warm.cost - cold.cost) <= 1e-10 * cold.cost
    W = warm.g[:-1].transpose(0, 2, 1) @ warm.g[1:]
    xi = np.array([vee(cay_inv(w)) for w in W]) / h
    assert np.abs(xi - warm.f).max() <= 1e-10 * np.abs(warm.f).max()
