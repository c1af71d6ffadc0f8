"""Sweeps of a parameter or of the step: ``symvi sweep`` (issue 24, item 4).

A sweep runs a model's example once per value of one swept quantity — a parameter of the
model, or the step h — as one batch: ``integrate_many`` on threads for a step-by-step
example, ``continuation`` (each solve warm-started from the previous success) for an
optimal-control one. Each member is judged by what tells a user whether the run can be
trusted: the energy error max |E − E₀| of a conservative integration (else the largest
drift of its conserved quantities, else the mean Newton iterations per step), or the
optimal cost of a solve. The result is written to a NumPy archive and, on request, drawn
against the swept values.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ._runtime.core.results import BatchResult, BVPBatch, State, Status, write_npz


@dataclass(frozen=True)
class Sweep:
    """The outcome of a sweep.

    Attributes
    ----------
    name : what was swept: a parameter's name, or ``"h"``.
    values : (B,) the swept values, in order.
    batch : the batch result (:class:`BatchResult` of the integrations, or
        :class:`BVPBatch` of the solves), member b at ``values[b]``.
    measure : (B,) what judges each member (NaN where it failed before producing one).
    measure_name : what ``measure`` is, e.g. ``"max |E − E₀|"``.
    """

    name: str
    values: np.ndarray
    batch: BatchResult | BVPBatch
    measure: np.ndarray
    measure_name: str

    @property
    def status(self) -> Status:
        return self.batch.status

    @property
    def success(self) -> bool:
        return self.batch.success

    @property
    def succeeded(self) -> np.ndarray:
        return self.batch.succeeded

    def slope(self) -> float | None:
        """The fitted order d log(measure) / d log(h) of a step sweep judged by an energy
        error or a drift (None otherwise, or with fewer than three usable members)."""
        usable = self.succeeded & np.isfinite(self.measure) & (self.measure > 0)
        if self.name != "h" or self.measure_name.startswith("mean") or usable.sum() < 3:
            return None
        return float(np.polyfit(np.log(self.values[usable]), np.log(self.measure[usable]),
                                1)[0])

    def save(self, file) -> None:
        """Write the sweep to the NumPy archive ``file`` atomically: ``swept`` (the name),
        ``values``, ``measure`` and ``measure_name``, ``statuses`` (by name) and
        ``messages``, and the batch's arrays (integrations: ``t``, ``x``, ``f``, ``g``,
        ``energy``, …, padded with NaN past a failure, with ``lengths_<name>``; solves:
        ``cost``, ``T`` and the stacked ``x``, ``g``, ``controls``, …)."""
        arrays = {"swept": np.array(self.name), "values": self.values,
                  "measure": self.measure, "measure_name": np.array(self.measure_name),
                  "statuses": np.array([Status(s).name for s in self.batch.statuses]),
                  "messages": np.array([m for m in _messages(self.batch)])}
        arrays |= _batch_arrays(self.batch)
        write_npz(file, arrays)

    def format(self) -> list[str]:
        """The summary lines ``symvi sweep`` prints."""
        ok = self.succeeded
        lines = [f"status     {self.status.name}: {self.batch.message}"]
        if ok.any():
            best, worst = np.nanmin(self.measure[ok]), np.nanmax(self.measure[ok])
            lines.append(f"{_short(self.measure_name):<10} {best:.3e} … {worst:.3e} over "
                         f"the {ok.sum()} that succeeded")
        slope = self.slope()
        if slope is not None:
            lines.append(f"order      {self.measure_name} ∝ h^{slope:.2f} (least-squares fit)")
        return lines


def run_sweep(module, example, name: str, values: np.ndarray, *, steps: int, h: float,
              params: dict, workers: int | None = None, keep_every: int = 1,
              progress: bool | None = None, options: dict | None = None) -> Sweep:
    """Run ``example`` (the model's :class:`symvi.Example`) of the generated package
    ``module`` once per value of ``name`` (a parameter, or ``"h"``), the other
    parameters ``params``, ``steps`` steps of ``h`` (an optimal-control example: N =
    ``steps``, horizon ``steps·h``), the solver's ``options`` by name (``xtol``,
    ``maxiter``, …: the continuation's or the step map's)."""
    options = dict(options or {})
    B = len(values)
    if example.whole_trajectory:
        if name == "h":
            raise ValueError("an optimal-control sweep varies a parameter; the step of a "
                             "whole trajectory follows from --steps and its horizon")
        batch = module.continuation(example.start, example.end, steps, h,
                                    {name: values}, params=params, progress=progress,
                                    guess=example.guess_nodes(steps, module.model.order),
                                    **options)
        return Sweep(name, values, batch, batch.cost, "cost")
    step = values if name == "h" else h
    overrides = dict(params) | ({} if name == "h" else {name: values})
    batch = module.integrate_many(_replicate(example.run_from, B), steps, step, overrides,
                                  workers=workers, keep_every=keep_every, progress=progress,
                                  **options)
    measure, measure_name = _judge(batch)
    return Sweep(name, values, batch, measure, measure_name)


def _judge(batch: BatchResult) -> tuple[np.ndarray, str]:
    """Each trajectory's energy error, else its conserved quantities' largest drift, else
    its mean Newton iterations per step (over its own entries)."""
    if batch.energy is not None and batch.energy.shape[1]:
        return _largest_change(batch.energy), "max |E − E₀|"
    if batch.noether is not None and batch.noether.shape[1]:
        return _largest_change(batch.noether), "max |F − F₀|"
    iterations = np.where(batch.newton_iterations >= 0, batch.newton_iterations, np.nan)
    with np.errstate(invalid="ignore"):
        return np.nanmean(iterations, axis=1), "mean Newton iterations"


def _largest_change(values: np.ndarray) -> np.ndarray:
    """max over time (and components) of |v − v₀| per member; NaN padding ignored."""
    change = np.abs(values - values[:, :1])
    change = change.reshape(len(values), -1)
    out = np.full(len(values), np.nan)
    some = np.isfinite(change).any(axis=1)
    out[some] = np.nanmax(change[some], axis=1)
    return out


def _replicate(value: Any, B: int):
    """The example's initial data with a leading batch axis of B copies."""
    if isinstance(value, State):
        return State(**{k: _replicate(getattr(value, k), B) for k in ("v", "x", "g")
                        if getattr(value, k) is not None})
    if isinstance(value, tuple):
        return tuple(_replicate(part, B) for part in value)
    array = np.asarray(value, dtype=float)
    return np.repeat(array[None], B, axis=0)


