"""The arguments of the batch calls, checked before any work (issue 48).

``integrate_many``, ``solve_bvp_many`` and ``continuation`` (``batch.py``,
``bvp_batch.py``; the solves' own checks are in ``bvp/solve_arguments.py``), and the Dask
calls of ``symvi/dask.py``, check what they are given with the functions here, and only
here: the batch's size from its data (zero members is an error, not an empty success),
every per-member value against it, the options, each member's step and parameters, and
the memory the results will hold. A bad argument is refused with one message — the same
on a cluster as on threads — before a thread or a task starts. What only the model's
kernels can judge (a configuration off its group, a singular Legendre transform, boundary
data of the wrong shape) is found in the run, which stops every worker at the first and
names the member.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

from ..core import arguments
from ..core.memory import require
from ..core.options import StepOptions
from ..core.results import State
from ..core.storage import bytes_per_node
from . import stepping

#: How a batch calls its members, one and many: "trajectory 2", "a batch of 4 solves".
TRAJECTORIES = ("trajectory", "trajectories")


@dataclass(frozen=True)
class Overrides:
    """Parameter overrides per member: name → one value per member, or None for the
    compiled defaults. ``uniform``: every override was one value for all."""

    columns: Mapping[object, np.ndarray] | None
    uniform: bool

    def __call__(self, b: int) -> dict | None:
        """Member b's overrides, as the single call takes them."""
        if self.columns is None:
            return None
        return {name: column[b] for name, column in self.columns.items()}

    def rows(self, start: int, stop: int) -> dict | None:
        """The overrides of members start … stop − 1, batched again."""
        if self.columns is None:
            return None
        return {name: column[start:stop] for name, column in self.columns.items()}


@dataclass(frozen=True)
class Trajectories:
    """``integrate_many``'s arguments, checked: member b starts from ``item(b)`` with the
    step ``steps[b]`` and the parameter vector ``parameters[b]`` (``overrides(b)`` as
    given); ``options`` are every step's Newton options."""

    item: Callable[[int], object]
    size: int
    from_state: bool
    steps: np.ndarray
    overrides: Overrides
    parameters: np.ndarray
    n_steps: int
    keep: int
    workers: int
    options: StepOptions
    quantities: bool


def trajectories(model, initial, n_steps: int, h, params: Mapping | None, *,
                 workers: int | None, keep_every: int, final_only: bool, quantities: bool,
                 maxiter: int = StepOptions.unset("maxiter"),
                 xtol: float = StepOptions.unset("xtol"),
                 ftol: float = StepOptions.unset("ftol"),
                 options: StepOptions | Mapping | None = None,
                 keywords: Mapping | None = None) -> Trajectories:
    """The arguments of ``integrate_many`` (its docstring says what each is), checked in
    full: the batch, the options, the memory of the stacked paths, then each member's
    step and parameters."""
    item, B = batch_items(initial, "initial", TRAJECTORIES)
    steps = per_member(h, B, "h", TRAJECTORIES)
    overrides = parameter_batch(params, B, TRAJECTORIES)
    n_steps = stepping.step_count(model, n_steps)
    keep = arguments.count(keep_every, "keep_every", 1)
    keep = n_steps if arguments.flag(final_only, "final_only") else keep
    workers = worker_count(workers)
    options = StepOptions.of(options, dict(maxiter=maxiter, xtol=xtol, ftol=ftol)
                             | dict(keywords or {}), "integrate_many")
    quantities = arguments.flag(quantities, "quantities")
    _paths_fit(model, B, n_steps, keep, quantities)
    positive_per_member(steps, np.ndim(h) == 0, TRAJECTORIES, arguments.step_size)
    parameters = member_parameters(model, overrides, B, TRAJECTORIES)
    return Trajectories(item, B, isinstance(initial, State), steps, overrides, parameters,
                        n_steps, keep, workers, options, quantities)


