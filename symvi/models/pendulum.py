"""Simple pendulum L = m l² θ̇²/2 + m g l cos θ (first order, midpoint rule)."""
import sympy as sp

from symvi import Example, Model, PairGroupoid, State

G = PairGroupoid("theta")
(theta,), (omega,) = G.q, G.qdot
m, l, g = sp.symbols("m l g", positive=True)

model = Model(
    name="pendulum", groupoid=G,
    lagrangian=m * l**2 * omega**2 / 2 + m * g * l * sp.cos(theta),
    discretisation="midpoint",
    parameters={m: 1.0, l: 1.0, g: 9.81},
    example=Example(initial=[[1.0], [1.0]], h=0.01, n_steps=100_000,
                    state=State(v=[0.0], x=[1.0])),
    description="Simple pendulum L = m l² θ̇²/2 + m g l cos θ, midpoint rule.",
)
