"""Invalid input is never a success (issue 18, findings 2, 6, 7 and 8).

* Model names that would shadow a module, or that do not import as written, are refused.
* Expressions symvi cannot compile (non-smooth, undefined functions, complex, not finite,
  functions C lacks) are refused with a message naming them.
* A step map that is not defined at the data is SINGULAR_JACOBIAN, not a constant path;
  outputs that are not finite make the result NON_FINITE; numbers must be numbers.
* Requests too large for memory are refused before allocating; ``keep_every`` stores every
  k-th node of the same run, bitwise; Ctrl-C stops a long run within a second.
"""
from __future__ import annotations

import importlib
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
import sympy as sp

from symvi import Model, ModelError, PairGroupoid
from symvi.build import compile_model


def pendulum_symbols():
    G = PairGroupoid("theta")
    return G, G.q[0], G.qdot[0]


# -- declaration -----------------------------------------------------------------------------
@pytest.mark.parametrize("name, reason", [
    ("math", "standard library"), ("json", "standard library"),
    ("numpy", "installed package 'numpy'"), ("cffi", "installed package 'cffi'"),
    ("sympy", "installed package 'sympy'"), ("symvi", "symvi itself"),
    ("ﬁle", "imports it as 'file'"),           # U+FB01: NFKC-normalised on import
    ("class", "public Python identifier"), ("_private", "public Python identifier"),
])
def test_model_names_that_shadow_or_do_not_import_are_refused(name, reason):
    G, theta, omega = pendulum_symbols()
    with pytest.raises(ModelError, match="model name") as info:
        Model(name, G, lagrangian=omega**2 / 2)
    assert reason in str(info.value)
    if "taken" in str(info.value):
        assert f"'{name}_model'" in str(info.value)          # a name is suggested


@pytest.mark.parametrize("make, pattern", [
    (lambda th, om: om**2 / 2 + sp.Abs(th), r"not twice differentiable.*Abs\(theta\)"),
    (lambda th, om: sp.Abs(om) ** 3, r"not twice differentiable.*Abs\(theta_dot\)"),
    (lambda th, om: om**2 / 2 - sp.Max(th, 0) ** 2, r"not twice differentiable.*Max"),
    (lambda th, om: om**2 / 2 + sp.Function("V")(th), r"undefined function.*V\(theta\)"),
    (lambda th, om: sp.I * om**2, r"complex.*contains I"),
    (lambda th, om: sp.nan * om**2, r"not finite"),
    (lambda th, om: om**2 / 2 + sp.zoo * th, r"not finite"),
    (lambda th, om: om**2 / 2 + sp.Derivative(sp.cos(th), th), r"unevaluated Derivative"),
])
def test_lagrangians_symvi_cannot_compile_are_refused_by_name(make, pattern):
    G, theta, omega = pendulum_symbols()
    with pytest.raises(ModelError, match=pattern):
        Model("bad", G, lagrangian=make(theta, omega))


def test_kinks_in_parameters_only_are_smooth():
    G, theta, omega = pendulum_symbols()
    k = sp.Symbol("k", real=True)
    Model("fine", G, lagrangian=omega**2 / 2 - sp.Abs(k) * theta**2, parameters={k: -1.0})


def test_function_without_c_implementation_is_named_at_compile(tmp_path):
    G, theta, omega = pendulum_symbols()
    model = Model("bessel", G, lagrangian=omega**2 / 2 + sp.besselj(0, theta))
    with pytest.raises(ModelError, match=r"kernel 'step'.*besselj.*C99"):
        compile_model(model, tmp_path)
    assert not (tmp_path / "bessel").exists()


# -- run time: undefined step maps and non-finite outputs ------------------------------------
@pytest.fixture(scope="module")
def unsigned_pendulum(build_dir):
    """The pendulum with parameters declared real only, so that m = 0 and l = 0 reach the
    solver (the bundled one declares them positive, and refuses them by name)."""
    G = PairGroupoid("theta")
    (theta,), (omega,) = G.q, G.qdot
    m, l, g = sp.symbols("m l g", real=True)
    model = Model("pendulum_unsigned", G, lagrangian=m * l**2 * omega**2 / 2
                  + m * g * l * sp.cos(theta), parameters={m: 1.0, l: 1.0, g: 9.81})
    return compile_model(model, build_dir)


