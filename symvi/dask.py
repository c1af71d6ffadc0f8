"""Batches on a Dask cluster (issue 24, item 3; the optional extra ``dask``).

The batch is cut into chunks along its leading axis; each chunk is one Dask task that
loads the generated package on its worker and runs the package's own ``integrate_many``
or ``solve_bvp_many`` on it (threads within the worker), and the chunks' results are
joined into the one result the local call returns — the same numbers, since every
trajectory is the same C loop on the same data. Nothing compiled is pickled: a task
carries the package's folder, arrays and options, and returns a result object.

The package must be readable by the workers under the same path: a shared file system
(a ``LocalCluster``, an NFS home or scratch directory). Uploading it
(``Client.upload_file``) does not work for a compiled package: Python does not import
extension modules from a zip archive. The workers need symvi installed (the task code is
here) and the same Python, NumPy and C ABI as the machine that compiled the package.

Every argument is checked here, on the client, before any task is submitted, by the
local calls' own checks (``_runtime/step/batch_arguments.py``): a bad batch is refused in the
same words as on threads, and no cluster time is spent on it.

    from dask.distributed import Client
    import symvi.dask

    if __name__ == "__main__":      # worker processes import the script: start nothing there
        client = Client("scheduler-address:8786")
        batch = symvi.dask.integrate_many(client, double_pendulum, start, 1000, 0.005)
"""
from __future__ import annotations

import inspect
from dataclasses import fields
from pathlib import Path
from types import ModuleType
from typing import Callable, Mapping

import numpy as np

from ._runtime.bvp import solve_arguments
from ._runtime.core import arguments
from ._runtime.step import batch_arguments
from ._runtime.step.batch import integrate_many as _local_integrate_many
from ._runtime.bvp.bvp_batch import solve_bvp_many as _local_solve_bvp_many
from ._runtime.core.progress import Progress
from ._runtime.core.results import BatchResult, BVPBatch, State, Status


def integrate_many(client, package: ModuleType, initial, n_steps: int, h,
                   params: Mapping | None = None, *, chunk: int = 1000,
                   progress: bool | None = None, **options) -> BatchResult:
    """``package.integrate_many`` on the workers of ``client`` (a
    ``dask.distributed.Client``), ``chunk`` trajectories per task (a positive integer);
    ``options`` as there (``workers=``: threads per task, default 1 — a Dask worker runs
    as many tasks at once as it has threads). ``progress``: a bar of finished
    trajectories here, as in the local call. Every argument is checked here, before any
    task is submitted, by the local call's own checks and in its words (the memory
    estimate counts the paths gathered here). Returns the :class:`BatchResult` the local
    call returns."""
    folder = _folder(package)
    options = {"workers": 1} | options
    batch = batch_arguments.trajectories(**_arguments(
        _local_integrate_many, package.model, initial, n_steps, h, params, **options))
    options = _plain_options(options, batch.options)
    parts = _submitted(client, _run_fields, folder, "integrate_many", batch.size, chunk,
                       "trajectories", progress,
                       lambda rows: _trajectory_task(batch, options, rows))
    return BatchResult.joined([_batch(fields) for fields in parts])


def solve_bvp_many(client, package: ModuleType, starts, ends, n_steps: int, h=None,
                   params: Mapping | None = None, *, chunk: int = 10,
                   progress: bool | None = None, **options) -> BVPBatch:
    """``package.solve_bvp_many`` on the workers of ``client``, ``chunk`` solves per task
    (a positive integer); ``progress`` and the checks as in :func:`integrate_many` (the
    memory estimate counts the results gathered here). Returns the :class:`BVPBatch` the
    local call returns."""
    folder = _folder(package)
    batch = solve_arguments.solves(**_arguments(
        _local_solve_bvp_many, package.model, starts, ends, n_steps, h, params, **options))
    options = _plain_options(options, batch.options)
    parts = _submitted(client, _run, folder, "solve_bvp_many", batch.size, chunk, "solves",
                       progress, lambda rows: _solve_task(batch, ends is None, options, rows))
    return BVPBatch.of([r for part in parts for r in part.results])


def _submitted(client, run: Callable, folder: str, method: str, size: int, chunk,
               what: str, progress: bool | None, task: Callable[[range], tuple]) -> list:
    """The results of ``run(folder, method, *task(rows))`` on the workers, one task per
    ``chunk`` members of the batch of ``size`` (``chunk`` checked first), in order; a bar
    counts the ``what`` finished."""
    chunk = _chunk(chunk)
    with Progress(size, what, progress) as bar:
        futures = [client.submit(run, folder, method, *task(rows), pure=False)
                   for rows in _ranges(size, chunk)]
        return _gathered(client, futures, bar)


def _arguments(local: Callable, model, *args, **options) -> dict:
    """The arguments the local call ``local(model, *args, **options)`` would check, its
    defaults filled in (``progress`` aside: the bar is here); a name it does not take is
    refused as the call itself would refuse it."""
    try:
        bound = inspect.signature(local).bind(model, *args, **options)
    except TypeError as exc:
        raise TypeError(f"{local.__name__}(): {exc}") from None
    bound.apply_defaults()
    bound.arguments.pop("progress")
    return dict(bound.arguments)


