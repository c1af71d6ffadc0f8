"""The group-variation oracle shared by the Lie-group and action-groupoid tests (DESIGN.md §5),
and their NumPy Lie-algebra helper :class:`Algebra`.

Along a computed path, vary node j by ε along each basis direction with the group's own
retraction and check by five-point differences that the action sum Σ L_d is stationary,
relative to the size of the individual window terms; ``noise`` is the rounding bound of
the differences on the same scale.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

U = np.finfo(float).eps
EPS_FD = 1e-3


class Algebra:
    """Basis E_a of a matrix Lie algebra, with hat, coordinates and the Cayley map."""

    def __init__(self, group):
        """``group``: a :class:`symvi.MatrixLieGroup`."""
        self.d = group.matrix_dim
        self.E = np.array([np.array(E.tolist(), dtype=float) for E in group.basis])
        self.n = len(self.E)
        self.B = self.E.reshape(self.n, -1).T          # (d², n): columns vec(E_a)
        self.I = np.eye(self.d)

    def hat(self, v):
        return np.einsum("a,aij->ij", np.asarray(v, dtype=float), self.E)

    def coords(self, X):
        v, *_ = np.linalg.lstsq(self.B, X.reshape(-1), rcond=None)
        # the matrix must lie in the algebra (else the variation left the group)
        assert np.abs(self.B @ v - X.reshape(-1)).max() <= 1e-12 * (1 + np.abs(X).max())
        return v

    def cay(self, X):
        return np.linalg.solve(self.I - X / 2, self.I + X / 2)

    def cay_inv(self, W):
        # X = 2 (W − I)(W + I)⁻¹  ⇔  X (W + I) = 2 (W − I)
        return 2 * np.linalg.solve((W + self.I).T, (W - self.I).T).T


@dataclass(frozen=True)
class OracleResult:
    nodes: np.ndarray
    relative: np.ndarray   # max_a |∂S/∂ε_a| / scale
    noise: np.ndarray      # rounding bound / scale


def oracle(mod, vary, n, x, f, h, nodes, eps=EPS_FD) -> OracleResult:
    """``vary(x, f, j, a, ε)`` → the varied path, for a = 0 … n − 1."""
    def windows(xx, ff):
        return mod.model.along("lagrangian", xx, ff, h)[:, 0]

    base = windows(x, f)
    rel, noise = [], []
    for j in nodes:
        grads, scales, floors = [], [], []
        for a in range(n):
            vals = {s: windows(*vary(x, f, j, a, s * eps)) for s in (-2, -1, 1, 2)}
            terms = (-vals[2] + 8 * vals[1] - 8 * vals[-1] + vals[-2]) / (12 * eps)
            touched = terms != 0
            grads.append(math.fsum(terms))
            scales.append(np.abs(terms))
            # a few ulp of each touched window and of the retraction round trip (a shift
            # of ~u in ε, worth u·|∂L_w/∂ε|); the five-point weights sum to 18/12ε
            floors.append(18 / (12 * eps) * 4 * U
                          * (np.abs(base[touched]).sum() + np.abs(terms).sum()))
        scale = np.max(scales, axis=0).sum()
        rel.append(max(abs(g) for g in grads) / scale)
        noise.append(max(floors) / scale)
    return OracleResult(np.asarray(nodes), np.asarray(rel), np.asarray(noise))


def assert_stationary(name: str, out: OracleResult, tol: float) -> None:
    """The oracle's verdict: rounding noise well below ``tol``, every gradient below it."""
    assert out.noise.max() < tol / 10, f"FD noise floor {out.noise.max():.2e} too high"
    worst = int(np.argmax(out.relative))
    print(f"{name}: max relative gradient {out.relative.max():.2e} "
          f"(noise bound {out.noise.max():.1e})")
    assert out.relative.max() < tol, (
        f"{name}: action not stationary at node {out.nodes[worst]}: relative gradient "
        f"{out.relative[worst]:.3e}")