def _batch_arrays(batch: BatchResult | BVPBatch) -> dict:
    if isinstance(batch, BatchResult):
        out = {}
        for name in ("t", "x", "f", "momenta", "energy", "noether", "newton_iterations"):
            if getattr(batch, name) is not None:
                out[name] = getattr(batch, name)
        g = batch.g
        out |= {f"g_{i}": part for i, part in enumerate(g)} if isinstance(g, tuple) else \
            ({} if g is None else {"g": g})
        return out | {f"lengths_{k}": v for k, v in batch.lengths.items()}
    out = {"cost": batch.cost, "T": batch.T}
    for name in ("t", "x", "f", "g", "controls", "multipliers"):
        first = getattr(batch[0], name)
        if isinstance(first, tuple):
            out |= {f"{name}_{i}": np.stack([getattr(r, name)[i] for r in batch])
                    for i in range(len(first))}
        elif first is not None:
            out[name] = batch.stack(name)
    return out


def _messages(batch: BatchResult | BVPBatch) -> Sequence[str]:
    return batch.messages if isinstance(batch, BatchResult) else \
        [r.message for r in batch.results]


def _short(name: str) -> str:
    return {"max |E − E₀|": "energy", "max |F − F₀|": "drift", "cost": "cost"}.get(
        name, "newton")
