"""The horizon inside Newton (issue 50, item 2): a free final time is one more unknown of
the whole-trajectory Newton system (``_runtime/bvp/bordered.py``), with inequalities of
the interior point's too (``_runtime/bounded/interior.py``).

Checked against exact optima: the double integrator min ∫ε u²/2 + ρT between States has
J*(T) in closed form, so T* is known to rounding; the spin-up with a free horizon is
exact at every N (``test_end_conditions``). The bordered matrix's row is taken as its
column's transpose: checked here by differentiating the horizon equation along random
node variations. The cart-pole's optimal horizon is checked against fixed-horizon
solves of the bundled ``cart_pole_oc`` around it.
"""
from __future__ import annotations

import importlib

import numpy as np
import pytest
import sympy as sp
from scipy.optimize import minimize_scalar

from symvi import Example, PairGroupoid, State, optimal_control
from symvi.build import compile_model
from symvi.models.cart_pole_oc import G as CART_POLE, LAGRANGIAN, PARAMETERS, u as FORCE


def double_integrator(name="double_integrator_timed", timed=True, bounded=False):
    """min ∫ε u²/2 (+ ρT where ``timed``) of ẍ = u, with |u| ≤ u_max where ``bounded``."""
    G = PairGroupoid("x")
    (v,) = G.qdot
    u = sp.Symbol("u", real=True)
    eps, rho, u_max = sp.symbols("epsilon rho u_max", positive=True)
    return optimal_control(
        name=name, groupoid=G, lagrangian=v**2 / 2, cost=eps * u**2 / 2, controls=[u],
        actuated=[0], parameters={eps: 1.0, rho: 1.0, u_max: 1.0},
        time_cost=rho if timed else None, bounds={u: (-u_max, u_max)} if bounded else None,
        example=Example(h=0.02, n_steps=100, start=np.zeros((2, 1)), end=np.ones((2, 1))))


def cart_pole_timed():
    rho = sp.Symbol("rho", positive=True)
    return optimal_control(
        name="cart_pole_timed", groupoid=CART_POLE, lagrangian=LAGRANGIAN,
        cost=FORCE**2 / 2, controls=[FORCE], actuated=[0],
        parameters=PARAMETERS | {rho: 1.0}, time_cost=rho,
        example=Example(h=0.01, n_steps=200, start=np.zeros((2, 2)),
                        end=np.array([[1.0, 0.0]] * 2)))


@pytest.fixture(scope="module")
def models(build_dir):
    return {"di": compile_model(double_integrator(), build_dir),
            "cart": compile_model(cart_pole_timed(), build_dir),
            "bounded": compile_model(double_integrator("double_integrator_bounded_timed",
                                                       bounded=True), build_dir),
            "fixed": compile_model(double_integrator("double_integrator_bounded",
                                                     timed=False, bounded=True), build_dir)}


def exact_horizon(v0: float, eps: float, rho: float) -> float:
    """T* of min ε/2 ∫u² + ρT, x(0) = 0, ẋ(0) = v0, x(T) = 1, ẋ(T) = 0: the least ∫u²
    of a double integrator is (12a² − 12abT + 4b²T²)/T³, a = 1 − v0 T, b = −v0."""
    def F(T):
        a, b = 1.0 - v0 * T, -v0
        return eps / 2 * (12 * a * a - 12 * a * b * T + 4 * b * b * T * T) / T**3 + rho * T
    return float(minimize_scalar(F, bounds=(0.2, 10.0), method="bounded",
                                 options=dict(xatol=1e-13)).x)


@pytest.mark.parametrize("v0", [0.0, 0.7])
def test_the_horizon_converges_at_order_two_from_states(models, v0):
    """From States (at rest, and leaving at speed 0.7) the optimal horizon converges to
    the continuous T* at order 2 (measured 2.000), each solve one Newton iteration count
    whatever N (the outer secant took 10–14 solves)."""
    exact = exact_horizon(v0, 1.0, 1.0)
    sizes = (25, 50, 100, 200, 400)
    errors, iterations = [], []
    for N in sizes:
        r = models["di"].solve_bvp(State(x=[0.0], v=[v0]), State(x=[1.0], v=[0.0]), N, T=2.0)
        assert r.success, r.message
        assert r.T == r.t_states[-1] and "free horizon T" in r.message
        errors.append(abs(r.T - exact))
        iterations.append(r.iterations)
    orders = np.log2(np.array(errors[:-1]) / errors[1:])
    print(f"\nv0 = {v0}: T* = {exact:.12f}, errors {np.array(errors)}, orders {orders}, "
          f"iterations {iterations}")
    assert np.all(np.abs(orders - 2.0) < 0.05)
    assert max(iterations) <= 8


