"""A planar free-flying body on SE(2) with a forward-only thruster, around a keep-out disc
(issue 21).

The body (rotation rate ω and body velocities v₁ forward, v₂ sideways; inertia I, mass m)
flies from rest at the origin to rest at (4, 0), heading along x at both ends, in T = 4,
minimising ½∫(τ² + f₁² + f₂²) dt for the torque τ and the body-frame forces f₁, f₂
(u = EL(l), fully actuated). The main thruster only pushes, 0 ≤ f₁ ≤ f_max; the side
thrusters and the torque are limited to |f₂| ≤ side, |τ| ≤ τ_max. A disc of radius r
about (2, 0.2) is out of bounds: the straight flight passes through it.

The keep-out disc is a path inequality on a base point: the model is the action groupoid
R²×SE(2) whose base point is the disc's centre seen from the body, c = g⁻¹·centre (the
same disc on the world position of ``ActionGroupoid.on_itself(SE2())`` gives the same
optimum, ``tests/test_configuration.py``): it moves with the increments as
c_{k+1} = w_k⁻¹·c_k (a right action), and the disc is r² − |c|² ≤ 0 at every window's
middle node. Without the bounds the body brakes with its main thruster (f₁ < 0 on 107 of
199 windows); the interior point started there stalls, and succeeds from that optimum
moved toward the bounds by a quadratic penalty (``_runtime/bounded/penalty.py``).
"""
import numpy as np
import sympy as sp

from symvi import SE2, ActionGroupoid, Example, optimal_control

T, N = 4.0, 200
CENTRE = (2.0, 0.2)


def seen_from_the_body(c, W):
    """c ↦ W⁻¹·c for W = [[R, t], [0, 1]] ∈ SE(2): Rᵀ(c − t)."""
    return W[:2, :2].T * (c - W[:2, 2])


def pose(x: float, y: float, heading: float) -> np.ndarray:
    c, s = np.cos(heading), np.sin(heading)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def boundary():
    """(base points, configurations) of the two fixed nodes at each end, at rest."""
    centre = np.r_[CENTRE, 1.0]
    ends = []
    for g in (pose(0.0, 0.0, 0.0), pose(4.0, 0.0, 0.0)):
        c = np.linalg.solve(g, centre)[:2]
        ends.append((np.array([c, c]), np.stack([g, g])))
    return ends


G = ActionGroupoid(SE2(), "c1 c2", seen_from_the_body, label="R2xSE2")
(omega, v1, v2), (c1, c2) = G.xi, G.q
I, m, r, tau_max, f_max, side = sp.symbols("I m r tau_max f_max side", positive=True)
tau, f1, f2 = sp.symbols("tau f1 f2", real=True)
start, end = boundary()

model = optimal_control(
    name="planar_flyer", groupoid=G,
    lagrangian=(I * omega**2 + m * (v1**2 + v2**2)) / 2,
    cost=(tau**2 + f1**2 + f2**2) / 2, controls=[tau, f1, f2], actuated=[0, 1, 2],
    parameters={I: 0.5, m: 1.0, r: 0.7, tau_max: 10.0, f_max: 10.0, side: 5.0},
    bounds={tau: (-tau_max, tau_max), f1: (0, f_max), f2: (-side, side)},
    inequalities={"keep-out": r**2 - (c1**2 + c2**2)},
    example=Example(h=T / N, n_steps=N, start=start, end=end),
    description="Planar flyer on SE(2): forward-only thruster, |f2| ≤ side, |τ| ≤ τ_max, "
                "around a keep-out disc: min ½∫|u|² (issue 21)")
