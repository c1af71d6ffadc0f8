"""Minimum-jerk trajectories in space: L = ½|q⃛|² (order 3, rule ``central3``).

The discrete Euler–Lagrange equation is the sixth difference of the nodes = 0, the
discrete form of q⁽⁶⁾ = 0: samples of any quintic are exact discrete solutions, and the
whole-trajectory solve between fixed first and last three nodes (position, velocity and
acceleration at each end) is the minimum-jerk interpolant used in robot motion planning.
"""
from symvi import Example, Model, PairGroupoid

G = PairGroupoid("x y z")

_h = 0.05
_quintic = [[t - 2 * t**3 + t**5, 1 - t**2 + 0.5 * t**4, 0.2 * t**3]
            for t in (k * _h for k in range(6))]
model = Model(
    name="minimum_jerk", groupoid=G,
    lagrangian=sum(v**2 for v in G.derivative(3)) / 2,
    example=Example(initial=_quintic, h=_h, n_steps=40),
    description="Minimum-jerk trajectories L = ½|q'''|² in space, central differences on "
                "four nodes (order 3).",
)
