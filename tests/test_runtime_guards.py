"""Run-time guards of issue 19: kernels along a path never read past it, parameters keyed
by SymPy symbols are taken by name, and a diverging Newton iteration stops early."""
from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

from symvi import Model, PairGroupoid, compile_model
from symvi.models import get

H = 0.01


def pendulum_path(compiled, n_steps: int = 6):
    return compiled("pendulum").integrate(get("pendulum").example.initial, n_steps, H)


# -- (a) along(kernel, ..., windows=w) ------------------------------------------------------
def test_along_gives_every_window_the_path_holds(compiled):
    model, path = compiled("pendulum").model, pendulum_path(compiled)
    # L_d takes one element: a window per element; F⁺L_d takes 2r − 1 = 1 as well
    every = model.along("lagrangian", path.x, path.f, H)
    assert every.shape == (path.f.shape[0], 1)
    np.testing.assert_array_equal(
        model.along("lagrangian", path.x, path.f, H, windows=path.f.shape[0]), every)


@pytest.mark.parametrize("kernel", ["lagrangian", "momentum_plus", "energy"])
def test_along_refuses_more_windows_than_the_path_holds(compiled, kernel):
    model, path = compiled("pendulum").model, pendulum_path(compiled)
    available = path.f.shape[0]
    message = rf"kernel '{kernel}': {available + 1} windows asked, but the path holds {available} "
    with pytest.raises(ValueError, match=message):
        model.along(kernel, path.x, path.f, H, windows=available + 1)
    with pytest.raises(ValueError, match=message):
        model.along_vector(kernel, path.x, path.f, H, model.params(), available + 1)


def test_along_counts_the_base_points_too(compiled):
    """Window i reads base point i: a path with fewer base points than windows of
    elements gives (or allows) only as many windows as it has base points."""
    model, path = compiled("pendulum").model, pendulum_path(compiled)
    assert model.along("lagrangian", path.x[:3], path.f, H).shape == (3, 1)
    with pytest.raises(ValueError, match=r"4 windows asked, but the path holds 3"):
        model.along("lagrangian", path.x[:3], path.f, H, windows=4)


def test_along_refuses_a_path_of_the_wrong_width(compiled):
    model = compiled("cubic_spline").model            # n = 2
    with pytest.raises(ValueError, match=r"elements f \(elements, 2\), got x \(5, 2\) and "
                                         r"f \(4, 3\)"):
        model.along("lagrangian", np.zeros((5, 2)), np.zeros((4, 3)), H)


# -- (c) parameters keyed by symbols --------------------------------------------------------
def test_parameter_keyed_by_a_symbol_without_the_assumptions_is_taken_by_name(compiled):
    mod = compiled("pendulum")                        # declares l with positive=True
    initial = get("pendulum").example.initial
    by_name = mod.integrate(initial, 50, H, params={"l": 2.0})
    by_symbol = mod.integrate(initial, 50, H, params={sp.Symbol("l"): 2.0})
    declared = mod.integrate(initial, 50, H, params={sp.Symbol("l", positive=True): 2.0})
    default = mod.integrate(initial, 50, H)
    np.testing.assert_array_equal(by_symbol.x, by_name.x)
    np.testing.assert_array_equal(declared.x, by_name.x)
    assert not np.array_equal(default.x, by_name.x)


def test_unknown_or_repeated_parameter_keys_are_refused(compiled):
    mod, initial = compiled("pendulum"), get("pendulum").example.initial
    with pytest.raises(ValueError, match=r"unknown parameter\(s\) \['k'\]; the model has "
                                         r"\['m', 'l', 'g'\]"):
        mod.integrate(initial, 5, H, params={sp.Symbol("k"): 1.0})
    with pytest.raises(ValueError, match=r"parameter l is given twice, as 'l' and l"):
        mod.integrate(initial, 5, H, params={"l": 2.0, sp.Symbol("l"): 3.0})


