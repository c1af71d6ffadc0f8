"""The arguments of the batches of whole-trajectory solves, checked before any work
(issue 48): ``solve_bvp_many`` and ``continuation`` (``bvp_batch.py``) and the Dask solves
of ``symvi/dask.py``, on the checks shared with ``integrate_many``
(``step/batch_arguments.py``, whose docstring gives the rules).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

from ..core import arguments
from ..core.memory import require
from ..core.options import SolveOptions
from ..core.storage import check_path_memory
from ..step.batch_arguments import (Overrides, batch_items, each_member, member_parameters,
                                    parameter_batch, per_member, positive_per_member,
                                    worker_count)
from . import boundary_states
from .bvp import solve_steps

#: How a batch of solves calls its members, one and many: "solve 3", "a batch of 4 solves".
SOLVES = ("solve", "solves")

#: What an unknown option's refusal adds in a batch of solves.
NOT_RAISING = " (a batch keeps each failure in its result, it does not raise)"


@dataclass(frozen=True)
class Solves:
    """``solve_bvp_many``'s arguments, checked: solve b from ``start_of(b)`` to
    ``end_of(b)`` (None without fixed ends), with ``steps[b]`` or ``horizons[b]`` (the
    other None), ``overrides(b)`` and ``guesses[b]``; ``options`` go to every solve."""

    start_of: Callable[[int], object]
    end_of: Callable[[int], object]
    size: int
    n_steps: int
    steps: np.ndarray | None
    horizons: np.ndarray | None
    overrides: Overrides
    guesses: list | None
    workers: int
    options: SolveOptions


@dataclass(frozen=True)
class Points:
    """``continuation``'s arguments, checked: the overrides of each of its ``size``
    points, and the ``options`` of every solve."""

    points: list[dict]
    size: int
    n_steps: int
    options: SolveOptions


def solves(model, starts, ends, n_steps: int, h, params: Mapping | None, *, T,
           guesses: list | None, workers: int | None,
           options: SolveOptions | Mapping | None = None,
           keywords: Mapping | None = None) -> Solves:
    """The arguments of ``solve_bvp_many`` (its docstring says what each is), checked in
    full: the batch, the options, the model's whole-trajectory solve and N, the memory of
    the results, then each solve's step or horizon and parameters."""
    start_of, B = batch_items(starts, "starts", SOLVES)
    end_of = (lambda b: None) if ends is None else _same_batch(ends, B)
    steps = None if h is None else per_member(h, B, "h", SOLVES)
    horizons = None if T is None else per_member(T, B, "T", SOLVES)
    overrides = parameter_batch(params, B, SOLVES)
    guesses = _guesses(guesses, B)
    workers = worker_count(workers)
    options = SolveOptions.of(options, keywords, "solve_bvp_many", NOT_RAISING)
    from_states = boundary_states.given(starts, ends)
    N = solve_steps(model, n_steps, from_states)
    check_path_memory(model, N + from_states)     # each solve's matrices, before any
    _results_fit(model, B, N, from_states, f"a batch of {B:,} solves",
                 "solve the batch in parts (keeping only what each needs) or with fewer "
                 "steps")
    _steps_or_horizons(h, T, steps, horizons, N)
    member_parameters(model, overrides, B, SOLVES)
    return Solves(start_of, end_of, B, N, steps, horizons, overrides, guesses, workers,
                  options)


