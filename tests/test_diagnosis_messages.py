"""What a failed solve with constraints says, checked against a feasible and an infeasible
problem (issue 53, item 4; ``symvi/_runtime/bvp/diagnosis.py``).

Feasible: the unicycle parked sideways by 1 (``unicycle_parking``) from the straight line
between its ends — at rest, heading along x, moving along y — where the sideways constraint
ẏ − v sin θ = 0 has no gradient toward the displacement (v = 0, θ = 0): Newton's matrix is
singular at iteration 0, yet the problem is feasible (the Example's guess, driving while
turning, converges). The message blames the path and says which guess to give; it said
"the constraint of the constraint constraint 2 cannot be met … Change the end conditions
or actuate these directions".

Infeasible: a cart on a rail along x (velocities in the span of (1, 0)) asked to end at
y = 1: ẏ = 0 telescopes, Σ_k (y_{k+1} − y_k) = y_N − y_0, at every path. The message says
the end conditions ask for motion the constraints forbid, at the path varied too.
"""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from symvi import PairGroupoid, distribution, nonholonomic_control
from symvi.build import compile_model
from symvi.models import get


def straight_line(example) -> np.ndarray:
    """The free nodes of the straight line between the Example's ends."""
    N = example.n_steps
    s = np.linspace(0.0, 1.0, N + 1)[1:-1, None]
    return example.start[0] + s * (example.end[0] - example.start[0])


def test_unicycle_from_a_straight_line_blames_the_path_and_says_which_guess(compiled):
    module, example = compiled("unicycle_parking"), get("unicycle_parking").example
    args = (example.start, example.end, example.n_steps, example.h)
    result = module.solve_bvp(*args, guess=straight_line(example), raise_on_failure=False)
    assert result.status.name == "SINGULAR_JACOBIAN"
    assert ("at this path constraint 2 has no gradient along a combination whose value "
            "(0.112) the end conditions ask to change, but it has one once the path's free "
            "nodes are varied by 1e-2: the path, not the problem, is degenerate") \
        in result.message
    assert result.message.endswith(
        "Give solve_bvp a guess that already moves along the allowed directions (for a "
        "wheeled vehicle moved sideways: driving while turning, forward then back)")
    assert "Change the end conditions" not in result.message
    assert "constraint of the constraint" not in result.message
    # and it is feasible: the guess the message describes converges
    s = np.linspace(0.0, 1.0, example.n_steps + 1)
    solved = module.solve_bvp(*args, guess=example.guess(s)[1:-1])
    assert solved.success, solved.message


@pytest.fixture(scope="module")
def rail_cart(build_dir):
    Q = PairGroupoid("x y")
    m = sp.Symbol("m", positive=True)
    F = sp.Symbol("F", real=True)
    D = distribution(Q, [[1, 0]], "v")
    model = nonholonomic_control(name="rail_cart", D=D, lagrangian=m * Q.qdot[0]**2 / 2,
                                 cost=F**2 / 2, controls=[F], parameters={m: 1.0})
    return compile_model(model, build_dir)


def test_rail_cart_asked_off_its_rail_is_told_the_end_conditions_are_unreachable(rail_cart):
    start, end = np.zeros((1, 3)), np.array([[1.0, 1.0, 0.0]])
    result = rail_cart.solve_bvp(start, end, 20, 0.05, raise_on_failure=False)
    assert not result.success
    assert ("constraint 2 cannot be met to first order: it has no gradient at this path but "
            "the value") in result.message
    assert result.message.endswith(
        ", nor at the path varied — the end conditions ask for motion that the constraints "
        "forbid. Change the end conditions: no path that keeps these constraints joins "
        "them")
    assert "degenerate" not in result.message
