"""Cubic splines: the second-order Lagrangian L = ½|q̈|² in the plane (three-point rule).

Its discrete Euler–Lagrange equation is the fourth difference = 0, so samples of any cubic
are exact discrete solutions (DESIGN.md §5).
"""
from symvi import Example, Model, PairGroupoid

G = PairGroupoid("x y")
a = G.qddot

_h = 0.1
_cubic = [[(k * _h) ** 3 - k * _h, 1 - 2 * (k * _h) ** 2] for k in range(4)]
model = Model(
    name="cubic_spline", groupoid=G,
    lagrangian=sum(ai**2 for ai in a) / 2,
    discretisation="three_point",
    example=Example(initial=_cubic, h=_h, n_steps=1_000),
    description="Cubic splines L = ½|q̈|² in the plane, three-point rule.",
)
