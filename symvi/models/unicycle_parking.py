"""Parallel parking of a unicycle: nonholonomic optimal control on D⁽²⁾ (issue 25).

Position (x, y) and heading θ; the wheel rolls without slipping sideways, so velocities lie
in the distribution spanned by ρ₁ = (cos θ, sin θ, 0) (drive, quasi-velocity v) and
ρ₂ = (0, 0, 1) (turn, ω). L = ½ m (ẋ² + ẏ²) + ½ J θ̇², a driving force F and a steering
torque τ (both actuated), cost ½(F² + τ²). Example: move sideways by 1 (a manoeuvre no
single motion along D achieves: it needs turning forward and back), at rest and facing
+x at both ends, T = 4, N = 80.
"""
import numpy as np
import sympy as sp

from symvi import Example, PairGroupoid, distribution, nonholonomic_control

T, N = 4.0, 80
Q = PairGroupoid("x y theta")
x, y, theta = Q.q
m, J = sp.symbols("m J", positive=True)
D = distribution(Q, [[sp.cos(theta), sp.sin(theta), 0], [0, 0, 1]], "v omega")
F, tau = sp.symbols("F tau", real=True)


def guess(s: np.ndarray) -> np.ndarray:
    """Forward while turning left, then back while turning right: nodes (x, y, θ, v, ω) at
    the normalised times s (on the straight line the sideways constraint has no
    gradient)."""
    return np.stack([0.3 * np.sin(2 * np.pi * s), s, 0.8 * np.sin(np.pi * s),
                     0.5 * np.cos(np.pi * s), 0.5 * np.sin(2 * np.pi * s)], axis=1)


model = nonholonomic_control(
    name="unicycle_parking", D=D,
    lagrangian=m * (Q.qdot[0]**2 + Q.qdot[1]**2) / 2 + J * Q.qdot[2]**2 / 2,
    cost=(F**2 + tau**2) / 2, controls=[F, tau], parameters={m: 1.0, J: 0.5},
    example=Example(h=T / N, n_steps=N, start=np.zeros((1, 5)),
                    end=np.array([[0.0, 1.0, 0.0, 0.0, 0.0]]), guess=guess),
    description="Parallel parking of a unicycle (drive force and steering torque): "
                "min ½∫F² + τ², sideways by 1.")
