"""Rigid body on SE(3) in gravity on a vertical spring, on an action groupoid.

The configuration (R, p) ∈ SE(3) enters the potential only through the height z = e₃·p
and the vertical in the body frame Γ = Rᵀe₃, so the base is Q = R × S² ∋ (z, Γ) with the
right action (z, Γ)·(Λ, u) = (z + Γ·u, ΛᵀΓ) of SE(3). With body velocities (Ω, V),
l = ½ ΩᵀJΩ + ½ m|V|² − m g z − ½ k z². Invariants: energy (bounded error), the momentum
about the vertical and the horizontal linear momentum (discrete Noether, exact).
"""
import sympy as sp

from symvi import ActionGroupoid, Example, Model, SE3, State


def _action(q, W):
    z, Gamma = q[0], q[1:, 0]
    Lambda, u = W[:3, :3], W[:3, 3]
    return [z + Gamma.dot(u)] + list(Lambda.T * Gamma)


def build(retraction: str = "cayley") -> Model:
    H = SE3(retraction=retraction)
    G = ActionGroupoid(H, "z Gamma1 Gamma2 Gamma3", _action, label="RxS2xSE3",
                       manifold=lambda q: [q[1:, 0].dot(q[1:, 0]) - 1])
    Omega, V = sp.Matrix(G.xi[:3]), sp.Matrix(G.xi[3:])
    z = G.q[0]
    J1, J2, J3, m, g, k = sp.symbols("J1 J2 J3 m g k", positive=True)
    suffix = "" if retraction == "cayley" else f"_{retraction}"
    return Model(
        name=f"se3_body{suffix}", groupoid=G,
        lagrangian=(J1 * Omega[0]**2 + J2 * Omega[1]**2 + J3 * Omega[2]**2) / 2
        + m * V.dot(V) / 2 - m * g * z - k * z**2 / 2,
        parameters={J1: 1.0, J2: 2.0, J3: 3.0, m: 1.0, g: 9.81, k: 4.0},
        example=Example(initial=([0.0, 0.0, 0.6, 0.8], [[0.5, 0.3, 1.0, 0.2, 0.0, 0.4]]),
                        h=0.01, n_steps=10_000,
                        state=State(v=[0.5, 0.3, 1.0, 0.2, 0.0, 0.4], x=[0.0, 0.0, 0.6, 0.8])),
        description=f"Rigid body on SE(3) in gravity on a vertical spring, {retraction} "
                    f"retraction.")


model = build()
