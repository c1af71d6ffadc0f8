"""Where the step map writes: the path and its derived quantities, every k-th node kept.

A stepped path has E = n_steps elements and E + 1 nodes. Every stored array
is indexed by one running index (a node, an element, a window of the kernel evaluated on
it), and each index belongs to a node: element e and the energy of element e to node e,
state j of the momenta to node j, the conserved quantities of window i to node i + r − 1,
the Newton iterations of step s to node K + s, the node it computed. With
``keep_every = k`` only indices whose node is a multiple of k are kept, so that a long
run fits in memory; with k = 1 everything is kept and the C loop writes straight into the
result.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .memory import SMALL, available_bytes, require


def first_kept(offset: int, keep: int) -> int:
    """The first index on a kept node, when index i belongs to node i + ``offset``."""
    return (-offset) % keep


def kept_count(total: int, offset: int, keep: int) -> int:
    """How many of the indices 0 … total − 1 lie on kept nodes (also the position of
    the first kept index ≥ total)."""
    return max(0, -(-(total - first_kept(offset, keep)) // keep))


@dataclass
class Series:
    """One stored array: ``total`` values of a running index, whose node is the index plus
    ``offset``; of them those on kept nodes (every ``keep``-th)."""

    total: int
    offset: int
    keep: int
    values: np.ndarray

    @classmethod
    def empty(cls, total: int, offset: int, keep: int, shape=(), dtype=np.float64):
        series = cls(max(total, 0), offset, keep, np.zeros(0))
        series.values = np.zeros((series.kept(series.total), *shape), dtype=dtype)
        return series

    def _position(self, index: int) -> int:
        """Position in ``values`` of the first kept index ≥ ``index``."""
        return kept_count(index, self.offset, self.keep)

    def kept(self, total: int) -> int:
        """How many of the indices 0 … total − 1 are kept."""
        return self._position(total)

    def put(self, start: int, values: np.ndarray) -> None:
        """Store ``values`` of the indices start, start + 1, … (those that are kept)."""
        stop = min(start + len(values), self.total)
        at, end = self._position(start), self._position(stop)
        if end > at:
            first = at * self.keep + first_kept(self.offset, self.keep)
            self.values[at:end] = values[first - start: stop - start: self.keep]

    def until(self, total: int) -> np.ndarray:
        """The kept values among the first ``total`` indices (a failed run stops early)."""
        return self.values[: self.kept(total)]


def bytes_per_node(model, quantities: bool = True) -> int:
    """Bytes stored per kept node: base point, fibre, configuration, time and the Newton
    iterations and, with ``quantities``, the momenta (r·n at second order), energy and
    conserved quantities."""
    info = model.info
    derived = (model.order * model.n + int(info.has_energy)
               + len(info.symmetries)) if quantities else 0
    return 8 * (model.m + model.n + info.configuration_dim + 1 + derived) + 4


def check_memory(model, elements: int, keep: int, buffered: int,
                 quantities: bool = True) -> None:
    """Refuse a run whose stored path (with its ``quantities`` or without) would not fit
    in memory, before allocating it."""
    nodes = elements // keep + 1
    per_node = float(bytes_per_node(model, quantities))
    needed = per_node * (nodes + buffered)
    if needed < SMALL:
        return
    available = available_bytes() or needed
    # the smallest multiple of keep whose path would fill at most half of the memory
    fitting = keep * max(2, int(np.ceil(needed / (0.5 * available))))
    require(needed, f"a path of {elements + 1:,} nodes ({nodes:,} stored)",
            f"store every k-th node with keep_every={fitting} or integrate in segments "
            f"(each from the last elements of the previous)")


def check_path_memory(model, n_steps: int) -> None:
    """Refuse a whole-trajectory solve whose Newton matrices would not fit in memory: per
    node, the band and its factorised copy ((3 bw + 1)·B doubles each, B = n + s unknowns,
    bw = (r + 1)·B − 1), those of the lifted system where the model has one, and some
    eight copies of the path (trial steps, results)."""
    B = model.n + model.constraints
    band = 3 * ((model.order + 1) * B - 1) + 1
    path = model.m + model.info.configuration_dim + model.n + model.constraints
    per_node = 2 * band * B + 8 * path
    if model.info.lifted:      # the lifted system (lifted.py): 3n + s per node
        lifted = 3 * model.n + model.constraints
        per_node += 2 * (3 * (lifted + 2 * model.n - 1) + 1) * lifted
    needed = 8.0 * (n_steps + 1) * per_node
    require(needed, f"the whole-trajectory solve with N = {n_steps:,}",
            "use fewer steps")
