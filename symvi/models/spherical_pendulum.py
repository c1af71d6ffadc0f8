"""Spherical pendulum on the action groupoid S²×SO(3).

The pendulum's frame R carries the rod along −e₃ (body frame); Γ = Rᵀe₃ is the vertical in
that frame, acted on by Γ·R = RᵀΓ. The bob is at −ℓRe₃, so with Ω the frame's body angular
velocity l(Γ, Ω) = ½ m ℓ² (Ω₁² + Ω₂²) + ½ J Ω₃² + m g ℓ Γ₃: a rod of negligible axial
inertia J, whose spin Ω₃ decouples (it is conserved) and keeps the Legendre condition
regular. With Ω₃ = 0 the bob −ℓRe₃ follows the spherical pendulum. Invariants: |Γ| = 1,
the angular momentum about the vertical Γ·Π, bounded energy error.
"""
import sympy as sp

from symvi import ActionGroupoid, Example, Model, SO3, State, Symmetry


def build(retraction: str = "cayley") -> Model:
    H = SO3(names="w1 w2 w3", retraction=retraction)
    G = ActionGroupoid(H, "Gamma1 Gamma2 Gamma3", lambda q, W: W.T * q, label="S2xSO3",
                       manifold=lambda q: [q.dot(q) - 1])
    w, Gamma = G.xi, G.q
    m, l, g, J = sp.symbols("m l g J", positive=True)
    suffix = "" if retraction == "cayley" else f"_{retraction}"
    return Model(
        name=f"spherical_pendulum{suffix}", groupoid=G,
        lagrangian=m * l**2 * (w[0]**2 + w[1]**2) / 2 + J * w[2]**2 / 2 + m * g * l * Gamma[2],
        symmetries=[Symmetry("vertical_momentum", G.q)],
        parameters={m: 1.0, l: 1.0, g: 9.81, J: 1.0},
        example=Example(initial=([0.0, 0.6, -0.8], [[1.0, 0.5, 0.0]]), h=0.01,
                        n_steps=10_000, state=State(v=[1.0, 0.5, 0.0], x=[0.0, 0.6, -0.8])),
        description=f"Spherical pendulum on S2 x SO(3) (bob at -l R e3), {retraction} "
                    f"retraction.")


model = build()
