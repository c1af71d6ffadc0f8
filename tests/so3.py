"""SO(3) in NumPy for the tests, independent of the generated code.

The hat map in the basis e₁, e₂, e₃ of ``symvi.SO3``, its inverse, and the Cayley map and
its inverse. Leading batch axes are allowed everywhere, and complex entries (complex-step
derivatives) pass through.
"""
from __future__ import annotations

import numpy as np

I3 = np.eye(3)


def hat(v) -> np.ndarray:
    """v̂ = Σ v_a E_a (v × · as a matrix)."""
    v = np.asarray(v)
    z = np.zeros_like(v[..., 0])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1),
                     np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)


def vee(X) -> np.ndarray:
    """Coordinates of a skew matrix: the inverse of :func:`hat`."""
    return np.stack([X[..., 2, 1], X[..., 0, 2], X[..., 1, 0]], -1)


def cay(X) -> np.ndarray:
    """cay(X) = (I − X/2)⁻¹(I + X/2)."""
    return np.linalg.solve(I3 - X / 2, I3 + X / 2)


def cay_inv(W) -> np.ndarray:
    """cay⁻¹(W) = 2(W − I)(W + I)⁻¹ (the two factors commute)."""
    return np.linalg.solve(W + I3, 2 * (W - I3))
