"""The step map: the C loop integrates the steps (Newton per step in C), chunk by chunk.

The loop returns to Python every ~0.05 s, so that Ctrl-C (raised by Python between two C
calls) stops a long run promptly, and so that a run can keep only every k-th node (see
:mod:`.storage`). Each chunk continues from the stencil the C loop would have slid to, so
a chunked run is bitwise the run of one call.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..core import arguments
from ..core.model_info import Kernel
from ..core.options import StepOptions
from ..core.progress import ProgressLine
from ..core.results import State, Status, StepResult
from ..core.storage import Series, check_memory

_FAILURE = {
    Status.MAX_ITERATIONS: "Newton's method did not converge in {maxiter} iterations",
    Status.SINGULAR_JACOBIAN: ("the step Jacobian is singular (the step map is not defined "
                               "at these data: D₁,₂ᵣL_d, the mixed derivative of L_d in its "
                               "first and last nodes, is singular)"),
    Status.NON_FINITE: "the residual or the update became non-finite (NaN or inf)",
    Status.OUTSIDE_CHART: ("the increment hξ left the retraction's chart (Cayley: I − hξ/2 "
                           "singular; exp: θ(hξ) ≥ π)"),
    Status.DIVERGED: ("Newton's iterates diverged (at iteration {iterations} of at most "
                      "{maxiter}: the update had more than doubled twice in a row, to its "
                      "largest yet, without contracting); the predictor is outside the "
                      "basin of the step's solution — try a smaller h"),
}
#: Seconds of C between two returns to Python (the latency of Ctrl-C).
CHUNK_SECONDS = 0.05
#: Steps of the chunk buffer when only every k-th node is kept.
BUFFER_STEPS = 2**16


def integrate(model, initial, n_steps: int, h: float, params: Mapping[str, float] | None = None,
              *, maxiter: int = StepOptions.unset("maxiter"),
              xtol: float = StepOptions.unset("xtol"), ftol: float = StepOptions.unset("ftol"),
              keep_every: int = 1, quantities: bool = True, raise_on_failure: bool = False,
              progress: bool | None = None, options: StepOptions | None = None,
              **keywords) -> StepResult:
    """Integrate ``n_steps`` steps of the discrete Euler–Lagrange equations.

    Parameters
    ----------
    initial : a :class:`State` (first-order models): ``State(x=q0, v=v0)`` on a pair
        groupoid, ``State(g=g0, v=xi0)`` on a Lie group, ``State(x=x0, g=g0, v=xi0)`` on
        an action groupoid — the first element from the discrete Legendre transform
        (:mod:`.legendre`). Or the first K−1 elements themselves. Pair groupoid: the
        first 2r nodes q_0, …, q_{2r−1} as an array (2r, n) (r the order). Matrix Lie
        group: ``(g_0, xi)`` with g_0 the initial configuration (d, d) and xi the first
        2r−1 increments ξ_k (2r−1, n). Action groupoids and products: ``(x_0, f)`` or
        ``(x_0, g_0, f)`` (see :meth:`CompiledModel.initial_state`). A group acting on
        itself (``ActionGroupoid.on_itself``): ``(g_0, f)`` or ``State(g=g0, v=xi0)``,
        x_0 filled from g_0; a given x_0 must be g_0's entries.
    n_steps : the number of steps: the result has n_steps elements, n_steps + 1 nodes on
        [0, n_steps·h], the first K − 1 elements — from the transform, or given — counted
        among them (at least K − 1: one on a first-order model, three on a second-order
        one).
    h : time step (> 0).
    params : parameter overrides (mapping name → value); the others keep the defaults
        compiled in (``INFO.defaults``).
    maxiter, xtol, ftol : Newton stops when ‖Δf‖∞ ≤ xtol·(1 + ‖f‖∞) or ‖R‖∞ ≤ ftol.
    keep_every : store only the nodes 0, k, 2k, … and what belongs to them (the elements
        leaving them, their momenta, energies and conserved quantities, the iterations of
        the steps that computed them; ``t`` gives their times), so that a long run fits
        in memory. A run whose stored path would not fit is refused before anything is
        allocated, with a ``MemoryError`` giving the estimate.
    quantities : compute the momenta, energies and conserved quantities along the path
        (True); False returns the path alone (those fields None), no work past the
        step loop: on the pendulum they take a fifth of the call's time.
    raise_on_failure : raise :class:`NewtonError` instead of returning a failed result.
    progress : a line on stderr saying how far the run has come, shown once it has run
        a few seconds (:mod:`.progress`) and erased at its end: True, False, or None (the
        default) for one when stderr is a terminal.
    options, keywords : the step's Newton options as one :class:`.options.StepOptions`
        (or a mapping of its fields) instead of ``maxiter``, ``xtol``, ``ftol`` (an
        options object and a keyword for one field are refused together); a keyword
        that is not an option is refused by name with the list of the valid ones.

    A step whose Jacobian is singular (the step map is not defined there) fails with
    ``SINGULAR_JACOBIAN`` even where the residual vanishes, and a run whose path, momenta,
    energies or conserved quantities are not all finite is never a success
    (``NON_FINITE``). A step whose Newton iterates run away (the update more than doubles
    twice in a row, to its largest yet, without contracting) fails with ``DIVERGED``
    within a few iterations instead of iterating to ``maxiter``. Ctrl-C stops a run
    within a fraction of a second (``KeyboardInterrupt``).
    """
    return run_steps(model, initial, n_steps, h, params, options, keep_every,
                     raise_on_failure, quantities=quantities, progress=progress,
                     keywords=dict(maxiter=maxiter, xtol=xtol, ftol=ftol) | keywords)


class Stopped(Exception):
    """A run stopped between two chunks because its ``stop`` event was set."""


def run_steps(model, initial, n_steps: int, h: float, params,
              options: StepOptions | None, keep_every: int, raise_on_failure: bool,
              stop: threading.Event | None = None, quantities: bool = True,
              keywords: Mapping | None = None, progress: bool | None = False) -> StepResult:
    """:func:`integrate` (``options``, ``keywords`` and ``progress`` as there; a batch's
    members show none), stopping (:class:`Stopped`) between two chunks once ``stop`` is
    set: how a batch (:mod:`.batch`) ends its worker threads promptly."""
    from_state, K = isinstance(initial, State), model.stencil_elements
    n_steps = step_count(model, n_steps)
    keep = arguments.count(keep_every, "keep_every", 1)
    h = arguments.step_size(h)
    options = StepOptions.of(options, keywords, "integrate")
    p = model.params(params)
    z0, g0 = model.initial_state(initial, h, p)
    new = n_steps - (K - 1)         # the initial elements are the first steps
    quantities = arguments.flag(quantities, "quantities")
    check_memory(model, n_steps, keep, BUFFER_STEPS if keep > 1 else 0, quantities)
    run = _Run(model, new, keep, p, h, stop, quantities)
    with ProgressLine(f"integrate {model.name}", progress) as line:
        code, steps, rnorm, iterations = run.loop(z0, g0, options, line)
    status = Status(code)
    measured = rounding_growth(run, z0, g0, options) \
        if status == Status.SUCCESS and amplification_note(K // 2, n_steps) else None
    message = outcome(status, n_steps, K, from_state, steps, h, options.maxiter, iterations,
                      rnorm, measured)
    result = run.result(steps, status, message)
    return result.raise_for_status() if raise_on_failure else result


def step_count(model, n_steps) -> int:
    """n_steps checked: an integer, at least the K − 1 elements of the initial data."""
    K = model.stencil_elements
    return arguments.count(n_steps, "n_steps", K - 1, why=(
        f" (the initial data's {K - 1} elements count among the steps)" if K > 2
        else " (the initial data's element counts among the steps)"))


#: Relative rounding amplification from which a run's message warns.
AMPLIFICATION_NOTE = 1e-6


def amplification_note(order: int, n_steps: int, measured: float | None = None) -> str:
    """A note on long runs of order r ≥ 2: the free part of an order-r step map (the 2r-th
    difference of the nodes) has the polynomials of degree 2r − 1 in the step index as
    solutions, so it can amplify a rounding error ε of one step to ε·n^{2r−1}/(2r − 1)!
    after n steps (minimum snap: 5.7e3 off after 10³ steps from exact data). Empty below
    :data:`AMPLIFICATION_NOTE`. That is the polynomial part only: unstable dynamics
    amplify rounding exponentially (issue 53: an order-2 model with an unstable mode
    e^{t}, 5000 steps, 4.6e-6 by the polynomial and 2e-2 from one ulp of its data), so
    the note gives the larger of the two and the run's ``measured`` bound
    (:func:`rounding_growth`) where it was measured."""
    if order < 2:
        return ""
    growth = float(np.finfo(float).eps) * float(n_steps) ** (2 * order - 1) \
        / math.factorial(2 * order - 1)
    if growth <= AMPLIFICATION_NOTE:
        return ""
    check = ("check the path against solve_bvp between its ends, which does not "
             "accumulate it")
    polynomial = f"n^{2 * order - 1}/{2 * order - 1}!"
    if measured is not None:
        return (f"; note: rounding accumulates along this order-{order} step map — its "
                f"free part amplifies it like {polynomial} ({growth:.1e} relative over "
                f"these steps) and, measured by a second run from initial data one unit "
                f"in their last place off, up to {max(measured, growth):.1e} relative — "
                f"{check}")
    return (f"; note: the free part of an order-{order} step map amplifies rounding like "
            f"{polynomial}, up to {growth:.1e} relative over these steps — {check}")


def rounding_growth(run: "_Run", z0: np.ndarray, g0: np.ndarray,
                    options: StepOptions) -> float:
    """A bound on the relative error rounding leaves in ``run``'s path, from the step
    map's measured growth: a second run from z0 with each entry moved by one unit in
    the last place of the data's size, in random directions; d_k, the largest change of
    stored node k (nodes and fibres) over the path's size, grows by G_k = d_k/d_0 from
    the start. Each step's rounding (ε) grows from step k to the end by G_n/G_k (one
    dominant mode), so the error is at most ε·Σ_k G_n/max(1, G_k) — with no growth ε per
    step, n·ε. ∞ when the second run fails."""
    model, eps = run.model, float(np.finfo(float).eps)
    rng = np.random.default_rng(0)
    size = max(float(np.abs(z0).max(initial=0.0)), 1.0)
    shadow = _Run(model, run.n_steps, run.keep, run.p, run.h, quantities=False)
    changed = z0 + eps * size * rng.choice((-1.0, 1.0), z0.size)
    if shadow.loop(changed, g0.copy(), options)[0] != 0:
        return math.inf
    rows = []
    for name in ("x", "f"):
        a, b = run.series[name].values, shadow.series[name].values
        if a.size:
            count = min(len(a), len(b))
            rows.append((a[:count].reshape(count, -1), b[:count].reshape(count, -1)))
    count = min(len(a) for a, _ in rows)
    scale = max(max(float(np.abs(a).max(initial=0.0)) for a, _ in rows), 1e-300)
    d = np.max([np.abs(a[:count] - b[:count]).max(axis=1) for a, b in rows], axis=0) / scale
    if not np.all(np.isfinite(d)):
        return math.inf
    G = np.maximum(d / max(d[0], eps), 1.0)
    return float(eps * run.keep * np.sum(G[-1] / G))


def outcome(status: Status, n_steps: int, K: int, from_state: bool, steps: int, h: float,
            maxiter: int, iterations: int, rnorm: float, measured: float | None = None
            ) -> str:
    """The message of a run of ``n_steps`` steps whose C loop ended with ``status`` after
    ``steps`` new steps (the failed one took ``iterations``, its residual ``rnorm``;
    ``measured``, the rounding bound from the run's growth: :func:`rounding_growth`)."""
    if status == Status.SUCCESS:
        return f"integrated {n_steps} step{'s' * (n_steps != 1)}" + (
            " (the first by the discrete Legendre transform)" if from_state
            else f" (the first {K - 1} given)" if K > 2 else " (the first given)") \
            + amplification_note(K // 2, n_steps, measured)
    reason = _FAILURE[status].format(maxiter=maxiter, iterations=iterations)
    return (f"step {K + steps} of {n_steps} (to t = {(K + steps) * h:.6g}) failed: "
            f"{reason}; residual norm {rnorm:.3e}")


@dataclass(frozen=True)
class _Quantity:
    """A result field computed by a kernel on windows of ``width`` consecutive elements;
    window i is entry i + ``shift`` of the field (``first``: windows 0 … first − 1 only,
    in the first chunk)."""

    field: str
    kernel: Kernel
    width: int
    shift: int = 0
    first: int = 0


def layout(model, quantities: bool = True) -> tuple[list[_Quantity],
                                                   dict[str, tuple[int, int, tuple]]]:
    """The derived quantities, and every stored field as (lag, offset, shape): a path of E
    elements has E + lag entries of the field, entry i belonging to node i + offset.

    Momenta: states 0 … r−1 from F⁻L_d, state i + r from F⁺L_d on window i, state j at
    node j; the energy of each element; the conserved quantities of window i at node
    i + r − 1 (paper §4.4); the Newton iterations of step s at node K + s. Without
    ``quantities``, the path alone.
    """
    r, n, K = model.order, model.n, model.stencil_elements

    def width(kernel: Kernel) -> int:
        return model.info.kernel(kernel).width(model.m, n)

    w, G = width(Kernel.MOMENTUM_PLUS), model.info.configuration_dim
    fields = {"x": (1, 0, (model.m,)), "f": (0, 0, (n,)), "newton_iterations": (1 - K, K, ())}
    if G:
        fields["g"] = (1, 0, (G,))
    if not quantities:
        return [], fields
    derived = [_Quantity("momenta", Kernel.MOMENTUM_MINUS, w, 0, r),
               _Quantity("momenta", Kernel.MOMENTUM_PLUS, w, r)]
    fields["momenta"] = (r - w + 1, 0, (n,) if r == 1 else (r, n))
    if model.info.has_energy:
        derived.append(_Quantity("energy", Kernel.ENERGY, width(Kernel.ENERGY)))
        fields["energy"] = (1 - width(Kernel.ENERGY), 0, ())
    if model.info.symmetries:
        derived.append(_Quantity("noether", Kernel.NOETHER, width(Kernel.NOETHER)))
        fields["noether"] = (1 - width(Kernel.NOETHER), r - 1, (len(model.info.symmetries),))
    return derived, fields


def entries(model, name: str, lag: int, elements: int) -> int:
    """How many entries of the field ``name`` (of lag ``lag``) a path of ``elements``
    elements determines: elements + lag, except the momenta of a short path.

    State j < r comes from F⁻L_d on the 2r − 1 elements after it, state j ≥ r from F⁺L_d
    on the 2r − 1 before it; a path of fewer than 3r − 2 elements has no elements after
    its states E − 2r + 2 … r − 1 and none before them, so they are not determined, and
    its momenta are its first E − 2r + 2 states (F⁻L_d's) only.
    """
    if name != "momenta":
        return elements + lag
    r, w = model.order, model.order - lag + 1     # lag = r − w + 1, w the window
    return elements + lag if elements >= r + w - 1 else max(elements - w + 1, 0)


class _Run:
    """The stored series of one run and the chunk loop that fills them."""

    def __init__(self, model, n_steps: int, keep: int, p: np.ndarray, h: float,
                 stop: threading.Event | None = None, quantities: bool = True):
        self.model, self.n_steps, self.keep, self.p, self.h = model, n_steps, keep, p, h
        self.stop = stop
        m, n, K = model.m, model.n, model.stencil_elements
        E, G = K - 1 + n_steps, model.info.configuration_dim
        self.G = G
        self.quantities, self.fields = layout(model, quantities)
        self.series = {name: Series.empty(E + lag, offset, keep, shape,
                                          np.intc if name == "newton_iterations" else float)
                       for name, (lag, offset, shape) in self.fields.items()}
        if keep == 1:    # the C loop writes straight into the result
            self.x, self.f = self.series["x"].values, self.series["f"].values
            self.g = self.series["g"].values if G else np.zeros((1, 1))
            self.iters = self.series["newton_iterations"].values
        else:
            steps = min(BUFFER_STEPS, n_steps)
            self.x, self.f = np.zeros((K + steps, m)), np.zeros((K - 1 + steps, n))
            self.g = np.zeros((K + steps if G else 1, max(G, 1)))
            self.iters = np.zeros(steps, np.intc)

    def loop(self, z0, g0, options: StepOptions,
             line: ProgressLine | None = None) -> tuple[int, int, float, int]:
        """Run the chunks, each step's Newton under ``options``, the progress ``line``
        updated between two; returns (status code, steps done, last residual norm,
        Newton iterations of the last step tried)."""
        model, K = self.model, self.model.stencil_elements
        done, rnorm = model.ffi.new("long *"), model.ffi.new("double *")
        # the Newton iteration's state, carried from chunk to chunk (templates/stepper.c.j2)
        carry = model.ffi.new("double[]", int(model.lib.symvi_integrate_carry()))
        start, chunk = 0, 4096
        while True:
            if self.stop is not None and self.stop.is_set():
                raise Stopped
            size = min(chunk, self.n_steps - start, BUFFER_STEPS if self.keep > 1 else chunk)
            at = start if self.keep == 1 else 0
            x, f, g = self.x[at:], self.f[at:], self.g[at:] if self.G else self.g
            began = time.perf_counter()
            code = model.lib.symvi_integrate(
                model.ptr(z0), model.ptr(g0), size, model.ptr(self.p), self.h, options.maxiter,
                options.xtol, options.ftol, model.ptr(x), model.ptr(f), model.ptr(g),
                model.ffi.from_buffer("int[]", self.iters[at:]), done, rnorm, carry)
            elapsed = time.perf_counter() - began
            finished = code != 0 or start + size == self.n_steps
            self._store(start, int(done[0]), finished)
            if finished:
                tried = self._iterations_at(at + int(done[0])) if code else 0
                return code, start + int(done[0]), float(rnorm[0]), tried
            # the next chunk starts from the stencil this one slid to
            z0 = np.concatenate([x[size], f[size: size + K - 1].reshape(-1)])
            g0 = g[size].copy() if self.G else g0
            if self.keep > 1:
                self.x[0], self.f[: K - 1] = x[size], f[size: size + K - 1]
                self.g[0] = g[size] if self.G else 0.0
            start += size
            chunk = int(min(max(size * CHUNK_SECONDS / max(elapsed, 1e-6), 1024), 2**30))
            if line is not None:
                line.update(lambda: self._progress(start))

    def _progress(self, done: int) -> str:
        """The progress line's text after ``done`` of the run's new steps."""
        return f"step {done:,} of {self.n_steps:,} ({100 * done / self.n_steps:.0f} %)"

    def _iterations_at(self, index: int) -> int:
        """Newton iterations of the step at ``index`` of the buffer: a failed step writes
        them where a completed one would (0 if the first elements failed before any step)."""
        return int(self.iters[index]) if index < len(self.iters) else 0

    def _store(self, start: int, done: int, finished: bool) -> None:
        """Store what the chunk that began at step ``start`` computed: its ``done`` new
        elements, and the windows that begin in it (all that remain, if ``finished``)."""
        elements = self.model.stencil_elements - 1 + done    # valid in this chunk's buffer
        at = start if self.keep == 1 else 0
        if self.keep > 1:
            path = {"x": (self.x, elements + 1), "f": (self.f, elements),
                    "g": (self.g, elements + 1), "newton_iterations": (self.iters, done)}
            for name, (values, valid) in path.items():
                if name in self.series:
                    self.series[name].put(start, values[: valid if finished else done])
        for q in self.quantities:
            if q.first:     # fewer than `first` on a short path (see entries)
                windows = min(q.first, elements - q.width + 1) if start == 0 else 0
            else:
                windows = elements - q.width + 1 if finished else done
            if windows > 0:
                series = self.series[q.field]
                values = self.model.along_vector(q.kernel, self.x[at:], self.f[at:], self.h,
                                                 self.p, windows)
                series.put(start + q.shift, values.reshape(windows, *series.values.shape[1:]))

    def result(self, steps: int, status: Status, message: str) -> StepResult:
        """The StepResult of a run that completed ``steps`` steps."""
        elements = self.model.stencil_elements - 1 + steps
        out = {"g": None, "energy": None, "noether": None}
        out |= {name: self.series[name].until(entries(self.model, name, lag, elements))
                for name, (lag, _, _) in self.fields.items()}
        if status == Status.SUCCESS:
            status, message = finite(out, message, self.h * self.keep)
        if self.model.info.inequalities:
            # the step map is the problem's without its inequalities (z = 0): a run from an
            # optimum's data entered the planar flyer's keep-out disc (a hunt)
            message += (f"; the step map integrates the equations without the "
                        f"{len(self.model.info.inequalities)} inequalities, which bind "
                        f"solve_bvp only: this path need not satisfy them")
        if self.G:
            out["g"] = self.model.configurations(out["g"])
        out["t"] = node_times(out["x"].shape[0], self.keep, self.h)
        return StepResult(status=status, message=message, labels=self.model.labels, **out)


def node_times(count: int, keep: int, h: float) -> np.ndarray:
    """t_j = (keep·j)·h for the ``count`` kept nodes, in place in one array: temporaries
    of a long run's length cost their page faults (a tenth of a pendulum run's time)."""
    t = np.arange(count, dtype=float)
    t *= keep           # exact: integers below 2**53
    t *= h
    return t


def finite(out: dict, message: str, spacing: float) -> tuple[Status, str]:
    """NON_FINITE, naming the first quantity and time, when an output is not finite."""
    for name in ("x", "f", "g", "momenta", "energy", "noether"):
        values = out.get(name)
        if values is None or np.isfinite(values).all():
            continue
        row = int(np.argwhere(~np.isfinite(values.reshape(values.shape[0], -1)))[0, 0])
        label = {"x": "nodes (base points)", "f": "fibres", "g": "configurations",
                 "energy": "energies", "noether": "conserved quantities"}.get(name, name)
        scale = float(np.abs(out["x"]).max(initial=0.0))
        return Status.NON_FINITE, (
            f"{message}, but the {label} are not finite (first at entry {row}, t ≈ "
            f"{row * spacing:.6g}): the path's magnitudes (max |x| = {scale:.3g}) overflow "
            f"double precision")
    return Status.SUCCESS, message
