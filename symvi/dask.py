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

    from dask.distributed import Client
    import symvi.dask
    client = Client("scheduler-address:8786")
    batch = symvi.dask.integrate_many(client, double_pendulum, start, 1000, 0.005)
"""
from __future__ import annotations

from dataclasses import fields
from pathlib import Path
from types import ModuleType
from typing import Mapping

import numpy as np

from ._runtime.batch import batch_items
from ._runtime.progress import Progress
from ._runtime.results import BatchResult, BVPBatch, State, Status


def integrate_many(client, package: ModuleType, initial, n_steps: int, h,
                   params: Mapping | None = None, *, chunk: int = 1000,
                   progress: bool | None = None, **options) -> BatchResult:
    """``package.integrate_many`` on the workers of ``client`` (a
    ``dask.distributed.Client``), ``chunk`` trajectories per task; ``options`` as there
    (``workers=``: threads per task, default 1 — a Dask worker runs as many tasks at
    once as it has threads). ``progress``: a bar of finished trajectories here, as in
    the local call. Returns the :class:`BatchResult` the local call returns."""
    item, B = batch_items(initial)
    parts = _chunks(item, B, h, params, chunk)
    options = {"workers": 1} | options | {"progress": False}
    futures = [client.submit(_run_fields, _folder(package), "integrate_many",
                             (_plain(start), n_steps, step),
                             dict(options, params=values), where, pure=False)
               for start, step, values, where in parts]
    return BatchResult.joined([_batch(fields) for fields in
                               _gathered(client, futures, B, "trajectories",
                                                         progress)])


def solve_bvp_many(client, package: ModuleType, starts, ends, n_steps: int, h=None,
                   params: Mapping | None = None, *, chunk: int = 10,
                   progress: bool | None = None, **options) -> BVPBatch:
    """``package.solve_bvp_many`` on the workers of ``client``, ``chunk`` solves per task;
    ``progress`` as in :func:`integrate_many`. Returns the :class:`BVPBatch` the local
    call returns."""
    options = options | {"progress": False}
    start_of, B = batch_items(starts)
    end_of = None if ends is None else batch_items(ends)[0]
    futures = []
    for a in range(0, B, chunk):
        rows = range(a, min(a + chunk, B))
        futures.append(client.submit(
            _run, _folder(package), "solve_bvp_many",
            (_gather(start_of, rows), None if end_of is None else _gather(end_of, rows),
             n_steps, _rows(h, rows, B)),
            dict(options, params=_rows_of(params, rows, B)), (a, rows[-1]), pure=False))
    return BVPBatch.of([r for batch in _gathered(client, futures, B, "solves", progress)
                        for r in batch.results])


def _gathered(client, futures: list, B: int, what: str, progress: bool | None) -> list:
    """The futures' results in order, gathered as they finish (a bar counts the B
    members); on an error or Ctrl-C the tasks not yet run are cancelled."""
    from distributed import as_completed

    index = {future.key: i for i, future in enumerate(futures)}
    out = [None] * len(futures)
    try:
        with Progress(B, what, progress) as bar:
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


#: A State travels as (_STATE, its fields): a worker that has imported no package yet
#: cannot unpickle the runtime's classes (``_runtime/results.py``).
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


def _chunks(item, B: int, h, params, chunk: int):
    """(initial data, h, params, (first, last)) of each chunk of the batch of B members
    ``item(b)``."""
    for a in range(0, B, chunk):
        rows = range(a, min(a + chunk, B))
        yield _gather(item, rows), _rows(h, rows, B), _rows_of(params, rows, B), (a, rows[-1])


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


def _rows(value, rows: range, B: int):
    """A per-member value's rows, or the one value for all."""
    if value is None or np.ndim(value) == 0:
        return value
    return np.broadcast_to(np.asarray(value, dtype=float), (B,))[rows.start:rows.stop]


def _rows_of(params: Mapping | None, rows: range, B: int):
    return None if params is None else {k: _rows(v, rows, B) for k, v in params.items()}