# -- (d) a diverging Newton iteration -------------------------------------------------------
@pytest.fixture(scope="module")
def asinh_chain(tmp_path_factory):
    """L_d(q₀, q₁) = F(q₁ − q₀) − c q₀ with F' = asinh (F'' > 0: regular). The step
    solves asinh(d) = asinh(d₀) − c for the jump d = q₂ − q₁, d₀ = q₁ − q₀, starting from
    the predictor's d = d₀; Newton's update is −(asinh(d) − target)·√(1 + d²)."""
    G = PairGroupoid("x")
    (q0,), (q1,) = G.nodes(2)
    c, d = sp.Symbol("c", real=True), q1 - q0
    Ld = d * sp.asinh(d) - sp.sqrt(1 + d**2) - c * q0
    model = Model("asinh_chain", G, discrete_lagrangian=Ld, order=1, parameters={c: 0.0})
    return compile_model(model, tmp_path_factory.mktemp("asinh"))


def newton_on_asinh(d: float, target: float, maxiter: int, stop: bool = True):
    """Newton on asinh(d) = target as the stepper runs it, with its divergence test
    unless ``stop`` is false: (outcome, iterations, last iterate, update ratios θ)."""
    previous, largest, growing, before, thetas = math.inf, 0.0, 0, 0.0, []
    for it in range(1, maxiter + 1):
        residual, slope = math.asinh(d) - target, math.sqrt(1 + d * d)   # slope = 1/|∂R/∂d|
        step = -residual * slope
        d += step
        size = abs(step)
        if size <= 1e-12 * (1 + abs(d)):
            return "converged", it, d, thetas
        thetas.append(size / previous)
        growing = growing + 1 if size > 2 * previous else 0
        # more than doubled twice, to the largest yet, and not contracting: the residual
        # solved with the previous Jacobian asks for no less than the previous update
        if stop and growing >= 2 and size > largest and abs(residual) * before >= previous:
            return "diverged", it, d, thetas
        previous, largest, before = size, max(largest, size), slope
    return "maxiter", maxiter, d, thetas


def test_diverging_newton_stops_within_a_few_iterations(asinh_chain):
    """From q₀ = 0, q₁ = 10 with c = asinh(10) the step's solution is q₂ = q₁ (d = 0);
    from d = 10 Newton flips sign and grows log(2|d|)-fold per iteration (10, −20.1,
    54.1, −199, …): after 50 iterations |d| ≈ 4e86, finite, which the stepper used to
    report as a mere MAX_ITERATIONS."""
    c = math.asinh(10.0)
    outcome, _, blown_up, _ = newton_on_asinh(10.0, 0.0, 50, stop=False)
    assert outcome == "maxiter" and 1e80 < abs(blown_up) < 1e100
    outcome, expected, _, thetas = newton_on_asinh(10.0, 0.0, 50)
    assert (outcome, expected) == ("diverged", 3)
    assert thetas[1:] == pytest.approx([2.47, 3.42], abs=0.01)
    r = asinh_chain.integrate([[0.0], [10.0]], 5, 0.1, params={"c": c}, maxiter=50)
    assert r.status == asinh_chain.Status.DIVERGED and not r.success
    assert r.message.startswith("step 2 of 5 (to t = 0.2) failed: Newton's iterates diverged "
                                "(at iteration 3 of at most 50:")
    assert r.newton_iterations.shape == (0,) and r.x.shape == (2, 1)
    with pytest.raises(asinh_chain.NewtonError, match="diverged"):
        asinh_chain.integrate([[0.0], [10.0]], 5, 0.1, params={"c": c}, raise_on_failure=True)


def test_growing_updates_towards_a_far_solution_are_not_divergence(asinh_chain):
    """From d₀ = −50 with c = 4.6 the solution d* = sinh(asinh(−50) − 4.6) ≈ −4975 lies
    a hundredfold beyond the predictor: the updates grow (θ = 3.5, then 2.05) while
    contracting, and Newton converges."""
    c = 4.6
    target = math.asinh(-50.0) - c
    outcome, iterations, d, thetas = newton_on_asinh(-50.0, target, 50)
    assert outcome == "converged" and thetas[1] > 2 and thetas[2] > 2
    r = asinh_chain.integrate([[0.0], [-50.0]], 2, 0.1, params={"c": c})
    assert r.success, r.message
    assert r.newton_iterations[0] <= iterations    # C may stop one early on θ's estimate
    jump = r.x[2, 0] - r.x[1, 0]
    assert jump == pytest.approx(math.sinh(target), rel=1e-12) and jump == pytest.approx(d)
