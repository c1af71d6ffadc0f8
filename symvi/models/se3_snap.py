"""Minimum snap in the Lie algebra on SE(3): L̃ = ½ (ξ⃛ᵀ diag(J, m) ξ⃛) (order 4).

Body angular and linear velocities ξ = (Ω, V); the pose's fourth derivative is ξ⃛ in body
coordinates, weighted by an inertia J and a mass m. Discretised by ``lie_central4``: ξ and
its derivatives at the centre of a window of four elements from the cubic through their
increments. Increments on any quintic ξ(t) are exact discrete solutions; the whole-trajectory solve between fixed first and last four poses is the
quadrotor planner's minimum-snap interpolation on SE(3).
"""
import math

import sympy as sp

from symvi import SE3, Example, Model


def _increments(h: float) -> list[list[float]]:
    """The first seven increments: a turn while climbing, ξ(t) = (0.3 sin t, 0.5 + 0.2 cos 2t,
    0.1, 1, 0.2 sin 3t, 0.2 + t²) at the elements' middles (its snap does not vanish)."""
    return [[0.3 * math.sin(t), 0.5 + 0.2 * math.cos(2 * t), 0.1, 1.0, 0.2 * math.sin(3 * t),
             0.2 + t * t] for t in ((k + 0.5) * h for k in range(7))]


def build(retraction: str = "cayley") -> Model:
    G = SE3(retraction=retraction)
    J1, J2, J3, m = sp.symbols("J1 J2 J3 m", positive=True)
    s = G.derivative(3)
    suffix = "" if retraction == "cayley" else f"_{retraction}"
    return Model(
        name=f"se3_snap{suffix}", groupoid=G,
        lagrangian=(J1 * s[0]**2 + J2 * s[1]**2 + J3 * s[2]**2
                    + m * (s[3]**2 + s[4]**2 + s[5]**2)) / 2,
        parameters={J1: 1.0, J2: 1.0, J3: 1.0, m: 1.0},
        example=Example(initial=(sp.eye(4).tolist(), _increments(0.01)), h=0.01, n_steps=200),
        description=f"Minimum snap in the Lie algebra on SE(3), order 4, {retraction} "
                    f"retraction.")


model = build()
