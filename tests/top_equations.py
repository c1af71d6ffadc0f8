"""The heavy top with two rotors' variational controlled equations, derived by hand.

First-order L_d on one element (Γ_k, θ_k) → (Γ_{k+1}, θ_{k+1}), increment cay(hξ̂_k):
L_d = h[½ rᵀ M r − Mgh (Γ_k,3 + Γ_{k+1},3)/2], r = (ξ_k, θ̇_k), θ̇_k = (θ_{k+1} − θ_k)/h.
Momenta μ = ∂/∂ξ = (γ₁ξ₁ + J₁θ̇₁, γ₂ξ₂ + J₂θ̇₂, Ī₃ξ₃), π = ∂/∂θ̇ = J(ξ₁₂ + θ̇). Moving node
k by g_k cay(εη̂) changes ξ_{k−1} by dcay⁻¹_{−hξ}η/h, ξ_k by −dcay⁻¹_{hξ}η/h (dcay⁻¹_x =
I − x̂/2 + xxᵀ/4) and Γ_k by Γ_k × η; moving θ_k changes θ̇_{k−1} by 1/h, θ̇_k by −1/h.
With D the node variation of L_d(k−1) + L_d(k), the controlled equations are
u = −D_θ/h = (π_k − π_{k−1})/h and Φ = −D_Ω/h =

    (μ_k − μ_{k−1})/h + ½(ξ_{k−1}×μ_{k−1} + ξ_k×μ_k)
        + (h/4)(ξ_k (ξ_k·μ_k) − ξ_{k−1} (ξ_{k−1}·μ_{k−1})) + Mgh e₃×Γ_k,

→ Π̇ + Ω×Π + Mgh e₃×Γ as h → 0. Batch axes are allowed and the arithmetic is
complex-safe (complex-step derivatives).
"""
from __future__ import annotations

import numpy as np


def momenta(p, xi, rate):
    """(μ, π) of one element from ξ and the rotor rates θ̇ (last axis: components)."""
    g1, g2, I3, J1, J2 = (p[k] for k in ("gamma1", "gamma2", "I3bar", "J1", "J2"))
    mu = np.stack([g1 * xi[..., 0] + J1 * rate[..., 0], g2 * xi[..., 1] + J2 * rate[..., 1],
                   I3 * xi[..., 2]], -1)
    pi = np.stack([J1 * (xi[..., 0] + rate[..., 0]), J2 * (xi[..., 1] + rate[..., 1])], -1)
    return mu, pi


def variational_terms(p, xi0, xi1, rate0, rate1, gamma, h):
    """(u terms, Φ terms) at the node between elements (ξ₀, θ̇₀) and (ξ₁, θ̇₁) with
    direction of gravity ``gamma`` there: per component the list of terms whose sum it is."""
    (mu0, pi0), (mu1, pi1) = momenta(p, xi0, rate0), momenta(p, xi1, rate1)
    spin0, spin1 = np.cross(xi0, mu0) / 2, np.cross(xi1, mu1) / 2
    along0 = xi0 * np.sum(xi0 * mu0, -1)[..., None] * h / 4
    along1 = xi1 * np.sum(xi1 * mu1, -1)[..., None] * h / 4
    Mgh = p["Mgh"]
    gravity = np.stack([-Mgh * gamma[..., 1], Mgh * gamma[..., 0], 0 * gamma[..., 2]], -1)
    phi = [[mu1[..., i] / h, -mu0[..., i] / h, spin0[..., i], spin1[..., i], along1[..., i],
            -along0[..., i], gravity[..., i]] for i in range(3)]
    u = [[pi1[..., i] / h, -pi0[..., i] / h] for i in range(2)]
    return u, phi
