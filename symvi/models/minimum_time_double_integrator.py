"""Minimum time of a double integrator with a force limit (issue 50): ẍ = u, |u| ≤ u_max,
from rest at x = 0 to rest at x = 1, min ∫ε u²/2 dt + ρT with the horizon T free.

As ε/ρ → 0 this is the pure minimum-time problem, whose optimum is bang–bang (u = +u_max,
then −u_max) with T* = 2√(1/u_max) = 2; the small control cost ε keeps the optimality
system regular and moves T* little (T* − 2 = 5.0e-5 at ε = 0.01, N = 200, 6.6e-10 at
ε = 10⁻⁴). The boundary data are States, so the horizon converges at order 2 in N (from
nodes, order 1); the example starts from T = 1, half the optimum
(tests/test_horizon_newton.py). Where the discrete optimum is a vertex — every window on
its bound, T fixed by the bounds alone (ε = 0.01 at N = 100: T = 2 exactly) — the
multipliers are not unique and the solve takes a few hundred iterations.
"""
import sympy as sp

from symvi import Example, PairGroupoid, State, optimal_control

G = PairGroupoid("x")
(v,) = G.qdot
u = sp.Symbol("u", real=True)
epsilon, rho, u_max = sp.symbols("epsilon rho u_max", positive=True)

model = optimal_control(
    name="minimum_time_double_integrator", groupoid=G, lagrangian=v**2 / 2,
    cost=epsilon * u**2 / 2, controls=[u], actuated=[0],
    parameters={epsilon: 1e-2, rho: 1.0, u_max: 1.0}, time_cost=rho,
    bounds={u: (-u_max, u_max)},
    example=Example(h=1.0 / 200, n_steps=200, start=State(x=[0.0], v=[0.0]),
                    end=State(x=[1.0], v=[0.0])),
    description="Minimum time of a double integrator, |u| ≤ u_max: min ∫ε u²/2 + ρT, "
                "bang–bang as ε → 0 (T* = 2) (issue 50)")
