"""The Chaplygin sled steered by a torque: nonholonomic optimal control, underactuated.

A planar body (x, y, θ) on a knife edge at distance a behind its centre of mass: the edge
cannot slip sideways, so the centre of mass moves with ẋ = u cos θ − a ω sin θ,
ẏ = u sin θ + a ω cos θ, θ̇ = ω — the distribution spanned by ρ₁ = (cos θ, sin θ, 0)
(forward, u) and ρ₂ = (−a sin θ, a cos θ, 1) (turning about the edge, ω). L = ½ m (ẋ² +
ẏ²) + ½ I θ̇². Only the turning is actuated (a torque τ, cost ½τ²); the forward equation
of motion m u̇ = m a ω² is a constraint: the sled moves forward by wiggling, and since
u̇ ≥ 0 it can never stop again. Example: from rest, reach at T = 6 the state (x, y, θ, u,
ω) that the wiggling torque τ = ½ sin(4πt/T) reaches (computed with scipy's solve_ivp to
1e-12), at least cost: the optimum is below that torque's ½∫τ² = 0.375. N = 120.
"""
import numpy as np
import sympy as sp

from symvi import Example, PairGroupoid, distribution, nonholonomic_control

T, N = 6.0, 120
Q = PairGroupoid("x y theta")
x, y, theta = Q.q
m, I, a = sp.symbols("m I a", positive=True)
D = distribution(Q, [[sp.cos(theta), sp.sin(theta), 0],
                     [-a * sp.sin(theta), a * sp.cos(theta), 1]], "u omega", parameters=[a])
tau = sp.Symbol("tau", real=True)


#: The state the torque ½ sin(4πt/T) reaches from rest at T = 6.
END = np.array([0.09430511, 2.82923551, 1.46398604, 0.69379529, -0.43247856])


def guess(s: np.ndarray) -> np.ndarray:
    """The straight line between the ends in (x, y, θ, u, ω), at the normalised times s."""
    return s[:, None] * END[None, :]


model = nonholonomic_control(
    name="chaplygin_sled", D=D,
    lagrangian=m * (Q.qdot[0]**2 + Q.qdot[1]**2) / 2 + I * Q.qdot[2]**2 / 2,
    cost=tau**2 / 2, controls=[tau], actuated=[1],
    parameters={m: 1.0, I: 0.2, a: 0.5},
    example=Example(h=T / N, n_steps=N, start=np.zeros((1, 5)), end=END[None], guess=guess),
    description="Chaplygin sled steered by a torque (forward motion unactuated): "
                "min ½∫τ² to a state a wiggle reaches.")
