"""Mesh sequencing: a whole-trajectory solve at many steps started from the solution at a
few (issue 50, items 1 and 5).

From its guess (the cubic or the chord between the ends) the Newton iteration at N steps
meets the whole nonlinearity of the problem at full resolution, and pays N for every
iteration of it: the interior point of the cart-pole swing-up took 51 iterations and
6.3 s at N = 10⁴, the planar flyer's (its straight guess crosses the keep-out disc)
STALLED there. The discrete solutions converge as N grows (order 2 in h from States, 1
from nodes at the ends), so the solution at N_c = ``coarse`` steps, resampled on the
groupoid (``symvi_path_resample``: a cubic Hermite curve in the chart at each coarse
node), is within O(h_c) of the solution at N, and the fine solve starts near it — with
bounds at the barrier parameter :data:`.options.NEAR_MU` (the swing-up at N = 10⁴: 40
iterations at N_c = 250, then 9, in 0.8 s). A free horizon starts from the coarse optimum's.

The coarse problem has the fine one's boundary data where they mean the same at any step:
States, ends at rest (every fixed node of an end the same), or a pair groupoid's nodes,
whose velocities (q₁ − q₀)/h are kept by scaling the differences from the outer node by
h_c/h. Elsewhere (moving ends on a group, given as nodes) the solve starts from the guess.
Where the coarse solve fails, or the fine one fails for its start (stalled, out of
iterations, diverged, …), the solve from the guess follows — not where the fine solve
reached its rounding limit (ILL_CONDITIONED), which the solve from the guess meets as well
(rigid_body_oc at N = 10⁶: 97 s for the same verdict, 18 s without it); every result
counts the iterations of all the solves it ran, its message says which, and its history
holds their rows in the order they ran.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..core.options import NEAR_MU
from ..core.paths import Resampled, flat_configurations
from ..core.results import BVPResult, State, Status

#: Sequencing applies from N = SPAN × coarse steps (2000 by default, where the lifted
#: system takes over): below, a Newton iteration at N costs little more than one at N_c
#: and the coarse solve about what it saves (the slew at N = 1000: 31 + 8 iterations,
#: 0.25 s, against 33 from the guess, 0.18 s).
SPAN = 8


def applies(model, N: int, guess, options) -> bool:
    """Whether a solve at N steps from ``guess`` starts from a coarse solution."""
    return (options.coarse > 0 and N >= SPAN * options.coarse
            and (guess is None or isinstance(guess, str)))


def sequenced(solve, model, start, end, N: int, h: float, p: np.ndarray, guess, options,
              from_states: bool) -> BVPResult | None:
    """The solve at N steps (``solve(start, end, N, h, guess, options)``, the caller's
    solve of checked arguments, parameters ``p``) from the solution at
    ``options.coarse`` steps resampled; None where the boundary data do not carry to the
    coarse step."""
    Nc = options.coarse
    ends = _coarse_ends(model, start, end, Nc / N, from_states)
    if ends is None:
        return None
    plain = options.replace(coarse=0)
    try:
        coarse = solve(*ends, Nc, h * N / Nc, guess, plain)
    except ValueError:
        # the coarse ends checked against the bounds: a pair's nodes moving out at the
        # edge of a bound are stretched past it by h_c/h (the swing-up's cart 0.4 mm
        # inside its track at 0.1 m/s, N = 2000); the solve from the guess checks the
        # user's own data
        return None
    fine_h = coarse.T / N if model.info.free_horizon else h
    if not coarse.success:
        direct = solve(start, end, N, h, guess, plain)
        return _combined(coarse, direct, f"the solve at {Nc} steps failed "
                                         f"({coarse.status.name}); from the guess")
    nodes = resampled(model, coarse, N + from_states, Nc, from_states, p)
    if nodes is None:
        return _combined(coarse, solve(start, end, N, h, guess, plain),
                         f"the solution at {Nc} steps leaves the retraction's chart "
                         f"between two nodes; from the guess")
    fine_options = plain.replace(mu_start=min(plain.mu_start, NEAR_MU))
    fine = solve(start, end, N, fine_h, nodes, fine_options)
    note = (f"mesh sequencing: from the solution at {Nc} steps ({coarse.iterations} "
            f"iterations), resampled")
    if fine.success or fine.status == Status.ILL_CONDITIONED:
        return _combined(coarse, fine, note)
    direct = solve(start, end, N, h, guess, plain)
    return _combined(_combined(coarse, fine, note), direct,
                     f"that start failed ({fine.status.name}); from the guess")


def _coarse_ends(model, start, end, ratio: float, from_states: bool):
    """(start, end) of the coarse problem (module docstring), or None."""
    if from_states or isinstance(start, State):
        return start, end
    ends = (_scaled(model, start, ratio, 0), None if end is None else
            _scaled(model, end, ratio, -1))
    return None if ends[0] is None or (end is not None and ends[1] is None) else ends


def _scaled(model, value, ratio: float, outer: int):
    """An end's fixed nodes at the coarse step: as they are at rest; a pair groupoid's
    differences from the outer node (index ``outer``) grown by h_c/h = 1/``ratio``,
    which keeps the velocities; None otherwise."""
    leaves = value if isinstance(value, tuple) else (value,)
    arrays = [np.asarray(a, dtype=float) for a in leaves]
    if all((a == a[:1]).all() for a in arrays):
        return value
    if model.matrix_dims or len(arrays) != 1:
        return None
    nodes = arrays[0]
    return nodes[outer] + (nodes - nodes[outer]) / ratio


def resampled(model, coarse: BVPResult, steps: int, Nc: int, from_states: bool,
              p: np.ndarray) -> Resampled | None:
    """The free nodes of the fine path (``steps`` elements) on the coarse solution: fine
    node j at time (j − o)h lies at coarse position (j − o)·h/h_c + o, o = ½ from States
    (nodes at the half steps), else 0; None where the resampling leaves the chart."""
    count = (coarse.x if coarse.x is not None else
             (coarse.g if not isinstance(coarse.g, tuple) else coarse.g[0])).shape[0]
    xc = np.ascontiguousarray(coarse.x if coarse.x is not None and model.m
                              else np.zeros((count, 0)), dtype=float)
    gc = np.ascontiguousarray(flat_configurations(model, coarse.g, count, "coarse nodes")
                              if model.matrix_dims else np.zeros((count, 0)))
    offset = 0.5 if from_states else 0.0
    N = steps - from_states
    where = np.clip((np.arange(steps + 1) - offset) * (Nc / N) + offset, 0.0, count - 1.0)
    x = np.zeros((steps + 1, xc.shape[1]))
    g = np.zeros((steps + 1, gc.shape[1]))
    code = model.lib.symvi_path_resample(model.ptr(xc), model.ptr(gc), count,
                                         model.ptr(where), steps + 1, model.ptr(x),
                                         model.ptr(g), model.ptr(p))
    if code != 0:
        return None
    r = model.order
    lam, active = _windows(coarse, steps + 1 - r, N / Nc, offset, r)
    last = (x[steps + 1 - r:], g[steps + 1 - r:]) if model.end_free else None
    return Resampled(x[r:steps + 1 - r], g[r:steps + 1 - r], lam, active, last)


def _windows(coarse: BVPResult, windows: int, refinement: float, offset: float, r: int):
    """(multipliers, active set) of the fine windows from the coarse window nearest each
    (window w centred at node w + r/2), or (None, None) without inequalities. A window's
    multipliers weigh its constraints in Σ_w (L_d + λ_w·Φ_w + z_w·c_w), L_d = O(h): they
    scale with h, so the coarse ones shrink by h/h_c = 1/``refinement`` (the slew's
    largest z: 6.7e-3 at N = 250, 1.6e-3 at 1000)."""
    if coarse.bound_multipliers is None or coarse.active is None:
        return None, None
    count = coarse.bound_multipliers.shape[0]
    centre = np.arange(windows) + r / 2
    nearest = np.clip(np.rint((centre - offset) / refinement + offset - r / 2), 0,
                      count - 1).astype(int)
    parts = [coarse.bound_multipliers[nearest]]
    if coarse.multipliers is not None:
        parts.insert(0, coarse.multipliers[nearest])
    return np.concatenate(parts, axis=1) / refinement, coarse.active[nearest].copy()


def _combined(first: BVPResult, then: BVPResult, note: str) -> BVPResult:
    """``then`` counting ``first``'s iterations, history, residual and step norms too
    (first's first), its message prefixed by ``note``."""
    history = {key: np.concatenate([first.history[key], then.history[key]])
               for key in then.history} if first.history and then.history else then.history
    return replace(then, iterations=first.iterations + then.iterations,
                   message=f"{note}: {then.message}", history=history,
                   residual_norms=np.concatenate([first.residual_norms, then.residual_norms]),
                   step_norms=np.concatenate([first.step_norms, then.step_norms]))
