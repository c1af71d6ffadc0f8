"""Free rigid body on SO(3): l(Ω) = ½ ΩᵀIΩ, first-order discrete Euler–Poincaré.

The discrete flow conserves the spatial angular momentum R_k μ_k exactly (Noether) and
keeps R_k orthogonal (reconstruction R_{k+1} = R_k τ(hΩ_k)). Bundled with the Cayley
retraction (``rigid_body``) and the exponential (``rigid_body_exp``).
"""
import sympy as sp

from symvi import Example, Model, SO3, State


def build(retraction: str = "cayley") -> Model:
    G = SO3(retraction=retraction)
    Omega = G.xi
    I1, I2, I3 = sp.symbols("I1 I2 I3", positive=True)
    suffix = "" if retraction == "cayley" else f"_{retraction}"
    return Model(
        name=f"rigid_body{suffix}", groupoid=G,
        lagrangian=(I1 * Omega[0]**2 + I2 * Omega[1]**2 + I3 * Omega[2]**2) / 2,
        parameters={I1: 1.0, I2: 2.0, I3: 3.0},
        example=Example(initial=(sp.eye(3).tolist(), [[0.3, 1.0, 0.2]]), h=0.01,
                        n_steps=100_000, state=State(v=[0.3, 1.0, 0.2])),
        description=f"Free rigid body on SO(3), inertia diag(I1, I2, I3), {retraction} "
                    f"retraction.")


model = build()
