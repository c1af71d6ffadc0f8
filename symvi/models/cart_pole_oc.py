"""Optimal control of a cart-pole (underactuated) on the pair groupoid.

Cart position x (actuated by a force u), pole angle θ from the upright (unactuated):
L = ½(M+m)ẋ² + m ℓ ẋ θ̇ cos θ + ½ m ℓ² θ̇² − m g ℓ cos θ. The cost ½∫u² dt with
u = EL(L)_x gives L̃; the pole's equation EL(L)_θ = 0 is a second-order constraint with
a multiplier per window (paper §3.3.2).

Example: move the cart by 1 with the pole upright and everything at rest at both ends,
T = 2, N = 200.
"""
import numpy as np
import sympy as sp

from symvi import Example, PairGroupoid, optimal_control

T, N = 2.0, 200
G = PairGroupoid("x theta")
(x, th), (v, w) = G.q, G.qdot
M, m, ell, g = sp.symbols("M m ell g", positive=True)
u = sp.Symbol("u", real=True)
#: The cart-pole's Lagrangian and parameters (shared with :mod:`.cart_pole_swing_up`).
LAGRANGIAN = (M + m) * v**2 / 2 + m * ell * v * w * sp.cos(th) + m * ell**2 * w**2 / 2 \
    - m * g * ell * sp.cos(th)
PARAMETERS = {M: 1.0, m: 0.3, ell: 0.5, g: 9.81}

model = optimal_control(
    name="cart_pole_oc", groupoid=G, lagrangian=LAGRANGIAN,
    cost=u**2 / 2, controls=[u], actuated=[0], parameters=PARAMETERS,
    example=Example(h=T / N, n_steps=N, start=np.zeros((2, 2)),
                    end=np.array([[1.0, 0.0]] * 2)),
    description="Optimal control of a cart-pole (force on the cart only): min ½∫u².")
