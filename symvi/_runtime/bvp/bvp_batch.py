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

from ..step.batch import NamedErrors, run_threads
from .solve_arguments import points, solves
from .bvp import solve_bvp
from ..core.options import SolveOptions
from ..core.progress import Progress
from ..core.results import BVPBatch, BVPResult


def solve_bvp_many(model, starts, ends, n_steps: int, h=None, params: Mapping | None = None,
                   *, T=None, guesses: list | None = None, workers: int | None = None,
                   progress: bool | None = None, options: SolveOptions | None = None,
                   **keywords) -> BVPBatch:
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
    options : the :class:`.options.SolveOptions` of every solve, or its fields as
        keywords (``maxiter``, ``xtol``, ``ftol``, …), as :func:`.bvp.solve_bvp` takes them.

    Returns a :class:`BVPBatch`: ``result[b]`` is solve b's :class:`BVPResult`, ``cost``,
    ``T`` and ``statuses`` are arrays over the batch; SUCCESS only when every solve
    succeeded. Ctrl-C stops after the solves under way. Every argument, each solve's step
    or horizon and parameters included, is checked before any solve
    (:func:`.solve_arguments.solves`), and a batch whose results would not fit in memory
    together is refused with a ``MemoryError`` giving the estimate.
    """
    batch = solves(model, starts, ends, n_steps, h, params, T=T, guesses=guesses,
                   workers=workers, options=options, keywords=keywords)
    results: list[BVPResult | None] = [None] * batch.size
    stop = threading.Event()

    def work(indices: np.ndarray) -> None:
        for b in indices:
            if stop.is_set():
                return
            with NamedErrors(b, stop, "solve"):
                results[b] = solve_bvp(
                    model, batch.start_of(b), batch.end_of(b), batch.n_steps,
                    None if batch.steps is None else float(batch.steps[b]),
                    batch.overrides(b),
                    T=None if batch.horizons is None else float(batch.horizons[b]),
                    guess=None if batch.guesses is None else batch.guesses[b],
                    options=batch.options, progress=False)
            bar.update()
    with Progress(batch.size, "solves", progress) as bar:
        run_threads(work, batch.size, batch.workers, stop)
    return BVPBatch.of(results)


def continuation(model, start, end, n_steps: int, h=None, path: Mapping | None = None, *,
                 T=None, params: Mapping | None = None, guess=None,
                 progress: bool | None = None, options: SolveOptions | None = None,
                 **keywords) -> BVPBatch:
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
    options : the :class:`.options.SolveOptions` of every solve, or its fields as
        keywords, as in :func:`solve_bvp_many`.

    Returns a :class:`BVPBatch` of the K solves in order, whose message names the
    failures. Every argument, each point's parameters included, is checked before the
    first solve (:func:`.solve_arguments.points`), and a path whose results would not fit
    in memory together is refused with a ``MemoryError`` giving the estimate.
    """
    checked = points(model, start, end, n_steps, h, path, T=T, params=params,
                     options=options, keywords=keywords)
    results, previous = [], guess
    with Progress(checked.size, "solves", progress) as bar:
        for point in checked.points:
            result = solve_bvp(model, start, end, checked.n_steps, h, point, T=T,
                               guess=previous, options=checked.options, progress=False)
            results.append(result)
            bar.update()
            if result.success:
                previous = result
    return BVPBatch.of(results)