def points(model, start, end, n_steps: int, h, path: Mapping | None, *, T,
           params: Mapping | None, options: SolveOptions | Mapping | None = None,
           keywords: Mapping | None = None) -> Points:
    """The arguments of ``continuation`` (its docstring says what each is), checked in
    full: the path, N, the step, the options, the memory of the results, then each
    point's parameters."""
    columns = _path_columns(path)
    if params is not None and not isinstance(params, Mapping):
        raise ValueError(f"params must be a mapping name → value, got "
                         f"{type(params).__name__}")
    K = len(next(iter(columns.values())))
    from_states = boundary_states.given(start, end)
    N = solve_steps(model, n_steps, from_states)
    check_path_memory(model, N + from_states)
    arguments.step_of(h, T, N)
    options = SolveOptions.of(options, keywords, "continuation", NOT_RAISING)
    _results_fit(model, K, N, from_states, f"a continuation of {K:,} solves",
                 "split the path into parts, each warm-started from the last result of "
                 "the one before (guess=), keeping only what each needs")
    fixed = dict(params or {})
    overrides = [fixed | {name: values[k] for name, values in columns.items()}
                 for k in range(K)]
    each_member(SOLVES, K, lambda k: model.params(overrides[k]))
    return Points(overrides, K, N, options)


def result_bytes(model, n_steps: int, from_states: bool) -> float:
    """Bytes one solve's result holds: per node its time, base point, configuration and
    fibre, the multipliers, controls, bound multipliers and active flags of its window;
    from States also the solved states and their times."""
    info = model.info
    configuration = info.configuration_dim
    inequalities = len(model.inequalities)
    per_node = 8 * (1 + model.m + configuration + model.n + model.constraints
                    + info.controls + inequalities) + inequalities
    if from_states:
        per_node += 8 * (1 + model.m + configuration + model.n)
    return float((n_steps + 1 + from_states) * per_node)


def _results_fit(model, count: int, N: int, from_states: bool, what: str, hint: str) -> None:
    """Refuse ``count`` solves whose results would not fit together (each solve's own
    matrices: :func:`.storage.check_path_memory`)."""
    require(count * result_bytes(model, N, from_states),
            f"{what} with N = {N:,} ({result_bytes(model, N, from_states) / 2**20:.3g} MiB "
            f"each)", hint)


def _steps_or_horizons(h, T, steps: np.ndarray | None, horizons: np.ndarray | None,
                       N: int) -> None:
    """Exactly one of h and T given, and each solve's positive and finite."""
    if (h is None) == (T is None):       # neither or both: one message for the batch
        arguments.step_of(h, T, N)
    if T is None:
        positive_per_member(steps, np.ndim(h) == 0, SOLVES,
                            lambda v: arguments.step_of(v, None, N))
    else:
        positive_per_member(horizons, np.ndim(T) == 0, SOLVES,
                            lambda v: arguments.step_of(None, v, N))


def _same_batch(ends, B: int) -> Callable[[int], object]:
    end_of, size = batch_items(ends, "ends", SOLVES)
    if size != B:
        raise ValueError(f"ends: {size} given for a batch of {B} starts")
    return end_of


def _guesses(guesses, B: int) -> list | None:
    """One first guess per solve, or None."""
    if guesses is None:
        return None
    if isinstance(guesses, (str, bytes, Mapping)) or not hasattr(guesses, "__len__"):
        raise ValueError(f"guesses must be a list of one guess per solve (or None), got "
                         f"{type(guesses).__name__}")
    if len(guesses) != B:
        raise ValueError(f"guesses: {len(guesses)} given for a batch of {B} solves")
    return list(guesses)


def _path_columns(path) -> dict[object, np.ndarray]:
    """A continuation's path: parameter names → K ≥ 1 values each."""
    if path is not None and not isinstance(path, Mapping):
        raise ValueError(f"path must be a mapping parameter name → sequence of values, got "
                         f"{type(path).__name__}")
    if not path:
        raise ValueError("continuation needs a path: parameter names → sequences of values")
    columns = {name: np.atleast_1d(arguments.real_array(values, f"path[{name!r}]"))
               for name, values in path.items()}
    for name, values in columns.items():
        if values.ndim != 1:
            raise ValueError(f"path[{name!r}] must be a sequence of numbers, got shape "
                             f"{values.shape}")
    lengths = {name: len(values) for name, values in columns.items()}
    if len(set(lengths.values())) != 1:
        raise ValueError(f"path: the sequences differ in length: {lengths}")
    if not next(iter(lengths.values())):
        raise ValueError("path: the sequences are empty (zero solves); give at least one "
                         "value")
    return columns