def batch_items(value, what: str, kind: tuple[str, str]) -> tuple[Callable[[int], object], int]:
    """(b ↦ member b's data, B) for data batched on a leading axis (``integrate_many``'s
    ``initial``: a State or tuple structure of arrays, every array batched); the arrays
    must agree on B, and B ≥ 1. ``what`` names the argument, ``kind`` its members."""
    leaves: list[tuple[str, np.ndarray]] = []

    def collect(value, where: str):
        if isinstance(value, State):
            return State(**{k: collect(getattr(value, k), f"{where}.{k}")
                            for k in ("v", "x", "g") if getattr(value, k) is not None})
        if isinstance(value, tuple):
            return tuple(collect(part, f"{where}[{i}]") for i, part in enumerate(value))
        array = arguments.real_array(value, where)
        if array.ndim == 0:
            raise ValueError(f"{where}: a batch needs a leading batch axis, got a scalar")
        leaves.append((where, array))
        return array

    structure = collect(value, what)
    sizes = {where: array.shape[0] for where, array in leaves}
    if not sizes:
        raise ValueError(f"{what}: no arrays given")
    if len(set(sizes.values())) > 1:
        raise ValueError(f"{what}: the arrays disagree on the batch size (the leading "
                         "axis): " + ", ".join(f"{w} has {n}" for w, n in sizes.items()))
    B = next(iter(sizes.values()))
    if B == 0:
        raise ValueError(f"{what}: the batch is empty (zero {kind[1]}); give at least one")

    def item(b: int, value=structure):
        if isinstance(value, State):
            return State(**{k: item(b, getattr(value, k)) for k in ("v", "x", "g")
                            if getattr(value, k) is not None})
        if isinstance(value, tuple):
            return tuple(item(b, part) for part in value)
        return value[b]
    return item, B


def per_member(value, B: int, what: str, kind: tuple[str, str]) -> np.ndarray:
    """``value`` — one number, or one per member — as B numbers."""
    array = arguments.real_array(value, what)
    try:
        return np.broadcast_to(array, (B,))
    except ValueError:
        raise ValueError(f"{what}: shape {array.shape} does not broadcast against the batch "
                         f"of {B} {kind[1]} (give one value, or {B})") from None


def parameter_batch(params: Mapping | None, B: int, kind: tuple[str, str]) -> Overrides:
    """The overrides of B members: each value a number or B of them."""
    if params is None:
        return Overrides(None, True)
    if not isinstance(params, Mapping):
        raise ValueError(f"params must be a mapping name → value(s), got "
                         f"{type(params).__name__}")
    columns = {name: per_member(value, B, f"params[{name!r}]", kind)
               for name, value in params.items()}
    return Overrides(columns, all(np.ndim(value) == 0 for value in params.values()))


def usable_cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:         # not on Linux
        return os.cpu_count() or 1


def worker_count(workers: int | None) -> int:
    """Threads of a batch: at least one; None for the usable cores."""
    return arguments.count(workers if workers is not None else usable_cores(), "workers", 1)


def _paths_fit(model, B: int, n_steps: int, keep: int, quantities: bool) -> None:
    """Refuse a batch whose paths (with their ``quantities`` or without) would not fit:
    each is held twice — its own result, then the stacked arrays (on a cluster: the
    chunks gathered, then joined)."""
    nodes = n_steps // keep + 2
    require(2.0 * B * nodes * bytes_per_node(model, quantities),
            f"a batch of {B:,} paths of {nodes:,} stored nodes",
            "store every k-th node (keep_every=k) or only the final one (final_only=True)")


def positive_per_member(values: np.ndarray | None, uniform: bool, kind: tuple[str, str],
                        check: Callable[[float], float]) -> None:
    """Every member's step (or horizon) positive and finite: where one is not, ``check``
    (the single call's) refuses it — naming the member unless one value was given for
    all."""
    if values is None:
        return
    bad = np.flatnonzero(~(np.isfinite(values) & (values > 0)))
    if bad.size and uniform:
        check(float(values[0]))
    elif bad.size:
        _named(kind, int(bad[0]), check, float(values[bad[0]]))


def member_parameters(model, overrides: Overrides, B: int,
                       kind: tuple[str, str]) -> np.ndarray:
    """(B, P) the members' parameter vectors; one check when the overrides are the same
    for all (its message then names no member)."""
    if overrides.uniform:
        vector = model.params(overrides(0))
        return np.broadcast_to(vector, (B, vector.size))
    return np.stack(each_member(kind, B, lambda b: model.params(overrides(b))))


def each_member(kind: tuple[str, str], count: int, check: Callable[[int], object]) -> list:
    """``check(b)`` of every member b < count, naming the member where one fails."""
    return [_named(kind, b, check, b) for b in range(count)]


def _named(kind: tuple[str, str], b: int, check: Callable, *args):
    """``check(*args)``, its ValueError re-raised naming member b ("solve 3: …")."""
    try:
        return check(*args)
    except ValueError as exc:
        raise ValueError(f"{kind[0]} {b}: {exc}") from None

