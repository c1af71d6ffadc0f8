"""Planar double pendulum with point masses (first order, midpoint rule)."""
import sympy as sp

from symvi import Example, Model, PairGroupoid, State

G = PairGroupoid("theta1 theta2")
(t1, t2), (w1, w2) = G.q, G.qdot
m1, m2, l1, l2, g = sp.symbols("m1 m2 l1 l2 g", positive=True)

kinetic = (m1 + m2) * l1**2 * w1**2 / 2 + m2 * l2**2 * w2**2 / 2 \
    + m2 * l1 * l2 * w1 * w2 * sp.cos(t1 - t2)
potential = -(m1 + m2) * g * l1 * sp.cos(t1) - m2 * g * l2 * sp.cos(t2)

model = Model(
    name="double_pendulum", groupoid=G,
    lagrangian=kinetic - potential,
    discretisation="midpoint",
    parameters={m1: 1.0, m2: 1.0, l1: 1.0, l2: 1.0, g: 9.81},
    example=Example(initial=[[0.5, -0.3], [0.5, -0.3]], h=0.005, n_steps=100_000,
                    state=State(v=[0.0, 0.0], x=[0.5, -0.3])),
    description="Double pendulum (point masses m1, m2 on massless rods l1, l2), midpoint rule.",
)
