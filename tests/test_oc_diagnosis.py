"""Why an underactuated optimal-control solve fails, where its constraints are the cause
(issue 22, item 5; ``symvi/_runtime/bvp/diagnosis.py``).

A planar body on SE(2) with a torque only: the constraints are its unactuated
translational equations, m(v̇₁ − ωv₂) = m(v̇₂ + ωv₁) = 0 — in the world frame mẍ = 0.
No control moves the body's position, so

- from rest, any end position but the start's is unreachable: asked to translate, the
  solve must fail (never a SUCCESS) and say which directions and which end data;
- a pure rotation is feasible, but the world-frame translational motion, a free
  particle in two coordinates with position and velocity given at both ends, is
  determined twice: 2 × 2 = 4 combinations of the constraints have no gradient, and
  the Newton matrix is singular at every N.
"""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from symvi import SE2, Example, optimal_control
from symvi.build import compile_model
from test_bvp_merit import runtime_of

T = 2.0


def pose(x: float, y: float, heading: float) -> np.ndarray:
    c, s = np.cos(heading), np.sin(heading)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def at_rest(g: np.ndarray) -> np.ndarray:
    return np.stack([g, g])


@pytest.fixture(scope="module")
def torque_only(build_dir):
    G = SE2()
    omega, v1, v2 = G.xi
    I, m = sp.symbols("I m", positive=True)
    tau = sp.Symbol("tau", real=True)
    model = optimal_control(
        name="torque_only_body", groupoid=G,
        lagrangian=(I * omega**2 + m * (v1**2 + v2**2)) / 2, cost=tau**2 / 2,
        controls=[tau], actuated=[0], parameters={I: 0.5, m: 1.0},
        example=Example(h=T / 20, n_steps=20, start=at_rest(pose(0, 0, 0)),
                        end=at_rest(pose(0, 0, np.pi / 2))))
    return compile_model(model, build_dir)


def solve(module, end: np.ndarray, N: int):
    result = module.solve_bvp(at_rest(pose(0, 0, 0)), at_rest(end), N, T / N,
                              raise_on_failure=False)
    assert not result.success, result.message
    assert "use fewer steps" not in result.message and "use more" not in result.message
    return result


@pytest.mark.parametrize("N", [20, 100])
def test_asked_to_translate_the_failure_names_the_unactuated_directions_and_end_data(
        torque_only, N):
    straight = solve(torque_only, pose(2.0, 0.0, 0.0), N)
    # x(T) − x(0) = T·p/m = 0: the combination the identity telescopes has no gradient
    assert "unactuated direction v1 cannot be met to first order" in straight.message
    # a pure translation's increment is (0, 2, 0) by any retraction: mean v1 = 2/T
    assert "v1: mean 1 over T = 2, 0 at the start, 0 at the end" in straight.message
    turned = solve(torque_only, pose(2.0, 1.0, np.pi / 2), N)
    assert "unactuated directions v1, v2 can be met to first order only by a correction" \
        in turned.message
    assert "ask for motion that no control produces" in turned.message


@pytest.mark.parametrize("N", [20, 100])
def test_a_pure_rotation_names_its_four_dependent_constraints_and_the_remedy(torque_only, N):
    result = solve(torque_only, pose(0.0, 0.0, np.pi / 2), N)
    assert result.status.name == "SINGULAR_JACOBIAN"
    assert "unactuated directions v1, v2 are dependent (4 combinations" in result.message
    assert "symmetries=[Symmetry(name, section)]" in result.message


@pytest.mark.parametrize("N, iterations", [(40, 1), (40, 3), (200, 1), (200, 3)])
def test_no_diagnosis_where_the_constraints_are_not_the_cause(compiled, N, iterations):
    """The cart-pole is underactuated but controllable: a solve stopped early is not
    blamed on its constraints."""
    from symvi.models import get

    module, ex = compiled("cart_pole_oc"), get("cart_pole_oc").example
    h = ex.h * ex.n_steps / N
    result = module.solve_bvp(ex.start, ex.end, N, h, maxiter=iterations,
                              raise_on_failure=False)
    assert result.status.name == "MAX_ITERATIONS"
    assert "constraints of the" not in result.message
    model, p = module.model, module.model.params()
    path = runtime_of(module, "core.paths").initial_path(model, ex.start, ex.end, N, result, p, h)
    problem = runtime_of(module, "bvp.assembly").Problem(model, p, h)
    assert runtime_of(module, "bvp.diagnosis").diagnose(problem, path) is None


def test_a_world_frame_symmetry_declared_as_a_constant_is_refused_with_the_form_expected(
        build_dir):
    """World-frame translations are symmetries of L, but on the Lie group a declared
    section is constant, which moves the nodes by body-frame translations g ↦ g·exp(εZ):
    not a symmetry of a rotating body. The refusal says which form is expected."""
    from symvi import Symmetry

    G = SE2()
    omega, v1, v2 = G.xi
    tau = sp.Symbol("tau", real=True)
    model = optimal_control(
        name="torque_only_declared", groupoid=G,
        lagrangian=(omega**2 / 2 + v1**2 + v2**2) / 2, cost=tau**2 / 2, controls=[tau],
        actuated=[0], equations="variational", symmetries=[Symmetry("p_x", [0, 1, 0])])
    module = compile_model(model, build_dir)
    with pytest.raises(ValueError, match=r"not an exact dependency.*a world-frame \(left\) "
                                         r"translation.*action groupoid whose base point"):
        module.solve_bvp(at_rest(pose(0, 0, 0)), at_rest(pose(0, 0, np.pi / 2)), 20, T / 20)
