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

import os
import threading
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from typing import Callable, Mapping

import numpy as np

from . import arguments, batch_loop, stepping
from .legendre import TransformError, first_fibres
from .results import BatchResult, State, StepResult
from .memory import require
from .progress import Progress
from .storage import bytes_per_node

#: Tasks per worker: small enough tasks that a slow trajectory does not idle the others.
TASKS_PER_WORKER = 8


def integrate_many(model, initial, n_steps: int, h, params: Mapping | None = None, *,
                   workers: int | None = None, keep_every: int = 1, final_only: bool = False,
                   maxiter: int = 50, xtol: float = 1e-12, ftol: float = 0.0,
                   progress: bool | None = None, quantities: bool = True) -> BatchResult:
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

    Returns a :class:`BatchResult`: every array of :class:`StepResult` with a leading
    batch axis, each trajectory's status and message (``statuses``, ``messages``), and
    ``result[b]``, trajectory b as the :class:`StepResult` of the single call. Its status
    is SUCCESS only when every trajectory succeeded.
    """
    item, B = batch_items(initial)
    steps = per_trajectory(h, B, "h")
    overrides = parameter_batch(params, B)
    n_steps = stepping.step_count(model, n_steps)
    keep = n_steps if final_only else arguments.count(keep_every, "keep_every", 1)
    workers = arguments.count(workers if workers is not None else usable_cores(),
                              "workers", 1)
    maxiter = arguments.iterations(maxiter)
    xtol, ftol = arguments.tolerance(xtol, "xtol"), arguments.tolerance(ftol, "ftol")
    quantities = arguments.flag(quantities, "quantities")
    _check_memory(model, B, n_steps, keep, quantities)
    run = _Run(model, item, B, isinstance(initial, State), steps, overrides, n_steps, keep,
               (maxiter, xtol, ftol), quantities)
    long = bytes_per_node(model, quantities) * (n_steps + 1) > batch_loop.MAX_PATH_BYTES
    with Progress(B, "trajectories", progress) as bar:
        # long runs one by one through the chunked single loop: bounded memory
        return (run.one_by_one if long else run.in_slices)(workers, bar)


class _Run:
    """A checked batch: its members' data and the two ways of running it."""

    def __init__(self, model, item, B: int, from_state: bool, steps: np.ndarray, overrides,
                 n_steps: int, keep: int, newton: tuple, quantities: bool):
        self.model, self.item, self.B, self.from_state = model, item, B, from_state
        self.steps, self.overrides, self.n_steps, self.keep = steps, overrides, n_steps, keep
        self.newton, self.quantities = newton, quantities
        self.stop = threading.Event()

    def one_by_one(self, workers: int, bar: Progress) -> BatchResult:
        """Each trajectory by :func:`.stepping.run_steps`, then stacked."""
        results: list[StepResult | None] = [None] * self.B

        def work(indices: np.ndarray) -> None:
            for b in indices:
                if self.stop.is_set():
                    return
                with NamedErrors(b, self.stop):
                    results[b] = stepping.run_steps(
                        self.model, self.item(b), self.n_steps, self.steps[b],
                        self.overrides(b), *self.newton, self.keep, False, self.stop,
                        self.quantities)
                bar.update()
        run_threads(work, self.B, workers, self.stop)
        return BatchResult.stacked(results)

    def in_slices(self, workers: int, bar: Progress) -> BatchResult:
        """Slices of trajectories by one C call each, stored into one stacked result."""
        stacked = batch_loop.Stacked(self.model, self.B, self.n_steps, self.keep,
                                     self.quantities)
        per_slice = max(1, batch_loop.SLICE_STEPS // self.n_steps)

        def work(indices: np.ndarray) -> None:
            parts = np.array_split(indices, -(-len(indices) // per_slice))
            buffers = batch_loop.Scratch(stacked.fields, len(parts[0]), self.n_steps)
            for part in parts:
                if self.stop.is_set():
                    return
                P, H = self._slice_data(part)
                starts = _starts(self.model, self.item, part, H, P, self.from_state, self.stop)
                batch_loop.run_slice(self.model, stacked, buffers, part, starts,
                                     self.n_steps, P, H, self.from_state, *self.newton)
                bar.update(len(part))
        run_threads(work, self.B, workers, self.stop)
        return stacked.result()

    def _slice_data(self, part: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The parameter rows and steps of the trajectories ``part``."""
        P, H = [], np.empty(len(part))
        for j, b in enumerate(part):
            with NamedErrors(b, self.stop):
                P.append(self.model.params(self.overrides(b)))
                H[j] = arguments.step_size(self.steps[b])
        return np.ascontiguousarray(np.stack(P)), H


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


def batch_items(initial) -> tuple[Callable[[int], object], int]:
    """(b ↦ trajectory b's initial data, B) for batched initial data (see
    :func:`integrate_many`); the arrays must agree on B."""
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

    structure = collect(initial, "initial")
    sizes = {where: array.shape[0] for where, array in leaves}
    if len(set(sizes.values())) > 1:
        raise ValueError("initial: the arrays disagree on the batch size (the leading "
                         "axis): " + ", ".join(f"{w} has {n}" for w, n in sizes.items()))
    B = next(iter(sizes.values()))
    if B == 0:
        raise ValueError("initial: the batch is empty")

    def item(b: int, value=structure):
        if isinstance(value, State):
            return State(**{k: item(b, getattr(value, k)) for k in ("v", "x", "g")
                            if getattr(value, k) is not None})
        if isinstance(value, tuple):
            return tuple(item(b, part) for part in value)
        return value[b]
    return item, B


def parameter_batch(params: Mapping | None, B: int) -> Callable[[int], dict | None]:
    """b ↦ trajectory b's parameter overrides; each value a number or B of them."""
    if params is None:
        return lambda b: None
    if not isinstance(params, Mapping):
        raise ValueError(f"params must be a mapping name → value(s), got {type(params).__name__}")
    columns = {name: per_trajectory(value, B, f"params[{name!r}]")
               for name, value in params.items()}
    return lambda b: {name: column[b] for name, column in columns.items()}


def per_trajectory(value, B: int, what: str) -> np.ndarray:
    array = arguments.real_array(value, what)
    try:
        return np.broadcast_to(array, (B,))
    except ValueError:
        raise ValueError(f"{what}: shape {array.shape} does not broadcast against the batch "
                         f"of {B} trajectories (give one value, or {B})") from None


def usable_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:         # not on Linux
        return os.cpu_count() or 1


def _check_memory(model, B: int, n_steps: int, keep: int, quantities: bool) -> None:
    """Refuse a batch whose paths (with their ``quantities`` or without) would not fit,
    before running it: each path is held twice (its own result, then the stacked arrays)."""
    nodes = n_steps // keep + 2
    require(2.0 * B * nodes * bytes_per_node(model, quantities),
            f"a batch of {B:,} paths of {nodes:,} stored nodes",
            "store every k-th node (keep_every=k) or only the final one (final_only=True)")

