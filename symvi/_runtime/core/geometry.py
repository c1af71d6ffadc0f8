"""User data checked against its geometry: configurations on their matrix group, base
points on their declared manifold.

A configuration g (d×d) of a matrix-group factor must meet the conditions its Lie algebra
fixes (``INFO.groups``, from :meth:`MatrixLieGroup.invariants`): gᵀJg = J, gKgᵀ = K,
gv = v, wᵀg = wᵀ and det g > 0 — for SO(3) orthogonality and determinant 1, for SE(n) an
orthogonal rotation block and the last row (0, …, 0, 1). A base point must satisfy the
equations of its manifold when the model declares them (the ``manifold`` kernel, e.g.
|Γ|² − 1 = 0 on S²). Off-group data would otherwise be integrated or solved silently:
g = 2I is a fixed point of every step and the solve reports success.
"""
from __future__ import annotations

import numpy as np

from .groups import TOLERANCE, group_defect, group_defects
from .model_info import Kernel

def _size(a: np.ndarray) -> float:
    return float(np.abs(a).max(initial=0.0))


def check_configurations(model, g: np.ndarray, what: str, first: int = 0) -> None:
    """Raise ValueError when a configuration of ``g`` (nodes × Σd², flattened factor by
    factor) is off its group; node numbers start at ``first``."""
    at = 0
    for d, group in zip(model.matrix_dims, model.info.groups):
        gs = g[:, at:at + d * d].reshape(-1, d, d)
        defects = group_defects(gs, group.invariants)[0]
        bad = np.flatnonzero(~(defects.max(axis=1, initial=0.0) <= TOLERANCE))
        if bad.size:
            k = int(bad[0])
            defect, condition = group_defect(gs[k], group.invariants)
            raise ValueError(
                f"{what}: the configuration of node {first + k} is not on "
                f"{group.label}: {condition} fails by {defect:.3e} (tolerance "
                f"{TOLERANCE:g}, relative); pass a configuration of the group "
                f"(re-orthonormalise the rotation, e.g. by its polar decomposition)")
        at += d * d


def check_base_points(model, x: np.ndarray, what: str, first: int = 0) -> None:
    """Raise ValueError when a base point of ``x`` (nodes × m) is off the manifold the
    model declares (its ``manifold`` kernel); nothing to check without one."""
    if not model.info.has_kernel(Kernel.MANIFOLD) or not len(x):
        return
    for k, point in enumerate(np.ascontiguousarray(x, dtype=np.float64)):
        values = model.evaluate(Kernel.MANIFOLD, point, 1.0)[0]
        with np.errstate(all="ignore"):         # huge data: an infinite defect, refused
            defect = _size(values) / (1.0 + np.float64(_size(point)) ** 2)
        if not defect <= TOLERANCE:
            raise ValueError(
                f"{what}: the base point of node {first + k}, {np.array2string(point)}, is "
                f"not on the model's manifold: its equations give {np.array2string(values)} "
                f"(defect {defect:.3e}, tolerance {TOLERANCE:g}, relative)")
