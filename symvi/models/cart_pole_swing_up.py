"""A cart-pole swing-up with a force limit and a track-length limit (issue 21).

The cart-pole of :mod:`symvi.models.cart_pole_oc` — cart position x, actuated by a force
u; pole angle θ from the upright, unactuated — swung up from hanging (θ = π) to upright
(θ = 0), the cart at x = 0 and at rest at both ends, in T = 2.5, minimising ½∫u² dt, with
|u| ≤ u_max = 14 and the cart on a track |x| ≤ d = 0.8 (at every window's quadrature
point). Without limits the swing-up needs a peak force of 14.9 and runs the cart out to
x = 0.92; with them the force saturates on 11 of 249 windows at N = 250 and the cart
touches the end of its track (tests/test_bounded_cart_pole.py: the same optimum as
SLSQP's on the same discrete problem).

The pole's equation EL(L)_θ = 0 is a second-order constraint with a multiplier per
window, so the interior-point solve carries equality constraints beside the bounds, and
its steps an inertia correction (``_runtime/bounded/interior.py``). There are other local
optima: some perturbed guesses swing the pole round the other way (cost 20.47 at
N = 250, no limit active). At N = 1000 it succeeds from 18 of 22 guesses of the
robustness battery (README, "Bounds and path inequalities").
"""
import numpy as np
import sympy as sp

from symvi import Example, optimal_control
from symvi.models.cart_pole_oc import LAGRANGIAN, PARAMETERS, G, u, x

T, N = 2.5, 250
u_max, d = sp.symbols("u_max d", positive=True)

model = optimal_control(
    name="cart_pole_swing_up", groupoid=G, lagrangian=LAGRANGIAN,
    cost=u**2 / 2, controls=[u], actuated=[0],
    parameters=PARAMETERS | {u_max: 14.0, d: 0.8},
    bounds={u: (-u_max, u_max), x: (-d, d)},
    example=Example(h=T / N, n_steps=N, start=np.array([[0.0, np.pi]] * 2),
                    end=np.zeros((2, 2))),
    description="Cart-pole swing-up with |u| ≤ u_max and the cart on a track |x| ≤ d: "
                "min ½∫u² (issue 21)")
