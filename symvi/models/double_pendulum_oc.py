"""Optimal control of a fully actuated double pendulum on the pair groupoid.

Torques u = EL(L) = d/dt ∂L/∂q̇ − ∂L/∂q at both joints; cost ½∫|u|² dt, so
L̃(q, q̇, q̈) = ½|EL(L)|², discretised by the three-point rule (DESIGN.md §3).

Example: from hanging at rest to (θ₁, θ₂) = (π/2, 0) at rest in T = 2, N = 200.
"""
import numpy as np
import sympy as sp

from symvi import Example, PairGroupoid, optimal_control

T, N = 2.0, 200
G = PairGroupoid("theta1 theta2")
(t1, t2), (w1, w2) = G.q, G.qdot
m1, m2, l1, l2, g = sp.symbols("m1 m2 l1 l2 g", positive=True)
u = sp.symbols("u1 u2", real=True)

kinetic = (m1 + m2) * l1**2 * w1**2 / 2 + m2 * l2**2 * w2**2 / 2 \
    + m2 * l1 * l2 * w1 * w2 * sp.cos(t1 - t2)
potential = -(m1 + m2) * g * l1 * sp.cos(t1) - m2 * g * l2 * sp.cos(t2)

model = optimal_control(
    name="double_pendulum_oc", groupoid=G, lagrangian=kinetic - potential,
    cost=(u[0] ** 2 + u[1] ** 2) / 2, controls=u,
    parameters={m1: 1.0, m2: 1.0, l1: 1.0, l2: 1.0, g: 9.81},
    example=Example(h=T / N, n_steps=N, start=np.zeros((2, 2)),
                    end=np.array([[np.pi / 2, 0.0]] * 2)),
    description="Optimal control of a fully actuated double pendulum: min ½∫|u|².")
