"""A configuration's membership of its matrix group, as numbers: the conditions its Lie
algebra fixes (:meth:`symvi.MatrixLieGroup.invariants`) — gᵀJg = J, gKgᵀ = K, gv = v,
wᵀg = wᵀ, det g > 0 — and each one's defect. A leaf of the run time (NumPy only), so that
the declaration checks an Example's configurations with the very test the run time
applies to the same data (:mod:`.geometry`).
"""
from __future__ import annotations

import numpy as np

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