def _plain_options(options: dict, checked) -> dict:
    """``options`` with the solver's options (given as ``options=`` or as keywords) as one
    mapping of the ``checked`` object's fields: every package carries its own options
    classes (``_runtime/core/options.py``), which a worker that has imported no package
    cannot unpickle."""
    names = set(checked.names())
    return {k: v for k, v in options.items() if k != "options" and k not in names} | \
        {"options": {f.name: getattr(checked, f.name) for f in fields(checked)}}


def _chunk(chunk) -> int:
    """Members per task: a positive integer, checked as the local calls check ``workers``."""
    return arguments.count(chunk, "chunk", 1)


def _ranges(B: int, chunk: int) -> list[range]:
    """The members of each task."""
    return [range(a, min(a + chunk, B)) for a in range(0, B, chunk)]


def _trajectory_task(batch: batch_arguments.Trajectories, options: dict,
                     rows: range) -> tuple[tuple, dict, tuple[int, int]]:
    """(arguments, options, (first, last member)) of the local ``integrate_many`` for
    the trajectories ``rows``."""
    args = (_plain(_gather(batch.item, rows)), batch.n_steps,
            batch.steps[rows.start:rows.stop])
    own = {"params": batch.overrides.rows(rows.start, rows.stop), "progress": False}
    return args, options | own, (rows.start, rows[-1])


def _solve_task(batch: solve_arguments.Solves, free_end: bool, options: dict,
                rows: range) -> tuple[tuple, dict, tuple[int, int]]:
    """(arguments, options, (first, last member)) of the local ``solve_bvp_many`` for the
    solves ``rows``: their boundary data, steps, parameters, horizons and guesses."""
    steps = None if batch.steps is None else batch.steps[rows.start:rows.stop]
    ends = None if free_end else _plain(_gather(batch.end_of, rows))
    args = (_plain(_gather(batch.start_of, rows)), ends, batch.n_steps, steps)
    own = {"params": batch.overrides.rows(rows.start, rows.stop), "progress": False}
    if batch.horizons is not None:
        own["T"] = batch.horizons[rows.start:rows.stop]
    if batch.guesses is not None:
        own["guesses"] = batch.guesses[rows.start:rows.stop]
    return args, options | own, (rows.start, rows[-1])


def _gathered(client, futures: list, bar: Progress) -> list:
    """The futures' results in order, gathered as they finish (``bar`` counts the
    members); on an error or Ctrl-C the tasks not yet run are cancelled."""
    from distributed import as_completed

    index = {future.key: i for i, future in enumerate(futures)}
    out = [None] * len(futures)
    try:
        for future, result in as_completed(futures, with_results=True):
            out[index[future.key]] = result
            bar.update(len(result["statuses"] if isinstance(result, dict) else result))
    except BaseException:
        client.cancel(futures)
        raise
    return out


def _run(folder: str, method: str, args: tuple, options: dict, where: tuple[int, int]):
    """On a worker: load the package (once per process) and run ``method`` on a chunk."""
    from symvi.build import load

    try:
        package = load(folder)
    except (ImportError, OSError) as exc:
        raise ImportError(f"cannot load the package {folder} on a worker: {exc} — the "
                          f"workers must read the folder under the same path (a shared "
                          f"file system), with symvi installed") from None
    args = tuple(package.State(**a[1]) if isinstance(a, tuple) and a[:1] == (_STATE,) else a
                 for a in args)
    try:
        return getattr(package, method)(*args, **options)
    except ValueError as exc:
        raise ValueError(f"in the chunk of members {where[0]}–{where[1]}: {exc}") from None


def _run_fields(*args) -> dict:
    """:func:`_run` returning the batch's fields: plain arrays travel through Dask's
    NumPy serialisation, about five times faster than the pickled result object."""
    result = _run(*args)
    return {f.name: getattr(result, f.name) for f in fields(result)} | \
        {"status": int(result.status)}


def _batch(values: dict) -> BatchResult:
    return BatchResult(**values | {"status": Status(values["status"])})


#: A State travels as (_STATE, its fields): plain fields, whatever the worker has
#: imported (a pickled result would load symvi's classes, ``_runtime/core/results.py``).
_STATE = "symvi.State"


def _plain(value):
    if isinstance(value, State):
        return (_STATE, {k: getattr(value, k) for k in ("v", "x", "g")
                         if getattr(value, k) is not None})
    return value


def _folder(package: ModuleType) -> str:
    if not hasattr(package, "integrate_many"):
        raise TypeError(f"{package!r} is not a generated symvi package")
    return str(Path(package.__file__).resolve().parent)


def _gather(item, rows: range):
    """The members ``rows`` of batched data, batched again (the structure of ``item(b)``)."""
    members = [item(b) for b in rows]

    def stack(values):
        first = values[0]
        if isinstance(first, State):
            return State(**{k: stack([getattr(v, k) for v in values])
                            for k in ("v", "x", "g") if getattr(first, k) is not None})
        if isinstance(first, tuple):
            return tuple(stack([v[i] for v in values]) for i in range(len(first)))
        return np.stack(values)
    return stack(members)
