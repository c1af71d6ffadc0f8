"""Optimal control of a rigid body on SO(3) (paper §3.3.4, with ERRATA items 1–3).

Euler's equations with torques τ: IΩ̇ + Ω×IΩ = τ, i.e. Ω̇_i = P_i Ω_j Ω_k + u_i with
P₁ = (I₂−I₃)/I₁ (cyclic) and u_i = τ_i/I_i. The cost ½∫|u|² dt gives
L̃(Ω, Ω̇) = ½ Σ_i (Ω̇_i − P_i Ω_j Ω_k)² (eq. ``LagCont``), discretised as paper eq.
``sdfinal``: L_d(w_k, w_{k+1}) = h L̃((ξ_k+ξ_{k+1})/2, (ξ_{k+1}−ξ_k)/h). The controls
returned are the torques τ_k at each window's midpoint.

Example (issue 4's benchmark problem): R_0 = I, R_N a quarter-turn about (1,1,1)/√3,
Ω = 0 at both ends, T = 1, inertia diag(1, 2, 3), N = 1000.
"""
import numpy as np
import sympy as sp

from symvi import SO3, Example, optimal_control

T, N = 1.0, 1000


def quarter_turn() -> np.ndarray:
    """Rotation by π/2 about (1, 1, 1)/√3 (Rodrigues)."""
    k = np.ones(3) / np.sqrt(3.0)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + K + K @ K   # sin(π/2) = 1, 1 − cos(π/2) = 1


def slew(name: str, retraction: str, description: str, steps: int = N, **options):
    """The quarter-turn slew of a rigid body with inertia diag(1, 2, 3) as an
    :func:`~symvi.optimal_control` problem (torques ``tau1…3``; example: T = 1 in
    ``steps`` steps), with ``options`` (e.g. bounds and their parameters) passed on."""
    G = SO3(retraction=retraction)
    Omega = sp.Matrix(G.xi)
    I = sp.symbols("I1 I2 I3", positive=True)
    u = sp.symbols("tau1 tau2 tau3", real=True)
    suffix = "" if retraction == "cayley" else f"_{retraction}"
    parameters = dict(zip(I, (1.0, 2.0, 3.0))) | options.pop("parameters", {})
    bounds = options.pop("bounds", lambda u: None)(u)
    return optimal_control(
        name=f"{name}{suffix}", groupoid=G,
        lagrangian=(Omega.T * sp.diag(*I) * Omega)[0] / 2,
        cost=sum((ui / Ii) ** 2 for ui, Ii in zip(u, I)) / 2, controls=u,
        parameters=parameters, bounds=bounds,
        example=Example(h=T / steps, n_steps=steps, start=[np.eye(3)] * 2,
                        end=[quarter_turn()] * 2),
        description=f"{description}, {retraction} retraction", **options)


def build(retraction: str = "cayley"):
    return slew("rigid_body_oc", retraction,
                "Optimal control of a rigid body on SO(3): min ½∫|τ/I|² (paper §3.3.4)")


model = build()
