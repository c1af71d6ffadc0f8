"""Optimal control of a heavy top with two internal rotors (paper §3.3.5, ERRATA 4–6).

The transformation algebroid R³×so(3)×T(S¹×S¹): the action groupoid of SO(3) on the
direction of gravity Γ (Γ·R = RᵀΓ) times the pair groupoid of the rotor angles θ. The
reduced Lagrangian l(Γ, Ω, θ̇) is the paper's, with γ_i = Ī_i + J_i. Only the rotors are
actuated (u_i = J_i(Ω̇_i + θ̈_i)); the three equations of the top are the constraints
Φ^A = EL(l)_A = 0 (derived here; the paper's printed ones have the slips of ERRATA 4).
Cost ½∫(u₁² + u₂²) dt. Discretisation: paper's rule (midpoints of ξ, second differences
of θ) with Γ at the middle node, the group-consistent Γ update Γ_{k+1} = cay(hξ_k)ᵀΓ_k
(ERRATA 6).

Example: from rest, upright (Γ = e₃), tilt the top by 0.2 rad about its first axis and
come to rest again, in T = 2 with N = 200 steps.

``build(equations="variational")`` (bundled as ``heavy_top_rotors_oc_variational``)
discretises the controlled equations as the forced discrete Euler–Lagrange equations of
the first-order L_d instead (:mod:`symvi.declaration.control`). The top's unactuated equations conserve
the vertical momentum Γ·∂l/∂Ω (the rotor torques are internal); that discretisation keeps
the identity exactly, so the declared symmetry Z = (Γ, 0, 0) is an exact dependency of the
constraints, which the solver removes. It is the formulation to use for motions that are
not planar at large N.
"""
import numpy as np
import sympy as sp

from symvi import (SO3, ActionGroupoid, Example, PairGroupoid, ProductGroupoid, Symmetry,
                   optimal_control)

T, N, TILT = 2.0, 200, 0.2


def _rotation_x(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def boundary(h: float = T / N):
    """Fixed nodes 0, 1 and N−1, N: (base points (Γ, θ), attitudes) at rest."""
    e3, R = np.array([0.0, 0.0, 1.0]), _rotation_x(TILT)
    theta_end = np.array([-1.0, 0.0])
    x_start = np.array([np.r_[e3, 0.0, 0.0]] * 2)
    x_end = np.array([np.r_[R.T @ e3, theta_end]] * 2)
    return (x_start, np.stack([np.eye(3)] * 2)), (x_end, np.stack([R] * 2))


def build(retraction: str = "cayley", equations: str = "paper"):
    top = ActionGroupoid(SO3(retraction=retraction), "Gamma1 Gamma2 Gamma3",
                         lambda q, W: W.T * q, label="R3xSO3")
    G = ProductGroupoid(top, PairGroupoid("theta1 theta2"))
    Omega, Gamma = sp.Matrix(top.xi), sp.Matrix(top.q)
    rates = sp.Matrix(list(Omega) + list(G.factors[1].qdot))
    g1, g2, I3, J1, J2, Mgh = sp.symbols("gamma1 gamma2 I3bar J1 J2 Mgh", positive=True)
    inertia = sp.Matrix([[g1, 0, 0, J1, 0], [0, g2, 0, 0, J2], [0, 0, I3, 0, 0],
                         [J1, 0, 0, J1, 0], [0, J2, 0, 0, J2]])
    u = sp.symbols("u1 u2", real=True)
    start, end = boundary()
    suffix = ("" if retraction == "cayley" else f"_{retraction}") \
        + ("" if equations == "paper" else f"_{equations}")
    return optimal_control(
        name=f"heavy_top_rotors_oc{suffix}", groupoid=G,
        lagrangian=(rates.T * inertia * rates)[0] / 2 - Mgh * Gamma[2],
        cost=(u[0] ** 2 + u[1] ** 2) / 2, controls=u, actuated=[3, 4],
        parameters={g1: 2.0, g2: 2.5, I3: 1.5, J1: 0.4, J2: 0.5, Mgh: 1.0},
        example=Example(h=T / N, n_steps=N, start=start, end=end), equations=equations,
        symmetries=[Symmetry("vertical_momentum", list(Gamma) + [0, 0])],
        description=f"Optimal control of a heavy top with two rotors (underactuated), "
                    f"{retraction} retraction, {equations} equations (paper §3.3.5).")


model = build()
