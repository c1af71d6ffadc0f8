"""Many trajectories at once: :func:`integrate_many` (issue 24).

Each trajectory is the single run :func:`.stepping.integrate` would compute — the same C
loop on the same data, so the same numbers bit for bit — and the batch is spread over
threads: the C loop releases the GIL, so two workers keep two cores busy. A trajectory
whose Newton step fails keeps its own status and message and the others go on. The
stacked arrays are padded with NaN past a failed trajectory's last node.

Threads stop promptly: every run checks a shared event between two chunks of its C loop
(about 0.05 s apart), which Ctrl-C, or bad data in one trajectory, sets before the
exception is raised; no worker is left running.
"""
from __future__ import annotations

import threading
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from typing import Callable, Mapping

import numpy as np

from . import batch_loop, stepping
from .batch_arguments import Trajectories, trajectories
from .legendre import TransformError, first_fibres
from ..core.options import StepOptions
from ..core.progress import Progress
from ..core.results import BatchResult, StepResult
from ..core.storage import bytes_per_node

#: Tasks per worker: small enough tasks that a slow trajectory does not idle the others.
TASKS_PER_WORKER = 8


def integrate_many(model, initial, n_steps: int, h, params: Mapping | None = None, *,
                   workers: int | None = None, keep_every: int = 1, final_only: bool = False,
                   maxiter: int = StepOptions.unset("maxiter"),
                   xtol: float = StepOptions.unset("xtol"),
                   ftol: float = StepOptions.unset("ftol"), progress: bool | None = None,
                   quantities: bool = True, options: StepOptions | None = None,
                   **keywords) -> BatchResult:
    """Integrate a batch of trajectories of ``n_steps`` steps each, in parallel threads.

    Parameters
    ----------
    initial : the initial data of :func:`.stepping.integrate` with a leading batch axis
        on every array: ``State(x=(B, n), v=(B, n))``, nodes (B, 2r, n) on a pair
        groupoid, ``(g0 (B, d, d), xi (B, 2r−1, n))`` on a Lie group, and so on. Tuples
        are the structure (as in the single call); every array in them is batched.
    n_steps : steps per trajectory (n_steps + 1 nodes on [0, n_steps·h]).
    h : the step, one for all or one per trajectory (an array of shape (B,)).
    params : parameter overrides, each value a number or an array of shape (B,) (one
        value per trajectory, broadcast against the batch).
    workers : threads (default: the cores this process may use).
    keep_every, final_only : store only the nodes 0, k, 2k, … (see
        :func:`.stepping.integrate`), or only the first and the final node, so that many
        long trajectories fit in memory.
    maxiter, xtol, ftol : Newton's options of every step (see :func:`.stepping.integrate`).
    progress : a progress bar of finished trajectories on stderr (``tqdm``): True, False,
        or None for one when tqdm is installed and stderr is a terminal.
    quantities : compute each trajectory's momenta, energies and conserved quantities
        (default); False gives the paths alone (those fields None), less work and memory.
    options, keywords : the steps' Newton options as one :class:`.options.StepOptions`,
        as :func:`.stepping.integrate` takes them.

    Returns a :class:`BatchResult`: every array of :class:`StepResult` with a leading
    batch axis, each trajectory's status and message (``statuses``, ``messages``), and
    ``result[b]``, trajectory b as the :class:`StepResult` of the single call. Its status
    is SUCCESS only when every trajectory succeeded. Every argument, each trajectory's
    step and parameters included, is checked before any work
    (:func:`.batch_arguments.trajectories`), and a batch whose paths would not fit in
    memory is refused with a ``MemoryError`` giving the estimate.
    """
    batch = trajectories(model, initial, n_steps, h, params, workers=workers,
                         keep_every=keep_every, final_only=final_only, maxiter=maxiter,
                         xtol=xtol, ftol=ftol, quantities=quantities, options=options,
                         keywords=keywords)
    run = _Run(model, batch)
    long = bytes_per_node(model, batch.quantities) * (batch.n_steps + 1) \
        > batch_loop.MAX_PATH_BYTES
    with Progress(batch.size, "trajectories", progress) as bar:
        # long runs one by one through the chunked single loop: bounded memory
        return (run.one_by_one if long else run.in_slices)(batch.workers, bar)


