"""The first guesses a user may give a whole-trajectory solve beyond the free nodes in
the node layout (issue 53, item 2): a function t ↦ :class:`State`, and a previous result
at another number of steps.

On a Lie group or an action groupoid the node layout means hand-building configurations
(and base points moving with them); a function of time gives them as a user thinks of a
path: ``guess=lambda t: State(g=expm(t * A), v=...)``. Its States are read at the free
nodes' times — t_j = j·h, or (j − ½)h from States, whose nodes lie at the half steps —
for their positions (x, g); the velocities are not used (the nodes determine them).

A previous result at another N is resampled on the groupoid as mesh sequencing resamples
its coarse solution (:func:`.sequence.resampled`: a cubic Hermite curve in the chart at
each node, its multipliers and active set with it), the horizon scaled to this solve's:
a solution at N = 50 starts the solve at N = 200 near its own solution.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..core.paths import Resampled
from ..core.results import BVPResult, State
from . import sequence


def converted(model, guess, N: int, h: float, p: np.ndarray, from_states: bool):
    """``guess`` in a form :func:`..core.paths.initial_path` reads: a function of time
    evaluated at the free nodes, a previous result at another N resampled; any other
    guess as it is. ``N`` counts the elements (from States, N + 1 of them)."""
    if isinstance(guess, BVPResult) and guess.f is not None and _steps(guess) != N:
        return _resampled(model, guess, N, p, from_states)
    if callable(guess):
        return _from_function(model, guess, N, h, from_states)
    return guess


def _steps(result: BVPResult) -> int:
    """The elements of a previous result's path (its nodes less one)."""
    return result.t.size - 1


def _resampled(model, previous: BVPResult, N: int, p: np.ndarray,
               from_states: bool) -> Resampled:
    """A previous result at another N, resampled to N elements; ValueError where its
    boundary data were of another kind or its path leaves the retraction's chart."""
    if (previous.t_states is not None) != from_states:
        kind = "States" if from_states else "nodes"
        raise ValueError(f"guess: a previous result at another number of steps starts a "
                         f"solve whose boundary data are of its own kind; this one's are "
                         f"{kind}, the result's are not")
    nodes = sequence.resampled(model, previous, N, _steps(previous) - from_states,
                               from_states, p)
    if nodes is None:
        raise ValueError("guess: the previous result, resampled to this solve's steps, "
                         "leaves the retraction's chart between two of its nodes")
    return nodes


def _from_function(model, guess: Callable[[float], State], N: int, h: float,
                   from_states: bool):
    """The free nodes r … N − r from States at their times, in the node layout."""
    r = model.order
    times = (np.arange(r, N + 1 - r) - 0.5 * from_states) * h
    states = [guess(float(t)) for t in times]
    for t, state in zip(times, states):
        if not isinstance(state, State):
            raise ValueError(f"guess: a function of time must return a State, got "
                             f"{type(state).__name__} at t = {t:.6g}")
    x = np.array([np.ravel(s.x) if s.x is not None else np.zeros(0) for s in states])
    dims = model.matrix_dims
    if not dims:
        return x
    g = _configurations(states, dims, times)
    return g if model.m == 0 or not x.size else (x, g)


def _configurations(states, dims: tuple[int, ...], times: np.ndarray):
    """The configurations of ``states``: one (count, d, d) array, or a tuple of them per
    matrix-group factor."""
    missing = [t for t, s in zip(times, states) if s.g is None]
    if missing:
        raise ValueError(f"guess: a State on a matrix Lie group needs its configuration "
                         f"g (none at t = {missing[0]:.6g})")
    if len(dims) == 1:
        return np.array([np.asarray(s.g, dtype=float) for s in states])
    return tuple(np.array([np.asarray(s.g[k], dtype=float) for s in states])
                 for k in range(len(dims)))
