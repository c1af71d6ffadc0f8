"""Heavy top on the action groupoid S²×SO(3) (paper §3.1, action-groupoid example).

Γ ∈ S² is the direction of gravity in the body frame, acted on by Γ·R = RᵀΓ; the reduced
Lagrangian is l(Γ, Ω) = ½ ΩᵀIΩ − m g ℓ χ·Γ with χ the unit vector from the fixed point to
the centre of mass (body frame). Discretised with the symmetric rule
L_d = h/2 [l(Γ_k, Ω_k) + l(Γ_{k+1}, Ω_k)]. Invariants: |Γ_k| = 1 (exact reconstruction),
the momentum about the vertical Γ·Π (discrete Noether, exact), bounded energy error.
"""
import sympy as sp

from symvi import ActionGroupoid, Example, Model, SO3, State, Symmetry


def build(retraction: str = "cayley") -> Model:
    H = SO3(retraction=retraction)
    G = ActionGroupoid(H, "Gamma1 Gamma2 Gamma3", lambda q, W: W.T * q, label="S2xSO3",
                       manifold=lambda q: [q.dot(q) - 1])
    Omega, Gamma = sp.Matrix(G.xi), sp.Matrix(G.q)
    I1, I2, I3, mgl = sp.symbols("I1 I2 I3 mgl", positive=True)
    chi = sp.Matrix(sp.symbols("chi1 chi2 chi3", real=True))
    inertia = sp.diag(I1, I2, I3)
    suffix = "" if retraction == "cayley" else f"_{retraction}"
    return Model(
        name=f"heavy_top{suffix}", groupoid=G,
        lagrangian=(Omega.T * inertia * Omega)[0] / 2 - mgl * chi.dot(Gamma),
        symmetries=[Symmetry("vertical_momentum", G.q)],
        parameters={I1: 1.0, I2: 2.0, I3: 3.0, mgl: 1.0,
                    chi[0]: 0.6, chi[1]: 0.0, chi[2]: 0.8},
        example=Example(initial=([0.0, 0.6, 0.8], [[0.5, 0.3, 2.0]]), h=0.01, n_steps=10_000,
                        state=State(v=[0.5, 0.3, 2.0], x=[0.0, 0.6, 0.8])),
        description=f"Heavy top on the action groupoid S2 x SO(3), inertia diag(I1, I2, I3), "
                    f"centre of mass along chi, {retraction} retraction.")


model = build()