@pytest.mark.parametrize("params", [{"l": 0.0}, {"m": 0.0}])
def test_undefined_step_map_is_singular_not_a_constant_path(compiled, unsigned_pendulum,
                                                            params):
    """L ≡ 0 (l = 0 or m = 0): every q_2 solves R = 0; that is no step map. Declared
    positive (the bundled pendulum), those values are refused before anything runs."""
    name = next(iter(params))
    with pytest.raises(ValueError, match=f"parameter {name} is declared positive"):
        compiled("pendulum").integrate([[1.0], [1.0]], 100, 0.01, params=params)
    mod = unsigned_pendulum
    result = mod.integrate([[1.0], [1.0]], 100, 0.01, params=params)
    assert result.status == mod.Status.SINGULAR_JACOBIAN, result.message
    assert "step 2 of 100" in result.message and "not defined" in result.message
    assert result.q.shape == (2, 1)
    bvp = mod.solve_bvp([[0.0]], [[1.0]], 50, 0.02, params=params)
    assert bvp.status == mod.Status.SINGULAR_JACOBIAN, bvp.message


def test_non_finite_energy_is_not_a_success(compiled):
    """q₀ = 10²⁰⁰: the path stays finite but ω² and the energy overflow."""
    mod = compiled("pendulum")
    result = mod.integrate([[1e200], [1.0]], 100, 0.01)
    assert result.status == mod.Status.NON_FINITE, result.message
    assert "energies" in result.message and "not finite" in result.message
    assert not np.isfinite(result.energy).all()
    with pytest.raises(mod.NewtonError, match="not finite"):
        mod.integrate([[1e200], [1.0]], 100, 0.01, raise_on_failure=True)


def test_non_finite_cost_is_not_a_success(compiled):
    mod = compiled("pendulum")
    result = mod.solve_bvp([[1e200]], [[1.0]], 50, 0.02)
    assert not result.success and "not finite" in result.message, result.message


@pytest.mark.parametrize("override, pattern", [
    (dict(params={"l": "2.0"}), r"parameter l must be a real number, got '2\.0'"),
    (dict(params={"l": True}), r"parameter l must be a real number, got True"),
    (dict(params={"l": 1 + 2j}), r"parameter l must be a real number"),
    (dict(params="l=2"), r"params must be a mapping"),
    (dict(params=5), r"params must be a mapping"),
    (dict(initial=[[True], [1.0]]), r"initial nodes.*element True of type bool"),
    (dict(initial=np.array([[True], [False]])), r"initial nodes.*real numbers, got booleans"),
    (dict(initial=np.array([["1"], [1.0]], dtype=object)), r"initial nodes.*element '1'"),
    (dict(initial=[[1.0 + 0j], [1.0]]), r"initial nodes.*complex"),
    (dict(h="0.01"), r"time step h must be a real number"),
    (dict(h=True), r"time step h must be a real number"),
    (dict(n_steps=True), r"n_steps must be an integer"),
    (dict(n_steps=np.float64(10)), r"n_steps must be an integer"),
    (dict(maxiter=2**31), r"maxiter must be at most 2147483647"),
    (dict(xtol="1e-3"), r"xtol must be a real number"),
    (dict(keep_every=0), r"keep_every must be at least 1"),
])
def test_numbers_must_be_numbers(compiled, override, pattern):
    mod = compiled("pendulum")
    args = {"initial": [[1.0], [1.01]], "n_steps": 10, "h": 0.01, **override}
    with pytest.raises(ValueError, match=pattern):
        mod.integrate(args.pop("initial"), args.pop("n_steps"), args.pop("h"), **args)


def test_object_arrays_of_numbers_are_numbers(compiled):
    mod = compiled("pendulum")
    nodes = np.array([[1.0], [1.01]], dtype=object)
    assert mod.integrate(nodes, 10, 0.01).success


