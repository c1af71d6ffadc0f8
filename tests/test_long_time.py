"""Convergence order and long-time behaviour of the first-order midpoint integrators.

* Global error at a fixed time T for h = T/N must decrease like h² (the midpoint rule is
  second order). The second node q₁ is taken from the exact / reference solution, so the
  starting value does not spoil the order.
* The discrete energy error over 10⁶ steps must stay bounded (no drift): its maximum over
  the last tenth of the run is at most 1.1 × its maximum over the first tenth.
* Discrete momenta p_k (first-order Legendre transforms) agree with m·ẋ(t_k) to O(h²).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

EPS = np.finfo(float).eps
T = 10.0
NS = [100 * 2**k for k in range(5)]          # h = 0.1 … 0.00625

# Harmonic oscillator (bundled defaults m = k = 1): x(t) = x₀ cos t + v₀ sin t.
X0, V0 = 1.0, 0.5


def ho_exact(t):
    return X0 * np.cos(t) + V0 * np.sin(t)


def ho_velocity(t):
    return -X0 * np.sin(t) + V0 * np.cos(t)


# Pendulum (bundled defaults m = l = 1, g = 9.81): θ'' = −(g/l) sin θ, large amplitude.
TH0, W0, G_OVER_L = 1.0, 0.0, 9.81


@pytest.fixture(scope="module")
def pendulum_reference():
    sol = solve_ivp(lambda t, y: [y[1], -G_OVER_L * math.sin(y[0])], (0.0, T), [TH0, W0],
                    method="DOP853", rtol=1e-12, atol=1e-12, dense_output=True)
    assert sol.success
    return lambda t: sol.sol(t)[0]


def fitted_order(hs, errors) -> float:
    return float(np.polyfit(np.log(hs), np.log(errors), 1)[0])


def global_errors(mod, exact, n_values):
    hs, errors = [], []
    for N in n_values:
        h = T / N
        result = mod.integrate([[exact(0.0)], [exact(h)]], N, h)
        assert result.success, result.message
        assert result.q.shape == (N + 1, 1)
        assert result.t[-1] == pytest.approx(T)
        hs.append(h)
        errors.append(abs(result.q[-1, 0] - exact(T)))
    return np.array(hs), np.array(errors)


# -- convergence order ----------------------------------------------------------------------
def test_harmonic_oscillator_converges_with_order_two(compiled):
    hs, errors = global_errors(compiled("harmonic_oscillator"), ho_exact, NS)
    slope = fitted_order(hs, errors)
    print(f"\nharmonic oscillator, midpoint: errors at T = {T}: "
          f"{', '.join(f'{e:.3e}' for e in errors)}; fitted order {slope:.4f}")
    assert abs(slope - 2.0) <= 0.1
    # every halving of h reduces the error by about 4
    ratios = errors[:-1] / errors[1:]
    assert np.all((ratios > 3.5) & (ratios < 4.5)), ratios


def test_pendulum_converges_with_order_two(compiled, pendulum_reference):
    hs, errors = global_errors(compiled("pendulum"), pendulum_reference, NS)
    slope = fitted_order(hs, errors)
    print(f"\npendulum, midpoint: errors at T = {T}: "
          f"{', '.join(f'{e:.3e}' for e in errors)}; fitted order {slope:.4f}")
    assert abs(slope - 2.0) <= 0.1
    # the reference is far more accurate than the finest run
    assert errors[-1] > 1e3 * 1e-10


def test_first_order_start_spoils_nothing_only_with_accurate_q1(compiled):
    """Control for the set-up above: with a crude start q₁ = q₀ + h·v₀ (error O(h²) per
    step, i.e. O(h) in the momentum) the global error is visibly larger than with the
    exact q₁, so the tests above do depend on taking q₁ from the exact solution."""
    mod = compiled("harmonic_oscillator")
    N = 400
    h = T / N
    good = mod.integrate([[X0], [ho_exact(h)]], N, h).q[-1, 0]
    crude = mod.integrate([[X0], [X0 + h * V0]], N, h).q[-1, 0]
    assert abs(crude - ho_exact(T)) > 5 * abs(good - ho_exact(T))


# -- energy over 10⁶ steps ------------------------------------------------------------------
def energy_tenths(result):
    assert result.success, result.message
    e = np.abs(result.energy - result.energy[0])
    tenth = e.size // 10
    return e, float(e[:tenth].max()), float(e[-tenth:].max())


def test_harmonic_oscillator_energy_does_not_drift(compiled):
    """For a quadratic L the midpoint discrete energy E_d = m v²/2 + k q̄²/2 is an exact
    invariant of the step map, so |E_k − E_0| is pure round-off: a random walk of size
    ~ε√k·E₀. The 1.1 criterion is applied with that round-off allowance added
    (10·ε·√(steps)·E₀ ≈ 1.4·10⁻¹²); any true drift (∝ k) would exceed it by orders of
    magnitude."""
    mod = compiled("harmonic_oscillator")
    h, steps = 0.05, 10**6
    result = mod.integrate([[X0], [ho_exact(h)]], steps, h)
    e, first, last = energy_tenths(result)
    E0 = abs(result.energy[0])
    allowance = 10 * EPS * math.sqrt(steps) * E0
    print(f"\nharmonic oscillator energy, 10^6 steps h = {h}: E0 = {E0:.15g}, max |E−E0| "
          f"first tenth {first:.3e}, last tenth {last:.3e}, overall {e.max():.3e} "
          f"(round-off allowance {allowance:.1e})")
    assert E0 == pytest.approx(0.5 * (X0**2 + V0**2), rel=1e-3)
    assert last <= 1.1 * first + allowance
    assert e.max() <= 1e3 * EPS * math.sqrt(steps) * E0


def test_pendulum_energy_does_not_drift(compiled, pendulum_reference):
    mod = compiled("pendulum")
    h, steps = 0.01, 10**6
    result = mod.integrate([[TH0], [pendulum_reference(h)]], steps, h)
    e, first, last = energy_tenths(result)
    E0 = result.energy[0]
    print(f"\npendulum energy, 10^6 steps h = {h}: E0 = {E0:.12g}, max |E−E0| first tenth "
          f"{first:.6e}, last tenth {last:.6e}, ratio {last / first:.6f}")
    # E = ½θ̇² − g cos θ at θ = 1, θ̇ = 0, up to the O(h²) of the discrete energy
    assert E0 == pytest.approx(-G_OVER_L * math.cos(TH0), abs=1e-2)
    # the energy error is an O(h²) oscillation, not round-off: the criterion is meaningful
    assert first > 1e-6
    assert last <= 1.1 * first
    assert e.max() <= 1e-2 * abs(E0)


def test_trapezoid_oscillator_energy_oscillates_but_does_not_drift(tmp_path):
    """Same criterion where the energy error is a genuine O(h²) oscillation: the
    harmonic oscillator with the trapezoid rule (Störmer–Verlet), whose discrete energy
    is not an exact invariant."""
    import sympy as sp

    from symvi import Model, PairGroupoid
    from symvi.build import compile_model

    G = PairGroupoid("x")
    (x,), (v,) = G.q, G.qdot
    k = sp.Symbol("k", positive=True)
    model = Model("ho_trapezoid", G, lagrangian=v**2 / 2 - k * x**2 / 2,
                  discretisation="trapezoid", parameters={k: 1.0})
    mod = compile_model(model, tmp_path)
    h, steps = 0.05, 10**6
    result = mod.integrate([[X0], [ho_exact(h)]], steps, h)
    e, first, last = energy_tenths(result)
    print(f"\ntrapezoid oscillator energy, 10^6 steps h = {h}: max |E−E0| first tenth "
          f"{first:.6e}, last tenth {last:.6e}, ratio {last / first:.6f}")
    assert first > 1e-5                 # O(h²) oscillation, far above round-off
    assert last <= 1.1 * first
    assert e.max() <= 10 * h**2


# -- momenta --------------------------------------------------------------------------------
def test_harmonic_oscillator_momenta_match_exact_to_second_order(compiled):
    mod = compiled("harmonic_oscillator")
    scaled, errors, hs = [], [], []
    for N in NS:
        h = T / N
        result = mod.integrate([[X0], [ho_exact(h)]], N, h)
        assert result.success, result.message
        assert result.momenta.shape == (N + 1, 1)
        exact = 1.0 * ho_velocity(result.t)          # p = m ẋ with m = 1
        err = float(np.abs(result.momenta[:, 0] - exact).max())
        errors.append(err)
        hs.append(h)
        scaled.append(err / h**2)
    slope = fitted_order(hs, errors)
    print(f"\nharmonic oscillator momenta: max |p_k − m ẋ(t_k)| = "
          f"{', '.join(f'{e:.3e}' for e in errors)}; / h² = "
          f"{', '.join(f'{s:.4f}' for s in scaled)}; fitted order {slope:.4f}")
    assert abs(slope - 2.0) <= 0.1
    assert max(scaled) <= 2.0


def test_momenta_scale_with_mass(compiled):
    """p = m ẋ: doubling the mass parameter (run-time override) doubles the momenta of the
    same path; with k doubled too the exact path is unchanged."""
    mod = compiled("harmonic_oscillator")
    N = 400
    h = T / N
    initial = [[X0], [ho_exact(h)]]
    base = mod.integrate(initial, N, h)
    heavy = mod.integrate(initial, N, h, params={"m": 2.0, "k": 2.0})
    np.testing.assert_allclose(heavy.q, base.q, rtol=0, atol=1e-13)
    np.testing.assert_allclose(heavy.momenta, 2.0 * base.momenta, rtol=1e-12, atol=1e-14)
