"""Validation of user arguments: shapes, finiteness, step size, parameters."""
from __future__ import annotations

import math
import numbers
from typing import Mapping, Sequence

import numpy as np


def finite_array(value, shape: tuple[int, ...], what: str) -> np.ndarray:
    """``value`` as a C-contiguous float64 array of ``shape`` with finite entries."""
    try:
        arr = np.array(value, dtype=np.float64, order="C")
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{what} must be an array of numbers: {exc}") from None
    squeezed = tuple(shape)
    while squeezed and squeezed[-1] == 1:
        squeezed = squeezed[:-1]
    if arr.shape != shape:
        # a scalar model's nodes may come without their trailing unit axis: (K,) for (K, 1)
        if arr.shape != squeezed or not squeezed:
            raise ValueError(f"{what} has shape {arr.shape}, expected {shape}")
        arr = arr.reshape(shape)
    bad = ~np.isfinite(arr)
    if bad.any():
        index = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValueError(f"{what} contains a non-finite value ({arr[index]}) at index {index}")
    return arr


def step_size(h) -> float:
    if isinstance(h, bool) or not isinstance(h, numbers.Real):
        raise ValueError(f"the time step h must be a real number, got {h!r}")
    h = float(h)
    if not math.isfinite(h) or h <= 0.0:
        raise ValueError(f"the time step h must be positive and finite, got {h}")
    return h


def count(value, what: str, minimum: int = 0) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{what} must be an integer, got {value!r}")
    if value < minimum:
        raise ValueError(f"{what} must be at least {minimum}, got {value}")
    return int(value)


def tolerance(value, what: str) -> float:
    value = float(value)
    if not math.isfinite(value) or value < 0:
        raise ValueError(f"{what} must be finite and non-negative, got {value}")
    return value


def parameters(names: Sequence[str], defaults: Sequence[float],
               given: Mapping[str, float] | Sequence[float] | None) -> np.ndarray:
    """Parameter vector: defaults overridden by a name → value mapping (or a full sequence)."""
    values = dict(zip(names, defaults))
    if given is None:
        pass
    elif isinstance(given, Mapping):
        unknown = set(given) - set(names)
        if unknown:
            raise ValueError(f"unknown parameter(s) {sorted(unknown)}; the model has "
                             f"{list(names)}")
        values.update(given)
    else:
        seq = list(given)
        if len(seq) != len(names):
            raise ValueError(f"expected {len(names)} parameter values {list(names)}, "
                             f"got {len(seq)}")
        values = dict(zip(names, seq))
    vec = np.array([values[n] for n in names] or [0.0], dtype=np.float64)
    for name, v in zip(names, vec):
        if not math.isfinite(v):
            raise ValueError(f"parameter {name} must be finite, got {v}")
    return vec
