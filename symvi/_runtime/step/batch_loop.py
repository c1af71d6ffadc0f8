"""The batch loop in C: slices of a batch stepped by one ``symvi_integrate_batch`` call.

Each trajectory of a slice is the single run's C loop on the same data, and its momenta,
energies and conserved quantities the same path kernels on the same windows, so the
numbers are the single call's bit for bit. What the single run does around its C loop per
trajectory — the result's arrays, the kernels along the path, the thinning to every k-th
node — is done here once per slice and per field, so that the Python work (which holds the
GIL) is small beside the C work (which does not), and threads scale.
"""
from __future__ import annotations

import numpy as np

from ..core.options import StepOptions
from ..core.results import BatchResult, Status
from .stepping import entries, finite, layout, outcome
from ..core.storage import first_kept, kept_count

#: Stored bytes of one trajectory's full path above which a batch is run trajectory by
#: trajectory (the chunked single loop) instead: a slice holds whole paths.
MAX_PATH_BYTES = 2**24
#: New steps per slice: about 0.01–0.05 s of C, so that a stop is noticed promptly.
SLICE_STEPS = 2**16


class Stacked:
    """The batch's stacked arrays, filled slice by slice, padded past failures."""

    def __init__(self, model, B: int, n_steps: int, keep: int, quantities: bool = True):
        self.model, self.keep, self.quantities = model, keep, quantities
        self.fields = layout(model, quantities)[1]
        self.arrays, self.lengths = {}, {}
        for name, (lag, offset, shape) in self.fields.items():
            kept = kept_count(entries(model, name, lag, n_steps), offset, keep)
            integer = name == "newton_iterations"
            self.arrays[name] = np.full((B, kept, *shape), -1 if integer else np.nan,
                                        dtype=np.intc if integer else float)
            self.lengths[name] = np.zeros(B, dtype=int)
        self.t = np.full((B, kept_count(n_steps + 1, 0, keep)), np.nan)
        self.statuses = np.zeros(B, dtype=np.int8)
        self.messages = [""] * B

    def result(self) -> BatchResult:
        arrays = dict(self.arrays)
        B = len(self.statuses)
        if "g" in arrays:
            g = arrays.pop("g")
            parts = self.model.configurations(g.reshape(-1, g.shape[-1]))
            arrays["g"] = tuple(p.reshape(B, -1, *p.shape[1:]) for p in parts) \
                if isinstance(parts, tuple) else parts.reshape(B, -1, *parts.shape[1:])
        lengths = dict(self.lengths) | {"t": self.lengths["x"]}
        status, message = BatchResult.summary(self.statuses, self.messages)
        return BatchResult(t=self.t, statuses=self.statuses, messages=tuple(self.messages),
                           lengths=lengths, status=status, message=message,
                           labels=self.model.labels,
                           **{"g": None, "momenta": None, "energy": None, "noether": None}
                           | arrays)


def run_slice(model, stacked: Stacked, buffers: "Scratch", indices, starts, n_steps: int,
              P: np.ndarray, H: np.ndarray, from_state: bool, options: StepOptions) -> None:
    """Step the trajectories ``indices`` (their stencil prefixes and configurations
    ``starts``, parameter rows P, steps H; Newton under ``options``) by one C call into
    ``buffers``; store them in ``stacked``."""
    maxiter = options.maxiter
    c, K = len(indices), model.stencil_elements
    new, E = n_steps - (K - 1), n_steps
    scratch = buffers.take(c)
    z0 = np.ascontiguousarray(np.stack([z for z, _ in starts]))
    g0 = np.ascontiguousarray(np.stack([g for _, g in starts]))
    ffi = model.ffi
    done, status = np.zeros(c, dtype=np.int_), np.zeros(c, dtype=np.intc)
    rnorm = np.zeros(c)
    model.lib.symvi_integrate_batch(
        c, model.ptr(z0), model.ptr(g0), new, model.ptr(P), P.shape[1], model.ptr(H),
        maxiter, options.xtol, options.ftol, *[model.ptr(scratch[k]) for k in ("x", "f", "g")],
        ffi.from_buffer("int[]", scratch["newton_iterations"]), ffi.from_buffer("long[]", done),
        model.ptr(rnorm), ffi.from_buffer("int[]", status), int(stacked.quantities),
        *[model.ptr(scratch[k]) for k in ("momenta", "energy", "noether")])
    completed = _store_completed(model, stacked, np.asarray(indices), scratch, status == 0,
                                 E, H, outcome(Status.SUCCESS, n_steps, K, from_state, 0, 0.0,
                                               maxiter, 0, 0.0))
    for j in np.flatnonzero(~completed):
        steps, code = int(done[j]), Status(int(status[j]))
        tried = int(scratch["newton_iterations"][j, steps]) if code and steps < new else 0
        message = outcome(code, n_steps, K, from_state, steps, float(H[j]), maxiter, tried,
                          float(rnorm[j]))
        _store(model, stacked, indices[j], j, scratch, K - 1 + steps, float(H[j]), code,
               message)


