"""Pure minimum time of a double integrator with a force limit (issue 50): ẍ = u,
|u| ≤ u_max, from rest at x = 0 to rest at x = 1 in the least time T, the cost T alone.

The optimum is bang–bang: u = +u_max, then −u_max, T* = 2/√u_max. With no control cost
the Lagrangian is zero and carries no curvature; the interior point's barrier supplies
it, and the active-set Newton finishes on the vertex the bounds make (every window on its
bound but one; at even N the discrete T* is T* exactly, at odd N it converges at order 2:
3.8e-4 at N = 51, 3.9e-7 at N = 1601). The boundary data are States; the example starts
from T = 1, half the optimum (tests/test_horizon_newton.py). A small control cost
ε u²/2 beside ρT (``time_cost``) gives the regularised problem, T* − 2 = O(ε).
"""
import sympy as sp

from symvi import Example, PairGroupoid, State, optimal_control

G = PairGroupoid("x")
(v,) = G.qdot
u = sp.Symbol("u", real=True)
u_max = sp.Symbol("u_max", positive=True)

model = optimal_control(
    name="minimum_time_double_integrator", groupoid=G, lagrangian=v**2 / 2, cost=0,
    controls=[u], actuated=[0], parameters={u_max: 1.0}, time_cost=1,
    bounds={u: (-u_max, u_max)},
    example=Example(h=1.0 / 200, n_steps=200, start=State(x=[0.0], v=[0.0]),
                    end=State(x=[1.0], v=[0.0])),
    description="Pure minimum time of a double integrator, |u| ≤ u_max: min T, bang–bang, "
                "T* = 2/√u_max (issue 50)")