@pytest.mark.parametrize("ratio", [1.0, 1e2, 1e4])
@pytest.mark.parametrize("first", [0.5, 3.0])
def test_time_weights_and_first_guesses(models, ratio, first):
    """ε u² + ρT with ρ/ε from 1 to 10⁴ (the secant STALLed from ρ ≥ 100 ε), from first
    horizons T*/2 and 3T*: SUCCESS at the discrete optimum, the same from both guesses
    (to the tolerance), within O(h²) of the continuous T*."""
    eps, rho, N = 1.0 / ratio, 1.0, 200
    exact = exact_horizon(0.0, eps, rho)
    r = models["di"].solve_bvp(State(x=[0.0], v=[0.0]), State(x=[1.0], v=[0.0]), N,
                               T=first * exact, params=dict(epsilon=eps, rho=rho))
    assert r.success, r.message
    assert abs(r.T - exact) <= 1.0 / N**2, (r.T, exact)
    other = models["di"].solve_bvp(State(x=[0.0], v=[0.0]), State(x=[1.0], v=[0.0]), N,
                                   T=exact, params=dict(epsilon=eps, rho=rho))
    assert abs(r.T - other.T) <= 1e-9 * (1 + exact), (r.T, other.T)


def runtime_of(mod, stage: str):
    return importlib.import_module(f"{type(mod.model).__module__.rsplit('.', 1)[0]}.{stage}")


def test_the_border_row_is_the_columns_transpose(models):
    """The design's premise: ∂G/∂(node variation) = ∂R/∂T (R the gradient of ℒ, G its
    T-derivative; both times T in σ = log T), measured on the cart-pole with random
    multipliers at a non-optimal path, G differentiated along random corrections by
    central differences."""
    mod = models["cart"]
    bordered = runtime_of(mod, "bvp.bordered")
    paths = runtime_of(mod, "core.paths")
    N, T = 40, 2.0
    p = mod.model.params(None)
    start, end = np.zeros((2, 2)), np.array([[1.0, 0.0]] * 2)
    path = paths.initial_path(mod.model, start, end, N, None, p, T / N)
    from dataclasses import replace
    path = replace(path, T=T)
    problem = bordered.HorizonProblem(mod.model, p, N)
    rng = np.random.default_rng(3)
    size = problem.assemble(path, False)[0].size
    path = problem.moved(path, np.append(0.05 * rng.standard_normal(size - 1), 0.0), 1.0)
    path.lam[:] = rng.standard_normal(path.lam.shape)
    problem.assemble(path, True)
    b, _ = problem.border
    for _ in range(3):
        w = np.append(rng.standard_normal(size - 1), 0.0)
        step = 1e-6
        sides = [problem.horizon_gradient(problem.moved(path, w, s)) for s in (step, -step)]
        row = (sides[0] - sides[1]) / (2 * step)
        # the unknown is σ = log T: the border holds T ∂R/∂T, the row T ∂G/∂η
        assert path.T * row == pytest.approx(float(b @ w[:-1]), rel=1e-7)


def test_cart_pole_horizon_is_where_fixed_horizon_solves_are_cheapest(models, compiled):
    """At the returned T*, F(T) = J*(T) + ρT sampled by fixed-horizon solves of the bundled
    ``cart_pole_oc`` (the same discrete problem at h = T/N) is smallest: a parabola
    through the samples has its vertex at T* (to 1e-6), and the costs agree at T*."""
    N = 60
    free, fixed = models["cart"], compiled("cart_pole_oc")
    start, end = np.zeros((2, 2)), np.array([[1.0, 0.0]] * 2)
    r = free.solve_bvp(start, end, N, T=2.0)
    assert r.success, r.message
    same = fixed.solve_bvp(start, end, N, T=r.T)
    assert same.success and abs(same.cost - r.cost) <= 1e-9 * r.cost
    offsets = np.array([-2e-4, -1e-4, 0.0, 1e-4, 2e-4])
    F = np.array([fixed.solve_bvp(start, end, N, T=r.T + d, guess=same).cost + r.T + d
                  for d in offsets])
    a, b, _ = np.polyfit(offsets, F, 2)
    print(f"\nT* = {r.T:.10f} ({r.iterations} iterations); vertex at {-b / (2 * a):+.1e}")
    assert F[2] <= F.min() + 1e-12 * F[2]
    assert abs(b / (2 * a)) <= 1e-6


