"""Validation of user arguments: types, shapes, finiteness, step size, counts, parameters.

Numbers must be numbers: strings, booleans, complex values and objects that merely convert
to a float (``'2.0'``, ``True``) are refused rather than silently converted, since such a
value in a numerical argument is almost always a mistake upstream.
"""
from __future__ import annotations

import math
import numbers
from typing import Mapping, Sequence

import numpy as np

from .signs import SIGNS

#: Largest value of a C ``int`` argument (maxiter): larger ones would overflow in cffi.
INT_MAX = 2**31 - 1
#: Largest value of a C ``long`` argument (step and node counts).
LONG_MAX = 2**63 - 1


def _is_real(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


#: Element types accepted without the per-element check (the common case, checked at C speed).
_PLAIN_REALS = frozenset({float, int, np.float64, np.float32, np.int64, np.int32})


def flag(value, what: str) -> bool:
    """``value``, which must be True or False (a TypeError naming ``what`` otherwise)."""
    if not isinstance(value, bool):
        raise TypeError(f"{what} must be True or False, got {value!r}")
    return value


def real_array(value, what: str) -> np.ndarray:
    """``value`` as a float64 array, refusing strings, booleans, complex and other
    non-numbers (NumPy would convert ``'2.0'`` and ``True`` without a word)."""
    arr = value
    if not isinstance(value, np.ndarray):
        # element by element: NumPy would turn [True, 1.5] into [1.0, 1.5]
        try:
            arr = np.asarray(value, dtype=object)
        except (TypeError, ValueError) as exc:   # ragged nesting
            raise ValueError(f"{what} must be an array of numbers: {exc}") from None
    if arr.dtype == object:
        flat = arr.reshape(-1)
        bad = [] if _PLAIN_REALS.issuperset(map(type, flat)) else \
            [v for v in flat if not _is_real(v)][:1]
        if bad:
            raise ValueError(f"{what} must be an array of real numbers, got an element "
                             f"{bad[0]!r} of type {type(bad[0]).__name__}")
        return np.array([float(v) for v in flat], dtype=np.float64).reshape(arr.shape)
    if not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        names = {"b": "booleans", "c": "complex numbers", "U": "strings", "S": "bytes"}
        raise ValueError(f"{what} must be an array of real numbers, got "
                         f"{names.get(arr.dtype.kind, f'dtype {arr.dtype}')}")
    return np.ascontiguousarray(arr, dtype=np.float64)


def finite_array(value, shape: tuple[int, ...], what: str) -> np.ndarray:
    """``value`` as a C-contiguous float64 array of ``shape`` with finite entries."""
    arr = real_array(value, what)
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
    return np.array(arr, order="C", copy=True)


def real(value, what: str) -> float:
    """A real scalar (not a string, a boolean or a complex number)."""
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    if not _is_real(value):
        raise ValueError(f"{what} must be a real number, got {value!r}")
    return float(value)


def step_size(h) -> float:
    if not _is_real(h):
        raise ValueError(f"the time step h must be a real number, got {h!r}")
    h = float(h)
    if not math.isfinite(h) or h <= 0.0:
        raise ValueError(f"the time step h must be positive and finite, got {h}")
    return h


def step_of(h, T, steps: int) -> float:
    """The step from exactly one of the step ``h`` and the horizon ``T`` = steps·h."""
    if (h is None) == (T is None):
        raise ValueError(f"give the step h or the horizon T (h = T/n_steps), not "
                         f"{'both' if h is not None else 'neither'}")
    if T is None:
        return step_size(h)
    if not _is_real(T) or not (math.isfinite(float(T)) and float(T) > 0.0):
        raise ValueError(f"the horizon T must be a positive, finite real number, got {T!r}")
    return float(T) / steps


def count(value, what: str, minimum: int = 0, maximum: int = LONG_MAX, why: str = "") -> int:
    """An integer in [minimum, maximum] (maximum: what the C argument can hold); ``why``
    explains the minimum in the message."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{what} must be an integer, got {value!r}")
    if value < minimum:
        raise ValueError(f"{what} must be at least {minimum}{why}, got {value}")
    if value > maximum:
        raise ValueError(f"{what} must be at most {maximum}, got {value}")
    return int(value)


def iterations(value, what: str = "maxiter") -> int:
    """An iteration limit passed to C as an ``int``."""
    return count(value, what, 1, INT_MAX)


def tolerance(value, what: str) -> float:
    value = real(value, what)
    if not math.isfinite(value) or value < 0:
        raise ValueError(f"{what} must be finite and non-negative, got {value}")
    return value


def _by_name(given: Mapping, names: Sequence[str]) -> dict[str, object]:
    """``given`` keyed by parameter name: a key that is not a string (a SymPy symbol,
    whatever its assumptions) stands for its ``str``. Unknown names and a name given
    twice (``'m'`` and ``Symbol('m')``) are refused."""
    named, keys = {}, {}
    for key, value in given.items():
        name = key if isinstance(key, str) else str(key)
        if name in named:
            raise ValueError(f"parameter {name} is given twice, as {keys[name]!r} and {key!r}")
        named[name], keys[name] = value, key
    unknown = sorted(set(named) - set(names))
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown}; the model has {list(names)}")
    return named


def parameters(names: Sequence[str], defaults: Sequence[float],
               given: Mapping[str, float] | Sequence[float] | None,
               signs: Sequence[str | None] = ()) -> np.ndarray:
    """Parameter vector: defaults overridden by a name → value mapping (or a full sequence),
    each value finite and of the sign its symbol was declared with (``signs``: a mass
    declared ``positive=True`` cannot be −1)."""
    values = dict(zip(names, defaults))
    if given is None:
        pass
    elif isinstance(given, Mapping):
        values.update(_by_name(given, names))
    elif isinstance(given, (str, bytes)):
        raise ValueError(f"params must be a mapping name → value or a sequence of "
                         f"{len(names)} numbers, got {given!r}")
    else:
        try:
            seq = list(given)
        except TypeError:
            raise ValueError(f"params must be a mapping name → value or a sequence of "
                             f"{len(names)} numbers, got {given!r}") from None
        if len(seq) != len(names):
            raise ValueError(f"expected {len(names)} parameter values {list(names)}, "
                             f"got {len(seq)}")
        values = dict(zip(names, seq))
    vec = np.array([real(values[n], f"parameter {n}") for n in names] or [0.0])
    declared_signs = dict(zip(names, signs))
    for name, v in zip(names, vec):
        declared = declared_signs.get(name)
        if not math.isfinite(v):
            raise ValueError(f"parameter {name} must be finite, got {v}")
        if declared in SIGNS and not SIGNS[declared][0](v):
            raise ValueError(f"parameter {name} is declared {declared} (its symbol's "
                             f"assumption): it must be {SIGNS[declared][1]}, got {v:g}")
    return vec
