"""Riemannian cubics in the Lie algebra on SO(3): L̃(ξ, ξ̇) = ½|ξ̇|² (second order).

The second-order discrete Euler–Poincaré equations of paper §3.1 (eq. ``sdfinal``
discretisation). One-parameter subgroups g(t) = g₀ exp(tX) are exact solutions (ξ
constant), and the whole-trajectory solve with fixed g₀, g₁, g_{N−1}, g_N interpolates
attitudes with minimal mean squared angular acceleration.
"""
import sympy as sp

from symvi import SO3, Example, Model

G = SO3()

model = Model(
    name="so3_cubic", groupoid=G,
    lagrangian=sum(v**2 for v in G.xidot) / 2,
    example=Example(initial=(sp.eye(3).tolist(), [[0.3, 1.0, 0.2], [0.3, 1.001, 0.202],
                                                 [0.3, 1.002, 0.204]]), h=0.01, n_steps=1000),
    description="Riemannian cubics in the Lie algebra on SO(3), second-order Euler-Poincare, "
                "Cayley retraction.",
)