REST = (State(x=[0.0], v=[0.0]), State(x=[1.0], v=[0.0]))


def test_bounded_minimum_time_from_states_converges_at_order_two(models):
    """|u| ≤ 1, min ∫u²/2 + T from States at rest (the force limit active on both
    arcs): SUCCESS at every N from 50 to 800, the bounds held to 1e-9, T converging at
    order 2 (measured 1.98–2.04); from first horizons half and three times T*, the same
    T to the tolerance."""
    sizes, horizons = (50, 100, 200, 400, 800), []
    for N in sizes:
        r = models["bounded"].solve_bvp(*REST, N, T=2.0)
        assert r.success, r.message
        assert np.abs(r.controls).max() <= 1.0 + 1e-9
        assert np.isclose(np.abs(r.controls).max(), 1.0, atol=1e-9), "the limit is active"
        horizons.append(r.T)
        for first in (0.5, 3.0):
            other = models["bounded"].solve_bvp(*REST, N, T=first * r.T)
            assert other.success and abs(other.T - r.T) <= 1e-8, (N, first, other.message)
    differences = np.abs(np.diff(horizons))
    orders = np.log2(differences[:-1] / differences[1:])
    print(f"\nT*(N = {sizes}) = {np.array(horizons)}; orders {orders}")
    assert np.all(np.abs(orders - 2.0) < 0.2)


def test_bounded_horizon_is_where_fixed_horizon_solves_are_cheapest(models):
    """The same discrete problem with the horizon fixed (an independent solve, the
    interior point at fixed h): F(T) = J*(T) + ρT around the returned T* is smallest there
    (a parabola through the samples has its vertex at T*, to 1e-6), and J* agrees."""
    N = 100
    r = models["bounded"].solve_bvp(*REST, N, T=2.0)
    assert r.success, r.message
    same = models["fixed"].solve_bvp(*REST, N, T=r.T)
    assert same.success and abs(same.cost - r.cost) <= 1e-9 * r.cost, same.message
    offsets = np.array([-2e-4, -1e-4, 0.0, 1e-4, 2e-4])
    F = []
    for d in offsets:
        fixed = models["fixed"].solve_bvp(*REST, N, T=r.T + d)
        assert fixed.success, fixed.message
        F.append(fixed.cost + r.T + d)
    a, b, _ = np.polyfit(offsets, F, 2)
    print(f"\nT* = {r.T:.10f} ({r.iterations} iterations); vertex at {-b / (2 * a):+.1e}")
    assert F[2] <= min(F) + 1e-12 * F[2]
    assert abs(b / (2 * a)) <= 1e-6


@pytest.mark.parametrize("ratio", [1.0, 1e2, 1e4])
def test_bounded_time_weights_all_succeed(models, ratio):
    """ε u²/2 + ρT, |u| ≤ 1, ρ/ε from 1 to 10⁴ (the outer secant STALLed from
    ρ/ε = 100 on): SUCCESS at N = 50 and 400, from the nodes at rest and from States;
    at ρ/ε = 10⁴ the control is bang–bang (|u| = 1 but at the switch) and T is the pure
    minimum time 2 to O(ε²)."""
    params = dict(epsilon=1.0 / ratio)
    for N in (50, 400):
        for ends in (REST, (np.zeros((2, 1)), np.ones((2, 1)))):
            r = models["bounded"].solve_bvp(*ends, N, T=2.0, params=params)
            assert r.success, (N, r.message)
            assert np.abs(r.controls).max() <= 1.0 + 1e-9
        if ratio == 1e4:
            u = np.abs(models["bounded"].solve_bvp(*REST, N, T=2.0, params=params).controls)
            assert (u < 1.0 - 1e-6).sum() <= 2
    if ratio == 1e4:
        assert abs(models["bounded"].solve_bvp(*REST, 400, T=2.0, params=params).T - 2.0) <= 1e-8


