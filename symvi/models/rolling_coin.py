"""A vertical rolling coin with a steering torque: nonholonomic optimal control.

Contact point (x, y), heading θ and rolling angle φ of a coin of radius R rolling without
slipping: ẋ = R φ̇ cos θ, ẏ = R φ̇ sin θ — the distribution spanned by ρ₁ = (R cos θ,
R sin θ, 0, 1) (rolling, quasi-velocity φ̇ = w) and ρ₂ = (0, 0, 1, 0) (steering, ω).
L = ½ m (ẋ² + ẏ²) + ½ I θ̇² + ½ J φ̇². A rolling torque T_r and a steering torque T_s,
cost ½(T_r² + T_s²). Example: from rest at the origin facing +x to rest at (1, 1) facing
+y, rolled by φ = π (the quarter circle of radius 1 between them is π/2 long), T = 3,
N = 60.
"""
import numpy as np
import sympy as sp

from symvi import Example, PairGroupoid, distribution, nonholonomic_control

T, N = 3.0, 60
Q = PairGroupoid("x y theta phi")
x, y, theta, phi = Q.q
m, I, J, R = sp.symbols("m I J R", positive=True)
D = distribution(Q, [[R * sp.cos(theta), R * sp.sin(theta), 0, 1], [0, 0, 1, 0]],
                 "w omega", parameters=[R])
Tr, Ts = sp.symbols("T_r T_s", real=True)


def guess(s: np.ndarray) -> np.ndarray:
    """The quarter circle of radius 1 about (0, 1) at the normalised times s: nodes
    (x, y, θ, φ, w, ω), rolling at the speed it needs."""
    angle = np.pi / 2 * s
    speed = np.pi / 2 / T * np.sin(np.pi * s) * 2        # rest at both ends
    return np.stack([np.sin(angle), 1 - np.cos(angle), angle, np.pi * s, speed / 0.5,
                     np.gradient(angle, s) / T], axis=1)


model = nonholonomic_control(
    name="rolling_coin", D=D,
    lagrangian=m * (Q.qdot[0]**2 + Q.qdot[1]**2) / 2 + I * Q.qdot[2]**2 / 2
    + J * Q.qdot[3]**2 / 2,
    cost=(Tr**2 + Ts**2) / 2, controls=[Tr, Ts],
    parameters={m: 1.0, I: 0.25, J: 0.5, R: 0.5},
    example=Example(h=T / N, n_steps=N, start=np.zeros((1, 6)),
                    end=np.array([[1.0, 1.0, np.pi / 2, np.pi, 0.0, 0.0]]), guess=guess),
    description="Vertical rolling coin with rolling and steering torques: min ½∫T_r² + T_s², "
                "to (1, 1) after a quarter turn.")
