"""A second-order model with a potential: L = ½|q̈|² + V(q), V = α|q|²/2 + β|q|⁴/4."""
import sympy as sp

from symvi import Example, Model, PairGroupoid

G = PairGroupoid("x y")
q, a = G.q, G.qddot
alpha, beta = sp.symbols("alpha beta", real=True)
r2 = sum(qi**2 for qi in q)

_h = 0.01
model = Model(
    name="spline_potential", groupoid=G,
    lagrangian=sum(ai**2 for ai in a) / 2 + alpha * r2 / 2 + beta * r2**2 / 4,
    discretisation="three_point",
    parameters={alpha: 1.0, beta: 0.5},
    # Fourth-order dynamics have growing modes (Ostrogradsky): keep the horizon short.
    example=Example(initial=[[1.0 - (k * _h) ** 2 / 2, k * _h] for k in range(4)],
                    h=_h, n_steps=300),
    description="Second-order model L = ½|q̈|² + α|q|²/2 + β|q|⁴/4, three-point rule.",
)
