"""Planar rigid body on SE(2) whose body frame is offset from the centre of mass.

With ξ = (ω, v₁, v₂) the body velocity of the frame and c = (c, 0) the centre of mass in the
body frame, l(ξ) = ½ I ω² + ½ m |v + ω J c|² (J the quarter turn): the translational and
rotational parts couple, yet the exact motion is known — ω constant and the centre of mass
moving on a straight line at constant speed — and the discrete flow's Noether momenta
(linear and angular) are conserved exactly.
"""
import sympy as sp

from symvi import Example, Model, SE2, State


def build(retraction: str = "cayley") -> Model:
    G = SE2(retraction=retraction)
    omega, v1, v2 = G.xi
    m, I, c = sp.symbols("m I c", positive=True)
    suffix = "" if retraction == "cayley" else f"_{retraction}"
    return Model(
        name=f"planar_body{suffix}", groupoid=G,
        lagrangian=I * omega**2 / 2 + m * (v1**2 + (v2 + omega * c)**2) / 2,
        parameters={m: 1.0, I: 0.5, c: 0.3},
        example=Example(initial=(sp.eye(3).tolist(), [[1.0, 0.5, -0.2]]), h=0.01,
                        n_steps=10_000, state=State(v=[1.0, 0.5, -0.2])),
        description=f"Planar rigid body on SE(2), centre of mass offset c from the frame, "
                    f"{retraction} retraction.")


model = build()