class _Run:
    """A checked batch (:class:`.batch_arguments.Trajectories`) and the two ways of
    running it."""

    def __init__(self, model, batch: Trajectories):
        self.model, self.batch = model, batch
        self.stop = threading.Event()

    def one_by_one(self, workers: int, bar: Progress) -> BatchResult:
        """Each trajectory by :func:`.stepping.run_steps`, then stacked."""
        batch = self.batch
        results: list[StepResult | None] = [None] * batch.size

        def work(indices: np.ndarray) -> None:
            for b in indices:
                if self.stop.is_set():
                    return
                with NamedErrors(b, self.stop):
                    results[b] = stepping.run_steps(
                        self.model, batch.item(b), batch.n_steps, batch.steps[b],
                        batch.overrides(b), batch.options, batch.keep, False, self.stop,
                        batch.quantities)
                bar.update()
        run_threads(work, batch.size, workers, self.stop)
        return BatchResult.stacked(results)

    def in_slices(self, workers: int, bar: Progress) -> BatchResult:
        """Slices of trajectories by one C call each, stored into one stacked result."""
        batch = self.batch
        stacked = batch_loop.Stacked(self.model, batch.size, batch.n_steps, batch.keep,
                                     batch.quantities)
        per_slice = max(1, batch_loop.SLICE_STEPS // batch.n_steps)

        def work(indices: np.ndarray) -> None:
            parts = np.array_split(indices, -(-len(indices) // per_slice))
            buffers = batch_loop.Scratch(stacked.fields, len(parts[0]), batch.n_steps)
            for part in parts:
                if self.stop.is_set():
                    return
                # the parameters and steps were checked with the arguments
                P = np.ascontiguousarray(batch.parameters[part])
                H = np.array(batch.steps[part], dtype=np.float64)
                starts = _starts(self.model, batch.item, part, H, P, batch.from_state,
                                 self.stop)
                batch_loop.run_slice(self.model, stacked, buffers, part, starts,
                                     batch.n_steps, P, H, batch.from_state, batch.options)
                bar.update(len(part))
        run_threads(work, batch.size, workers, self.stop)
        return stacked.result()


def _starts(model, item, part: np.ndarray, H: np.ndarray, P: np.ndarray, from_state: bool,
            stop: threading.Event) -> list[tuple[np.ndarray, np.ndarray]]:
    """The stencil prefixes and configurations of the trajectories ``part``; from States,
    their discrete Legendre transforms solved together (:func:`.legendre.first_fibres`)."""
    if not from_state:
        starts = []
        for j, b in enumerate(part):
            with NamedErrors(b, stop):
                starts.append(model.initial_state(item(b), H[j], P[j]))
        return starts
    parts = []
    for b in part:
        with NamedErrors(b, stop):
            parts.append(model.state_parts(item(b)))
    X, V = np.stack([x for x, _, _ in parts]), np.stack([v for _, v, _ in parts])
    try:
        F = first_fibres(model, X, V, H, P)
    except TransformError as exc:
        stop.set()
        raise ValueError(f"trajectory {part[exc.index]}: {exc}") from None
    return [(np.concatenate([x, f]), g) for (x, _, g), f in zip(parts, F)]


class NamedErrors:
    """Re-raise bad data of member b (ValueError, MemoryError) naming it — "trajectory
    b", or ``noun`` — after stopping the other workers; a stopped run just returns."""

    def __init__(self, b: int, stop: threading.Event, noun: str = "trajectory"):
        self.b, self.stop, self.noun = b, stop, noun

    def __enter__(self):
        return self

    def __exit__(self, kind, exc, traceback):
        if kind is stepping.Stopped:
            return True
        if kind is not None and issubclass(kind, (ValueError, MemoryError)):
            self.stop.set()
            raise kind(f"{self.noun} {self.b}: {exc}") from None
        return False


def run_threads(work: Callable[[np.ndarray], None], B: int, workers: int,
                stop: threading.Event) -> None:
    """``work`` on parts of range(B) in ``workers`` threads; the first error (or Ctrl-C)
    sets ``stop``, and no thread outlives the call."""
    tasks = np.array_split(np.arange(B), min(B, workers * TASKS_PER_WORKER))
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="symvi") as pool:
        futures = pending = {pool.submit(work, task) for task in tasks}
        try:
            while pending:
                # a timed wait: a blocking one would notice Ctrl-C only when it ends
                done, pending = wait(pending, timeout=0.1, return_when=FIRST_EXCEPTION)
                for future in done:
                    future.result()
        except BaseException:
            stop.set()          # the others end at their next chunk; `with` waits for them
            for future in futures:
                future.cancel()
            raise
