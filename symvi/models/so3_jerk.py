"""Minimum jerk in the Lie algebra on SO(3): L̃(ξ, ξ̇, ξ̈) = ½ ξ̈ᵀIξ̈ (order 3).

The order-3 analogue of :mod:`so3_cubic` (the attitude's third derivative is ξ̈ in body
coordinates), discretised by ``lie_central3``: ξ and its derivatives at the centre of a
window of three elements from the quadratic through their increments. Increments ξ_k on
any cubic ξ(t) (degree 2k − 3) are exact discrete solutions (the gradient of the action
sum in each increment, a fourth difference of ξ, vanishes), one-parameter subgroups among
them.
"""
import math

import sympy as sp

from symvi import SO3, Example, Model


def _increments(h: float) -> list[list[float]]:
    """The first five increments: ξ(t) = (0.3 + 0.5 sin 2t, 1 + 0.3 cos 3t, 0.2 + t) at the
    elements' middles (a path whose jerk does not vanish)."""
    return [[0.3 + 0.5 * math.sin(2 * t), 1.0 + 0.3 * math.cos(3 * t), 0.2 + t]
            for t in ((k + 0.5) * h for k in range(5))]


def build(retraction: str = "cayley") -> Model:
    G = SO3(retraction=retraction)
    I1, I2, I3 = sp.symbols("I1 I2 I3", positive=True)
    xi2 = G.derivative(2)
    suffix = "" if retraction == "cayley" else f"_{retraction}"
    return Model(
        name=f"so3_jerk{suffix}", groupoid=G,
        lagrangian=(I1 * xi2[0]**2 + I2 * xi2[1]**2 + I3 * xi2[2]**2) / 2,
        parameters={I1: 1.0, I2: 1.0, I3: 1.0},
        example=Example(initial=(sp.eye(3).tolist(), _increments(0.01)), h=0.01, n_steps=200),
        description=f"Minimum jerk in the Lie algebra on SO(3), order 3, {retraction} "
                    f"retraction.")


model = build()
