"""Minimum-snap trajectories in space: L = ½|q⁽⁴⁾|² (order 4, rule ``central4``).

The discrete Euler–Lagrange equation is the eighth difference of the nodes = 0, the
discrete form of q⁽⁸⁾ = 0: samples of any polynomial of degree 7 are exact discrete
solutions, and the whole-trajectory solve between fixed first and last four nodes is the
minimum-snap interpolant of quadrotor trajectory planning.
"""
from symvi import Example, Model, PairGroupoid

G = PairGroupoid("x y z")

_h = 0.05
_septic = [[t - t**3 + 0.5 * t**7, 1 - t**2 + 0.1 * t**6, 0.2 * t**5 - t**4]
           for t in (k * _h for k in range(8))]
model = Model(
    name="minimum_snap", groupoid=G,
    lagrangian=sum(v**2 for v in G.derivative(4)) / 2,
    example=Example(initial=_septic, h=_h, n_steps=40),
    description="Minimum-snap trajectories L = ½|q''''|² in space, central differences on "
                "five nodes (order 4).",
)
