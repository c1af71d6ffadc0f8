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

from .model_info import Kernel

#: Largest defect accepted, relative to the size of the data: configurations built in
#: floating point (a product of rotations, a rotation from Euler angles) are off by
#: 1e-15–1e-13; re-orthonormalise data that is further off.
TOLERANCE = 1e-9


def group_defect(g: np.ndarray, invariants: dict) -> tuple[float, str]:
    """The largest defect of the configuration g (d×d) against the group's conditions,
    each relative to the size of the products it is computed from (so that an SE(n)
    translation, which no condition involves, does not hide a rotation's defect), and
    the condition it violates."""
    values, conditions = group_defects(g[None], invariants)
    worst = int(np.argmax(values[0])) if len(conditions) else 0
    return (float(values[0, worst]), conditions[worst]) if len(conditions) else (0.0, "")


def group_defects(gs: np.ndarray, invariants: dict) -> tuple[np.ndarray, list[str]]:
    """Defects of the configurations ``gs`` (K, d, d), one column per condition (NaN
    counted as infinite), and the conditions' descriptions; vectorised over the nodes,
    since a guess may hold 10⁵ of them."""
    with np.errstate(all="ignore"):             # huge data: an infinite defect, refused
        a, columns, conditions = np.abs(gs), [], []

        def consider(defect: np.ndarray, size: np.ndarray, what: str) -> None:
            value = _sizes(defect) / np.maximum(1.0, _sizes(size))
            columns.append(np.where(np.isnan(value), np.inf, value))
            conditions.append(what)

        T = np.swapaxes(gs, 1, 2)
        for J in map(np.asarray, invariants["quadratic"]):
            consider(T @ J @ gs - J, np.swapaxes(a, 1, 2) @ np.abs(J) @ a,
                     "gᵀJg = J (an invariant quadratic form)")
        for K in map(np.asarray, invariants["coquadratic"]):
            consider(gs @ K @ T - K, a @ np.abs(K) @ np.swapaxes(a, 1, 2),
                     "gKgᵀ = K (an invariant co-form: on SE(n) the rotation block's orthogonality)")
        for v in map(np.asarray, invariants["fixed"]):
            consider(gs @ v - v, a @ np.abs(v), f"g v = v for v = {v.tolist()}")
        for w in map(np.asarray, invariants["cofixed"]):
            consider(w @ gs - w, np.abs(w) @ a, f"wᵀg = wᵀ for w = {w.tolist()} (an invariant covector: on SE(n) the last row)")
        det = np.linalg.det(gs)
        columns.append(np.where(det > 0.0, 0.0, np.where(np.isfinite(det), 1.0 + np.abs(det),
                                                           np.inf)))
        conditions.append("det g > 0 (the group is connected; det g = {det:.6g})")
    values = np.stack(columns, axis=1)
    return values, [c.format(det=float(det[0])) if "{det" in c else c for c in conditions]


def _sizes(a: np.ndarray) -> np.ndarray:
    """Largest absolute entry of each node's array (first axis)."""
    return np.abs(a).reshape(len(a), -1).max(axis=1, initial=0.0)


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