# -- memory, thinning and interrupts ---------------------------------------------------------
def test_requests_beyond_memory_are_refused_before_allocating(compiled):
    mod = compiled("pendulum")
    start = time.perf_counter()
    with pytest.raises(MemoryError) as info:
        mod.integrate([[1.0], [1.01]], 10**9, 0.01)
    message = str(info.value)
    assert "1,000,000,001 nodes" in message and "GiB" in message and "keep_every=" in message
    with pytest.raises(MemoryError, match=r"N = 1,000,000,000 needs about .* GiB"):
        mod.solve_bvp([[0.0]], [[1.0]], 10**9, 1e-9)
    assert time.perf_counter() - start < 1.0       # nothing was allocated or touched


def runtime_module(mod, name: str):
    """The generated package's own copy of a run-time module."""
    return importlib.import_module(f"{mod.__name__}._runtime.{name}")


@pytest.mark.parametrize("name", [
    "spherical_pendulum",           # action groupoid with a symmetry (noether)
    "cubic_spline",                 # second order: momenta (E, 2, n)
])
def test_keep_every_stores_every_kth_node_of_the_same_run(compiled, monkeypatch, name):
    """Thinned, chunked and unchunked runs are one run: every stored array is the full
    run's at the kept nodes, bitwise, across chunk boundaries (chunks forced small)."""
    from symvi.models import get

    mod, example, k = compiled(name), get(name).example, 7
    n = 5000
    full = mod.integrate(example.initial, n, example.h)
    stepping = runtime_module(mod, "step.stepping")
    monkeypatch.setattr(stepping, "BUFFER_STEPS", 1000)
    monkeypatch.setattr(stepping, "CHUNK_SECONDS", 1e-7)      # many chunks of 1024 steps
    chunked = mod.integrate(example.initial, n, example.h)
    thin = mod.integrate(example.initial, n, example.h, keep_every=k)
    assert full.success and thin.success, (full.message, thin.message)
    r, K = mod.model.order, mod.model.stencil_elements
    offsets = {"t": 0, "x": 0, "f": 0, "momenta": 0, "energy": 0, "noether": r - 1,
               "newton_iterations": K}
    for field, offset in offsets.items():
        whole = getattr(full, field)
        if whole is None:
            continue
        np.testing.assert_array_equal(getattr(chunked, field), whole, err_msg=field)
        np.testing.assert_array_equal(getattr(thin, field), whole[(-offset) % k::k],
                                      err_msg=field)
    if full.g is not None:
        np.testing.assert_array_equal(thin.g, full.g[::k])
    if full.noether is not None:       # the conserved quantity is conserved, thinned too
        assert np.ptp(thin.noether) < 1e-12 * (1 + np.abs(thin.noether).max())


def test_failed_thinned_run_stops_at_the_failing_step(compiled):
    mod = compiled("pendulum")
    full = mod.integrate([[1.0], [1.0]], 100, 0.01, maxiter=1, xtol=1e-14)
    thin = mod.integrate([[1.0], [1.0]], 100, 0.01, maxiter=1, xtol=1e-14, keep_every=3)
    assert thin.status == full.status and thin.message == full.message
    np.testing.assert_array_equal(thin.q, full.q[::3])


INTERRUPTED = textwrap.dedent("""
    import signal, sys, time
    # Python keeps SIGINT ignored when it starts with it ignored (a background job of a
    # non-interactive shell): install the handler an interactive session has
    signal.signal(signal.SIGINT, signal.default_int_handler)
    sys.path.insert(0, sys.argv[1])
    import pendulum
    pendulum.integrate([[1.0], [1.01]], 10, 0.01)       # warm up
    print("integrating", flush=True)
    try:
        pendulum.integrate([[1.0], [1.01]], 10**8, 0.01)
    except KeyboardInterrupt:
        print("interrupted", flush=True)
""")


