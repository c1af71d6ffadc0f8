"""A cart-pole catching its pole (issue 21, end conditions): the pole starts at rest
0.3 rad off the upright, and at T = 2 it must be upright and at rest with the cart at
rest — wherever the cart is. The cart's force is limited, |u| ≤ u_max, and the cost is
½∫u² dt.

The end is given by the conditions ψ = (θ, θ̇, ẋ) = 0 on the last element (midpoint rule),
not by fixed nodes: the last two nodes are unknowns and the cart's final position is
part of the optimum: the cart runs under the pole and brakes, ending 1.27 to the right at
N = 200 (1.01 without the limit). Without the limit the force peaks at 8.4; with
u_max = 5 it saturates for the first 0.23 s.
``res.end_multipliers`` holds the multipliers ν of ψ.
"""
import numpy as np
import sympy as sp

from symvi import Example, optimal_control
from symvi.models.cart_pole_oc import G, LAGRANGIAN, PARAMETERS

T, N = 2.0, 200
(x, theta), (v, omega) = G.q, G.qdot
u = sp.Symbol("u", real=True)
u_max = sp.Symbol("u_max", positive=True)

model = optimal_control(
    name="cart_pole_catch", groupoid=G, lagrangian=LAGRANGIAN, cost=u**2 / 2,
    controls=[u], actuated=[0], parameters=PARAMETERS | {u_max: 5.0},
    bounds={u: (-u_max, u_max)},
    end={"upright": theta, "pole at rest": omega, "cart at rest": v},
    example=Example(h=T / N, n_steps=N, start=np.array([[0.0, 0.3], [0.0, 0.3]]), end=None),
    description="Cart-pole catching a pole tilted 0.3 rad: upright and at rest at T = 2, "
                "the cart's position free, |u| ≤ u_max (end conditions, issue 21)")