def _store_completed(model, stacked: Stacked, indices: np.ndarray, scratch: dict,
                     ok: np.ndarray, E: int, H: np.ndarray, message: str) -> np.ndarray:
    """Store the slice's runs that completed every step with finite outputs, all at once
    (one thinning per field); return which they were (the others: :func:`_store`)."""
    keep, thinned = stacked.keep, {}
    for name, (lag, offset, _) in stacked.fields.items():
        count = entries(model, name, lag, E)
        thinned[name] = scratch[name][:, first_kept(offset, keep): max(count, 0): keep]
        if name != "newton_iterations":
            finite = np.isfinite(thinned[name].reshape(len(ok), -1)).all(axis=1)
            ok = ok & finite
    rows = indices[ok]
    for name, values in thinned.items():
        stacked.arrays[name][rows, :values.shape[1]] = values[ok]
        stacked.lengths[name][rows] = values.shape[1]
    nodes = thinned["x"].shape[1]
    stacked.t[rows, :nodes] = H[ok, None] * (keep * np.arange(nodes))
    stacked.statuses[rows] = int(Status.SUCCESS)
    for b in rows:
        stacked.messages[b] = message
    return ok


class Scratch:
    """Full-path outputs of the C call for up to ``rows`` trajectories of E elements,
    allocated once per worker task and reused by its slices: fresh megabytes per slice
    cost page faults, many more where the allocator hands freed memory back to the system
    at once (a Dask worker sets glibc's trim threshold to 64 KiB: 20–40 % slower)."""

    def __init__(self, fields: dict, rows: int, E: int):
        self.buffers = {}
        for name, (lag, _, shape) in fields.items():
            integer = name == "newton_iterations"
            self.buffers[name] = np.empty((rows, max(E + lag, 1), *shape),
                                          dtype=np.intc if integer else float)
        for name in ("g", "momenta", "energy", "noether"):   # what the C call is not
            self.buffers.setdefault(name, np.empty((rows, 1)))  # asked to write

    def take(self, c: int) -> dict:
        """The first c rows, zeroed (contiguous: a leading slice)."""
        out = {name: buffer[:c] for name, buffer in self.buffers.items()}
        for values in out.values():
            values.fill(0)
        return out


def _store(model, stacked: Stacked, b: int, j: int, scratch: dict, elements: int, h: float,
           code: Status, message: str) -> None:
    """Trajectory j of the slice, thinned to every keep-th node, as trajectory b."""
    keep, out = stacked.keep, {}
    for name, (lag, offset, _) in stacked.fields.items():
        count = entries(model, name, lag, elements)
        values = scratch[name][j, first_kept(offset, keep): max(count, 0): keep]
        out[name] = values
        stacked.arrays[name][b, :len(values)] = values
        stacked.lengths[name][b] = len(values)
    nodes = len(out["x"])
    stacked.t[b, :nodes] = h * (keep * np.arange(nodes))
    if code == Status.SUCCESS:
        if "g" in out:
            out["g"] = model.configurations(out["g"])
        code, message = finite(out, message, h * keep)
    stacked.statuses[b], stacked.messages[b] = int(code), message

