"""Many whole-trajectory solves: :func:`solve_bvp_many` and :func:`continuation` (issue 24).

``solve_bvp_many`` runs independent solves — one per start–end pair, parameter set or
horizon — on worker threads (the band assembly and factorisation run in C and LAPACK,
outside the GIL), each the single :func:`.bvp.solve_bvp` call. ``continuation`` walks a
path of parameter values, each solve warm-started from the last that succeeded (its path,
multipliers and, with bounds, its active set), and says which ones failed: how a library
of optimal trajectories, or a sweep of a limit, is built without the loop. A failed solve
keeps its status and message; the others go on.
"""
from __future__ import annotations

import threading
from typing import Mapping

import numpy as np

from . import arguments
from .batch import NamedErrors, per_trajectory, run_threads, usable_cores, batch_items, parameter_batch
from .bvp import solve_bvp
from .progress import Progress
from .results import BVPBatch, BVPResult


def solve_bvp_many(model, starts, ends, n_steps: int, h=None, params: Mapping | None = None,
                   *, T=None, guesses: list | None = None, workers: int | None = None,
                   progress: bool | None = None, **options) -> BVPBatch:
    """Solve a batch of whole-trajectory problems on worker threads.

    Parameters
    ----------
    starts, ends : the boundary data of :func:`.bvp.solve_bvp` with a leading batch axis
        on every array (``ends`` None with end conditions other than fixed).
    n_steps : N, the same for every solve.
    h, T : the step or the horizon, one for all or one per solve (arrays of shape (B,)).
    params : parameter overrides, each a number or B of them.
    guesses : a first guess per solve (anything ``guess=`` takes), or None.
    workers : threads (default: the cores this process may use).
    progress : a progress bar of finished solves (``tqdm``): True, False, or None for one
        when tqdm is installed and stderr is a terminal.
    options : ``maxiter``, ``xtol``, ``ftol`` of :func:`.bvp.solve_bvp`.

    Returns a :class:`BVPBatch`: ``result[b]`` is solve b's :class:`BVPResult`, ``cost``,
    ``T`` and ``statuses`` are arrays over the batch; SUCCESS only when every solve
    succeeded. Ctrl-C stops after the solves under way.
    """
    start_of, B = batch_items(starts)
    end_of = (lambda b: None) if ends is None else _same_batch(ends, B)
    steps = None if h is None else per_trajectory(h, B, "h")
    horizons = None if T is None else per_trajectory(T, B, "T")
    overrides = parameter_batch(params, B)
    if guesses is not None and len(guesses) != B:
        raise ValueError(f"guesses: {len(guesses)} given for a batch of {B} solves")
    workers = arguments.count(workers if workers is not None else usable_cores(),
                              "workers", 1)
    results: list[BVPResult | None] = [None] * B
    stop = threading.Event()

    def work(indices: np.ndarray) -> None:
        for b in indices:
            if stop.is_set():
                return
            with NamedErrors(b, stop, "solve"):
                results[b] = solve_bvp(
                    model, start_of(b), end_of(b), n_steps,
                    None if steps is None else float(steps[b]), overrides(b),
                    T=None if horizons is None else float(horizons[b]),
                    guess=None if guesses is None else guesses[b], **options)
            bar.update()
    with Progress(B, "solves", progress) as bar:
        run_threads(work, B, workers, stop)
    return BVPBatch.of(results)


def continuation(model, start, end, n_steps: int, h=None, path: Mapping | None = None, *,
                 T=None, params: Mapping | None = None, guess=None,
                 progress: bool | None = None, **options) -> BVPBatch:
    """Solve along a path of parameter values, each solve warm-started from the last
    success.

    Parameters
    ----------
    start, end, n_steps, h, T : as in :func:`.bvp.solve_bvp`, the same for every point.
    path : parameter names → sequences of equal length K, the values at the K points.
    params : fixed overrides of other parameters.
    guess : the first solve's guess (default: the cubic guess). Solve k starts from the
        last solve before it that succeeded (its path, multipliers and, with bounds, its
        active set), or cold if none did.
    progress : a progress bar of finished solves, as in :func:`solve_bvp_many`.
    options : ``maxiter``, ``xtol``, ``ftol`` of :func:`.bvp.solve_bvp`.

    Returns a :class:`BVPBatch` of the K solves in order, whose message names the
    failures.
    """
    if not path:
        raise ValueError("continuation needs a path: parameter names → sequences of values")
    columns = {name: np.atleast_1d(arguments.real_array(values, f"path[{name!r}]"))
               for name, values in path.items()}
    lengths = {name: len(values) for name, values in columns.items()}
    if len(set(lengths.values())) != 1:
        raise ValueError(f"path: the sequences differ in length: {lengths}")
    K = next(iter(lengths.values()))
    results, previous = [], guess
    with Progress(K, "solves", progress) as bar:
        for k in range(K):
            point = dict(params or {}) | {name: values[k] for name, values in columns.items()}
            result = solve_bvp(model, start, end, n_steps, h, point, T=T, guess=previous,
                               **options)
            results.append(result)
            bar.update()
            if result.success:
                previous = result
    return BVPBatch.of(results)


def _same_batch(ends, B: int):
    end_of, size = batch_items(ends)
    if size != B:
        raise ValueError(f"ends: {size} given for a batch of {B} starts")
    return end_of