def test_minimum_time_slew_from_states(compiled):
    """The bundled minimum-time slew on SO(3) from States at rest: SUCCESS, the horizon
    converging at order about 2 (measured 2.1, 2.3 over N = 50 … 400; from nodes at rest,
    order 1), the torque limits held."""
    from symvi.models import get

    mod, ex = compiled("minimum_time_slew"), get("spacecraft_slew").example
    ends = State(g=ex.start[0], v=[0, 0, 0]), State(g=ex.end[-1], v=[0, 0, 0])
    horizons = []
    for N in (50, 100, 200, 400):
        r = mod.solve_bvp(*ends, N, T=1.0)
        assert r.success, r.message
        assert np.abs(r.controls).max() <= 11.0 * (1 + 1e-9)
        horizons.append(r.T)
    differences = np.abs(np.diff(horizons))
    orders = np.log2(differences[:-1] / differences[1:])
    print(f"\nT* = {np.array(horizons)}; orders {orders}")
    assert np.all(orders > 1.8)


@pytest.mark.parametrize("bounded", [False, True])
def test_loose_tolerances_and_far_first_horizons_are_honest(models, bounded):
    """The false-success hunt of the bordered horizon: at xtol = 1e-2 a first horizon of
    T*/10 once returned SUCCESS at T = 0.025 for T* = 0.21 (cost 40 for 0.07): Newton
    moves a far T by about T/4 per iteration, corrections far below the distance, within
    xtol·(1 + size) of nodes of size 1. Every SUCCESS, for xtol 1e-2 … 1e-6 and first
    horizons T*/10 … 3T*, now lies within the tolerance of the tight optimum — nodes,
    bound multipliers and log T (the unknown: T's relative error)."""
    mod, N = models["bounded" if bounded else "di"], 50
    params = dict(epsilon=1e-4)
    ends = (np.zeros((2, 1)), np.ones((2, 1)))
    best = mod.solve_bvp(*ends, N, T=1.0, params=params, xtol=1e-10)
    assert best.success, best.message

    def unknowns(r):
        return [r.x] + ([r.bound_multipliers] if bounded else [])
    size = max(float(np.abs(u).max()) for u in unknowns(best))
    for first in (0.1, 0.3, 3.0):
        for xtol in (1e-2, 1e-4, 1e-6):
            r = mod.solve_bvp(*ends, N, T=first * best.T, params=params, xtol=xtol)
            assert r.success, (first, xtol, r.message)
            error = max([float(np.abs(a - b).max()) for a, b in
                         zip(unknowns(r), unknowns(best))] + [abs(np.log(r.T / best.T))])
            assert error <= xtol * (1 + size), (first, xtol, error, r.T, best.T)


def test_perturbed_starts_go_on_from_the_optimum_without_bounds(models):
    """Where the interior point from a perturbed guess stalls at μ = 10 (primal
    infeasibility 4 on a double integrator with |u| ≤ 0.5 between moving ends, first
    horizon 10 T*), the solve goes on from the optimum without bounds — T free there too
    — and ends at the optimum the unperturbed start finds (path and T to the
    tolerance)."""
    N, params = 30, dict(epsilon=0.01, u_max=0.5)
    ends = (np.array([[0.0], [0.02]]), np.array([[0.98], [1.0]]))
    best = models["bounded"].solve_bvp(*ends, N, T=2.0, params=params, xtol=1e-12)
    assert best.success, best.message
    rng = np.random.default_rng(0)
    for _ in range(3):
        guess = best.x[2:-2] + 0.3 * rng.standard_normal((N - 3, 1))
        r = models["bounded"].solve_bvp(*ends, N, T=10 * best.T, params=params, guess=guess)
        assert r.success, r.message
        assert abs(np.log(r.T / best.T)) <= 1e-8 and np.abs(r.x - best.x).max() <= 1e-8


def test_verbose_shows_the_horizon(models, capsys):
    """``verbose=True``: each Newton iteration's line carries T (at its start) where it
    is an unknown, as the result's ``history`` does."""
    r = models["di"].solve_bvp(*REST, 50, T=1.0, verbose=True)
    lines = capsys.readouterr().err.splitlines()[2:]
    assert r.success and len(lines) == len(r.history["T"]) in (r.iterations, r.iterations + 1)
    assert all("  T " in ln for ln in lines) and f"T {r.T:.10g}: SUCCESS" in lines[-1]
    assert r.history["T"][0] == 1.0 and abs(r.history["T"][-1] - r.T) <= 1e-8 * r.T
