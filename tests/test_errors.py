"""Bad input is refused early, with a message that names the problem.

Model errors at construction (undeclared symbols, shapes), regularity at compile time,
Newton failures at run time (reported with the step and the residual norm, arrays
truncated, never NaN), argument validation, and build failures (compiler errors,
missing compiler). Throwaway models are compiled into ``tmp_path``.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest
import sympy as sp

import symvi
import symvi.build
from symvi import BuildError, CompilerNotFoundError, Example, Model, ModelError, PairGroupoid, h
from symvi.build import compile_model
from symvi.models import get

# -- model declaration ----------------------------------------------------------------------


def oscillator_symbols():
    G = PairGroupoid("x")
    (x,), (v,) = G.q, G.qdot
    return G, x, v


def test_undeclared_symbol_is_named():
    G, x, v = oscillator_symbols()
    stiffness = sp.Symbol("stiffness")
    with pytest.raises(ModelError) as info:
        Model("bad", G, lagrangian=v**2 / 2 - stiffness * x**2 / 2)
    message = str(info.value)
    assert "undeclared" in message and "stiffness" in message
    # declared as a parameter, the same Lagrangian is fine
    Model("good", G, lagrangian=v**2 / 2 - stiffness * x**2 / 2, parameters={stiffness: 1.0})


def test_undeclared_symbol_in_discrete_lagrangian_is_named():
    G = PairGroupoid("x")
    (x0,), (x1,) = G.nodes(2)
    x2 = sp.Symbol("x_2", real=True)           # a node outside the first-order window
    with pytest.raises(ModelError) as info:
        Model("bad", G, discrete_lagrangian=(x1 - x0) ** 2 / (2 * h) + x2, order=1)
    assert "x_2" in str(info.value) and "undeclared" in str(info.value)


def test_acceleration_with_first_order_rule_is_refused():
    G = PairGroupoid("x")
    (a,) = G.qddot
    with pytest.raises(ModelError, match=r"x_ddot.*second order.*'midpoint' is first order.*three_point"):
        Model("bad", G, lagrangian=a**2 / 2, discretisation="midpoint")


def test_matrix_lagrangian_is_a_dimension_error():
    G, x, v = oscillator_symbols()
    with pytest.raises(ModelError) as info:
        Model("bad", G, lagrangian=sp.Matrix([v**2 / 2, -x**2 / 2]))
    message = str(info.value)
    assert "scalar" in message and "(2, 1)" in message


def test_example_initial_data_of_wrong_shape_is_refused():
    G = PairGroupoid("x y")
    (x, y), (u, w) = G.q, G.qdot
    with pytest.raises(ModelError) as info:
        Model("bad", G, lagrangian=(u**2 + w**2) / 2,
              example=Example(initial=[[1.0, 0.0, 0.5]], h=0.1, n_steps=10))
    message = str(info.value)
    assert "(1, 3)" in message and "(2, 2)" in message and "example" in message


def test_unknown_discretisation_is_named():
    G, x, v = oscillator_symbols()
    with pytest.raises(ModelError, match=r"unknown discretisation 'leapfrog'"):
        Model("bad", G, lagrangian=v**2 / 2, discretisation="leapfrog")


# -- regularity -----------------------------------------------------------------------------
@pytest.mark.parametrize("lagrangian", ["v", "x*v", "v - x**2/2", "-x**2/2"])
def test_first_order_lagrangian_failing_legendre_condition_is_refused(lagrangian):
    """∂²L/∂q̇² ≡ 0: a rule may still give an invertible D₁₂L_d at finite h (midpoint of
    L = V(q): −hV''/4) but it vanishes as h → 0, so the model is refused when built."""
    G, x, v = oscillator_symbols()
    L = sp.sympify(lagrangian, locals={"x": x, "v": v})
    with pytest.raises(ModelError) as info:
        Model("degenerate", G, lagrangian=L)
    message = str(info.value)
    assert "not regular" in message and "D₁₂L_d" in message and "x_dot" in message


@pytest.mark.parametrize("lagrangian", ["a", "v*a", "v*a + v**2/2", "v**2/2"])
def test_second_order_lagrangian_failing_legendre_condition_is_refused(lagrangian):
    """∂²L/∂q̈² ≡ 0 with the three-point rule: D₁₃L_d = h[… + L_aa/h⁴ + …] loses its
    leading term (for ½q̇² it is −1/(4h), invertible but degenerate as h → 0)."""
    G = PairGroupoid("x")
    (x,), (v,), (a,) = G.q, G.qdot, G.qddot
    L = sp.sympify(lagrangian, locals={"a": a, "v": v})
    with pytest.raises(ModelError) as info:
        Model("degenerate", G, lagrangian=L, discretisation="three_point")
    message = str(info.value)
    assert "not regular" in message and "D₁₃L_d" in message and "x_ddot" in message


@pytest.mark.parametrize("order", [1, 2])
def test_discrete_lagrangian_with_singular_step_jacobian_is_refused_at_compile(tmp_path, order):
    """A discrete Lagrangian given directly is checked on the derived step Jacobian:
    L_d = q₁ − q₀ (D₁₂L_d ≡ 0) and L_d = (q₂ − q₀)·q₁ (D₁₃L_d ≡ 0)."""
    G = PairGroupoid("x")
    nodes = [node[0] for node in G.nodes(order + 1)]
    Ld = nodes[1] - nodes[0] if order == 1 else (nodes[2] - nodes[0]) * nodes[1]
    model = Model("singular_ld", G, discrete_lagrangian=Ld, order=order)
    with pytest.raises(ModelError) as info:
        compile_model(model, tmp_path)
    message = str(info.value)
    which = "D₁₂L_d" if order == 1 else "D₁₃L_d"
    assert "not regular" in message and which in message and "rank 0 < 1" in message
    assert not (tmp_path / "singular_ld").exists()


# -- run time: Newton failures --------------------------------------------------------------
def assert_truncated_and_finite(result, K: int, steps_done: int):
    """Arrays hold the initial K nodes and the steps before the failing one, nothing else."""
    assert result.q.shape[0] == K + steps_done
    assert result.f.shape[0] == K - 1 + steps_done
    assert result.t.shape[0] == K + steps_done
    assert result.newton_iterations.shape == (steps_done,)
    assert result.momenta.shape[0] == result.q.shape[0]
    if result.energy is not None:
        assert result.energy.shape[0] == result.f.shape[0]
    for name in ("t", "q", "f", "momenta", "energy"):
        value = getattr(result, name)
        if value is not None:
            assert np.all(np.isfinite(value)), f"{name} contains non-finite values"


def test_newton_non_convergence_reports_step_and_residual(compiled):
    mod = compiled("pendulum")
    result = mod.integrate([[1.0], [1.0]], 100, 0.01, maxiter=1, xtol=1e-14)
    assert not result.success
    assert result.status == mod.Status.MAX_ITERATIONS
    assert re.search(r"\bstep 2 of 100\b", result.message), result.message
    assert "did not converge in 1 iteration" in result.message
    match = re.search(r"residual norm ([0-9.e+-]+)", result.message)
    assert match and float(match.group(1)) > 0
    assert_truncated_and_finite(result, K=2, steps_done=0)
    with pytest.raises(mod.NewtonError) as info:
        mod.integrate([[1.0], [1.0]], 100, 0.01, maxiter=1, xtol=1e-14, raise_on_failure=True)
    assert info.value.result.message == result.message
    assert "step 2 of 100" in str(info.value)


def fold_model():
    """L_d = (q₁ − q₀)³/h² − h q₀. Its discrete EL equation is d_{k+1}² = d_k² − h³/3 for
    the increments d_k = q_{k+1} − q_k: the step map exists while d_k² ≥ h³/3 and then
    has no real solution, at a step we can predict exactly."""
    G = PairGroupoid("x")
    (x0,), (x1,) = G.nodes(2)
    return Model("fold", G, discrete_lagrangian=(x1 - x0) ** 3 / h**2 - h * x0, order=1)


def test_newton_failure_mid_run_truncates_at_failing_step(tmp_path):
    mod = compile_model(fold_model(), tmp_path)
    step = 0.1
    d0 = math.sqrt(0.0105)          # d_{s+1}² = 0.0105 − (s+1)/3000 < 0 first for s = 31
    expected_failure = math.floor(3 * d0**2 / step**3)
    assert expected_failure == 31
    result = mod.integrate([[0.0], [d0]], 100, step)
    assert not result.success
    assert f"step {expected_failure + 2} of 100 " in result.message, result.message
    assert "residual norm" in result.message
    assert_truncated_and_finite(result, K=2, steps_done=expected_failure)
    # the part that was returned satisfies the recurrence d_{k+1}² = d_k² − h³/3
    d2 = np.diff(result.q[:, 0]) ** 2
    np.testing.assert_allclose(d2, d0**2 - np.arange(d2.size) * step**3 / 3, rtol=0, atol=1e-12)
    with pytest.raises(mod.NewtonError) as info:
        mod.integrate([[0.0], [d0]], 100, step, raise_on_failure=True)
    assert info.value.result.q.shape == result.q.shape


def test_singular_step_jacobian_is_reported(tmp_path):
    """L_d = (q₁ − q₀)³/h² + h q₀ is regular at generic points (D₁₂L_d = −6(q₁ − q₀)/h²)
    but from q₀ = q₁ the predictor q₂ = q₁ makes ∂R/∂q₂ exactly 0 while R = h ≠ 0."""
    G = PairGroupoid("x")
    (x0,), (x1,) = G.nodes(2)
    model = Model("cubic_increment", G, discrete_lagrangian=(x1 - x0) ** 3 / h**2 + h * x0,
                  order=1)
    mod = compile_model(model, tmp_path)
    result = mod.integrate([[1.0], [1.0]], 10, 0.1)
    assert result.status == mod.Status.SINGULAR_JACOBIAN
    assert "singular" in result.message and "step 2 of 10 " in result.message
    assert re.search(r"residual norm 1\.0+e-01", result.message), result.message
    assert_truncated_and_finite(result, K=2, steps_done=0)
    # away from the singular point the same model steps fine (d_{k+1}² = d_k² + h³/3)
    ok = mod.integrate([[1.0], [1.1]], 10, 0.1)
    assert ok.success, ok.message
    with pytest.raises(mod.NewtonError, match="singular"):
        mod.integrate([[1.0], [1.0]], 10, 0.1, raise_on_failure=True)


# -- run time: argument validation ----------------------------------------------------------
GOOD = dict(initial=[[1.0], [1.0]], n_steps=10, h=0.01)


@pytest.mark.parametrize("override, pattern", [
    (dict(initial=[[np.nan], [1.0]]), r"initial nodes.*non-finite.*nan.*\(0, 0\)"),
    (dict(initial=[[1.0], [np.inf]]), r"initial nodes.*non-finite.*inf.*\(1, 0\)"),
    (dict(initial=[[1.0], [1.0], [1.0]]), r"initial nodes.*shape \(3, 1\).*expected \(2, 1\)"),
    (dict(initial=[[1.0]]), r"initial nodes.*shape \(1, 1\).*expected \(2, 1\)"),
    (dict(initial=[["a"], [1.0]]), r"initial nodes.*numbers"),
    (dict(h=0.0), r"time step h must be positive.*0\.0"),
    (dict(h=-0.01), r"time step h must be positive.*-0\.01"),
    (dict(h=float("nan")), r"time step h must be positive and finite.*nan"),
    (dict(h=float("inf")), r"time step h must be positive and finite.*inf"),
    (dict(n_steps=0), r"n_steps must be at least 1 \(the initial data's element counts "
                          r"among the steps\), got 0"),
    (dict(n_steps=2.5), r"n_steps must be an integer"),
    (dict(params={"mass": 2.0}), r"unknown parameter.*'mass'.*\['m', 'l', 'g'\]"),
    (dict(params={"g": float("nan")}), r"parameter g must be finite"),
    (dict(params=[1.0, 2.0]), r"expected 3 parameter values"),
    (dict(maxiter=0), r"maxiter must be at least 1"),
    (dict(xtol=-1.0), r"xtol must be finite and non-negative"),
])
def test_bad_arguments_to_integrate(compiled, override, pattern):
    mod = compiled("pendulum")
    kwargs = {**GOOD, **override}
    with pytest.raises(ValueError, match=pattern):
        mod.integrate(kwargs.pop("initial"), kwargs.pop("n_steps"), kwargs.pop("h"), **kwargs)


def test_the_given_element_is_the_first_step(compiled):
    """n_steps counts the given element: one step returns the two nodes given, on [0, h]."""
    result = compiled("pendulum").integrate([[1.0], [1.0]], 1, 0.01)
    assert result.success and result.q.shape == (2, 1) and result.t[-1] == 0.01
    assert result.message == "integrated 1 step (the first given)"


@pytest.mark.parametrize("call, pattern", [
    (lambda m: m.solve_bvp(np.zeros((2, 2)), np.zeros((2, 2)), 3, 0.1),
     r"n_steps must be at least 4 \(2 fixed nodes at each end.*free node.*\), got 3"),
    (lambda m: m.solve_bvp(np.zeros((2, 2)), np.zeros((3, 2)), 10, 0.1),
     r"end nodes.*shape \(3, 2\).*expected \(2, 2\)"),
    (lambda m: m.solve_bvp(np.zeros((2, 2)), np.zeros((2, 2)), 10, 0.1, guess=np.zeros((3, 2))),
     r"guess.*shape \(3, 2\).*expected \(7, 2\)"),
    (lambda m: m.solve_bvp([[np.nan, 0], [0, 0]], np.zeros((2, 2)), 10, 0.1),
     r"start nodes.*non-finite"),
    (lambda m: m.solve_bvp(np.zeros((2, 2)), np.zeros((2, 2)), 10, -0.1),
     r"time step h must be positive"),
    (lambda m: m.solve_bvp(np.zeros((2, 2)), np.zeros((2, 2)), 10, 0.1, params={"gamma": 1}),
     r"unknown parameter.*'gamma'"),
])
def test_bad_arguments_to_solve_bvp(compiled, call, pattern):
    with pytest.raises(ValueError, match=pattern):
        call(compiled("spline_potential"))


@pytest.mark.parametrize("which", ["integrate", "solve_bvp"])
def test_transposed_nodes_are_refused(compiled, which):
    mod = compiled("cubic_spline")                   # nodes have shape (4, 2) / (2, 2)
    nodes = np.arange(8.0).reshape(4, 2)
    if which == "integrate":
        with pytest.raises(ValueError, match=r"shape \(2, 4\).*expected \(4, 2\)"):
            mod.integrate(nodes.T, 10, 0.1)                       # (2, 4) instead of (4, 2)
    else:
        with pytest.raises(ValueError, match=r"shape \(1, 4\).*expected \(2, 2\)"):
            mod.solve_bvp(nodes[:2], np.zeros((1, 4)), 10, 0.1)   # (1, 4) instead of (2, 2)


# -- build failures -------------------------------------------------------------------------
def test_compiler_error_is_reported_with_compiler_output(tmp_path, monkeypatch):
    monkeypatch.setattr(symvi.build, "COMPILE_ARGS",
                        [*symvi.build.COMPILE_ARGS, "-Werror=bogus-flag"])
    with pytest.raises(BuildError) as info:
        compile_model(get("harmonic_oscillator"), tmp_path)
    message = str(info.value)
    # gcc: "cc1: error: '-Werror=bogus-flag': no option '-Wbogus-flag'"; clang words it
    # differently but also names the flag.
    assert "bogus-flag" in message and "error" in message.lower()
    assert "compiler output" in message
    assert not isinstance(info.value, CompilerNotFoundError)
    # nothing half-built is left behind: no package, no scratch directory
    assert not (tmp_path / "harmonic_oscillator").exists()
    assert not list(tmp_path.glob(".harmonic_oscillator/build-*"))
    # and the real flags still build the model in the same directory afterwards
    monkeypatch.undo()
    mod = compile_model(get("harmonic_oscillator"), tmp_path)
    assert mod.integrate([[1.0], [1.0]], 10, 0.1).success


def test_missing_compiler_is_reported(tmp_path, monkeypatch):
    monkeypatch.setenv("CC", "/nonexistent/cc")
    with pytest.raises(CompilerNotFoundError) as info:
        compile_model(get("harmonic_oscillator"), tmp_path)
    message = str(info.value)
    assert "no C compiler" in message and "/nonexistent/cc" in message
    assert isinstance(info.value, BuildError)
    assert not (tmp_path / "harmonic_oscillator").exists()


@pytest.mark.parametrize("name", ["X0_0", "F0_0", "x_0", "f1_0"])
def test_parameter_named_like_internal_symbols_is_not_confused(tmp_path, name):
    """Slot and stencil coordinates are Dummy symbols, so no user name can alias them:
    the midpoint residual of L = v²/2 − k q²/2 at (0.1, 0.2, 0.3), h = 0.1, k = 2 is
    (2q₁ − q₀ − q₂)/h − h k (q₀ + 2q₁ + q₂)/4 = −0.04."""
    G, x, v = oscillator_symbols()
    k = sp.Symbol(name, real=True)
    model = Model(f"clash_{name.lower()}", G, lagrangian=v**2 / 2 - k * x**2 / 2,
                  parameters={k: 2.0})
    residual, _ = compile_model(model, tmp_path).evaluate("step", [0.1, 0.2, 0.3], 0.1)
    assert residual[0] == pytest.approx(-0.04, rel=1e-12)


def test_parameter_named_h_is_reserved():
    G, x, v = oscillator_symbols()
    hh = sp.Symbol("h", real=True)
    with pytest.raises(ModelError, match="reserved for the time step"):
        Model("bad", G, lagrangian=v**2 / 2 - hh * x**2, parameters={hh: 1.0})