def test_ctrl_c_stops_a_long_integration_within_a_second(compiled, build_dir):
    compiled("pendulum")
    proc = subprocess.Popen([sys.executable, "-c", INTERRUPTED, str(build_dir)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"})
    assert proc.stdout.readline().strip() == "integrating"
    time.sleep(1.0)                                # well inside the 10⁸ steps (~10 s)
    sent = time.perf_counter()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    latency = time.perf_counter() - sent
    assert "interrupted" in out, err
    print(f"\nCtrl-C latency: {latency * 1e3:.0f} ms")
    assert latency < 1.0


# -- declarations refuse what run-time arguments refuse (issue 48, finding 6) ------------------
@pytest.mark.parametrize("value", ["1.0", True, np.bool_(False), b"2", np.array("1.5")])
def test_parameter_defaults_that_are_not_numbers_are_refused_in_the_run_times_words(value):
    """A string or boolean default was silently converted (``"1.0"`` → 1.0, True → 1.0)
    where ``integrate(..., params={"k": "1.0"})`` refuses it: the declaration now refuses
    it with the run time's own message."""
    from symvi._runtime.core.arguments import real
    G, theta, omega = pendulum_symbols()
    k = sp.Symbol("k", real=True)
    with pytest.raises(ValueError) as runtime:
        real(value, "parameter k")
    with pytest.raises(ModelError) as declared:
        Model("spring", G, lagrangian=omega**2 / 2 - k * theta**2 / 2, parameters={k: value})
    assert str(declared.value) == str(runtime.value)
    for number in (2, np.float64(2.0), sp.Rational(1, 2), sp.Float(0.5)):   # still numbers
        model = Model("spring", G, lagrangian=omega**2 / 2 - k * theta**2 / 2,
                      parameters={k: number})
        assert model.parameter_defaults == (float(number),)


@pytest.mark.parametrize("declare, message", [
    (dict(time_cost="1"), "time_cost must be a real number or an expression in the "
                          "parameters, got '1'"),
    (dict(time_cost=True), "time_cost must be a real number or an expression in the "
                           "parameters, got True"),
    (dict(bounds={"tau1": ("-1", 1)}), "lower bound of control tau1 must be a real number "
                                       "or an expression in the parameters, got '-1'"),
])
def test_time_cost_and_bounds_that_are_not_numbers_are_refused(declare, message):
    """``time_cost="1"`` was parsed to ρ = 1 without a word."""
    from symvi import SO3, optimal_control
    G = SO3()
    u = sp.symbols("tau1 tau2 tau3", real=True)
    Omega = sp.Matrix(G.xi)
    with pytest.raises(ModelError) as info:
        optimal_control("bad", G, (Omega.T * Omega)[0] / 2, sum(v**2 for v in u) / 2, u,
                        **declare)
    assert str(info.value) == message


def test_derivative_takes_sympy_and_numpy_integers_and_refuses_other_types():
    """``G.derivative(sp.Integer(3))`` was refused with "derivative(3): … go from 0 to 5",
    contradicting itself; SymPy and NumPy integers are integers, a bool or a float is
    refused as such, and a range error names the range."""
    from symvi import SO3
    G, S = PairGroupoid(["x", "y"]), SO3()
    assert G.derivative(sp.Integer(3)) == G.derivative(3) == G.derivative(np.int64(3))
    assert S.derivative(sp.Integer(3)) == S.derivative(np.int32(3)) == S.derivative(3)
    assert G.derivative(sp.Integer(1)) == G.qdot and S.derivative(np.int8(0)) == S.xi
    for bad, kind in [(True, "bool"), (np.bool_(True), "bool"), (3.0, "float"),
                      (sp.Float(3), "Float"), (sp.Rational(3, 2), "Rational"), ("3", "str"),
                      (None, "NoneType")]:
        with pytest.raises(ModelError, match=f"must be an integer, got {kind}$"):
            G.derivative(bad)
    with pytest.raises(ModelError, match=r"^derivative\(6\): .* go from 0 to 5"):
        S.derivative(sp.Integer(6))
    with pytest.raises(ModelError, match=r"^derivative\(-1\): .* go from 0 to 6"):
        G.derivative(np.int64(-1))
