"""Harmonic oscillator L = m q̇²/2 − k q²/2 (first order, midpoint rule)."""
import math

import sympy as sp

from symvi import Example, Model, PairGroupoid, State

G = PairGroupoid("x")
(x,), (v,) = G.q, G.qdot
m, k = sp.symbols("m k", positive=True)

_h = 0.05
model = Model(
    name="harmonic_oscillator", groupoid=G,
    lagrangian=m * v**2 / 2 - k * x**2 / 2,
    discretisation="midpoint",
    parameters={m: 1.0, k: 1.0},
    example=Example(initial=[[1.0], [math.cos(_h)]], h=_h, n_steps=10_000,
                    state=State(v=[0.0], x=[1.0])),
    description="Harmonic oscillator L = m v²/2 − k x²/2, midpoint rule.",
)
