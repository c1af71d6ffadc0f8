"""States as the boundary data of a whole-trajectory solve (issue 22): the element whose
midpoint is the state.

A second-order problem fixes its first and last elements, two nodes each. A state
(position, velocity) at t = 0 fixes the element whose midpoint it is: where each fibre
coordinate copies a base coordinate of the next node (a pair groupoid, as the package
records in ``INFO.fibre_nodes``) q₀ = q − h v/2 and q₁ = q + h v/2; on a matrix Lie
group g₀ = g τ(−hξ/2) and g₁ = g₀ τ(hξ), so that the increment is ξ and the midpoint
g₀ τ(hξ/2) is g (τ(−a) = τ(a)⁻¹ for the Cayley map and the exponential). Element k is then the state at t_k = k·h, k = 0 … N, on
[0, T = N·h], and the nodes sit at the half steps t = (k − ½)h, k = 0 … N + 1.

A window (elements k and k + 1) is centred at (k + ½)h, where both second-order rules
evaluate the integrand (paper eq. ``sdfinal``: velocity (ξ_k + ξ_{k+1})/2, acceleration
(ξ_{k+1} − ξ_k)/h), so the discrete cost Σ L_d is the midpoint rule on [0, T]. The
boundary elements are the exact solution's to O(h²) (their nodes are off by h²q̈/8, the
same at both nodes, so the velocity is off by O(h²) too), and the optimal cost and path
converge at order 2 in h. Nodes given directly fix the velocity at t = h/2 and sum over
[h/2, T − h/2]: the cost of a rest-to-rest problem then converges at order 1.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..core import arguments
from ..core.geometry import check_base_points, check_configurations
from ..core.paths import check_configured, held, held_base_points, node_velocities
from ..core.results import BVPResult, State


def given(start, end) -> bool:
    """Whether the boundary data are States (both ends); one State alone is refused."""
    kinds = isinstance(start, State), isinstance(end, State)
    if kinds[0] != kinds[1]:
        raise ValueError("boundary data: give States at both ends (positions and velocities, "
                         "t = 0 and t = T) or nodes at both ends, not one of each")
    return kinds[0]


def check_supported(model) -> None:
    """Raise ValueError where States cannot be boundary data of ``model``'s solve."""
    name = model.name
    if model.order != 2:
        raise ValueError(f"model {name!r}: States are boundary data of second-order problems; "
                         f"an order-{model.order} problem fixes its end nodes only (positions)")
    if model.end_free or model.end_count:
        raise ValueError(f"model {name!r}: its end is free or given by end conditions; give "
                         f"the start as nodes (a State fixes both ends)")


def element_nodes(model, state: State, h: float, p: np.ndarray, what: str):
    """The two nodes of the element whose midpoint is ``state`` (:func:`element`), in the
    layout of :func:`.bvp.solve_bvp`'s ``start``/``end``."""
    x, g = element(model, state, h, p, what)
    if not model.matrix_dims:
        return x
    return model.configurations(g) if model.m == 0 else (x, model.configurations(g))


def element(model, state: State, h: float, p: np.ndarray, what: str):
    """(base points (2, m), flat configurations (2, Σd²)) of the two nodes of the element
    whose midpoint is ``state``: the state's node moved by the node variations τ(∓hv/2) —
    x ∓ hv/2 on a pair factor, g τ(∓hξ/2) on a group factor, the base point of an action
    groupoid by the action (which keeps it on its manifold)."""
    v = arguments.finite_array(state.v, (model.n,), f"the {what} state's velocity v")
    x, g = _node(model, state, what)
    # the element's increment τ(hξ) within the chart (exp: an angle below π), which the
    # node variations themselves do not need
    inside = not model.matrix_dims or _retract(model, g[None], v[None], h) is not None
    first = _moved(model, x[None], g[None], v[None], -0.5 * h, p) if inside else None
    second = None if first is None else _moved(model, *first, v[None], h, p)
    if second is None:
        raise ValueError(f"the {what} state's velocity is outside the retraction's chart at "
                         f"h = {h:g} (Cayley: a half-turn; exp: an angle ≥ π per step); "
                         f"take more steps")
    return tuple(np.concatenate(pair) for pair in zip(first, second))


def _node(model, state: State, what: str) -> tuple[np.ndarray, np.ndarray]:
    """The state's position as one node (x, flat g), checked on its manifold and group;
    a group acting on itself takes its base point from the configuration."""
    g = np.zeros(0)
    if model.matrix_dims:
        g = model.configuration(state.g, f"the {what} state's configuration g")
        check_configurations(model, g[None], f"the {what} state's configuration g")
    if model.m and state.x is None and held(model):
        x = held_base_points(model, g)
    else:
        x = arguments.finite_array(state.x, (model.m,), f"the {what} state's position x") \
            if model.m else np.zeros(0)
    check_base_points(model, x[None], f"the {what} state's position x")
    check_configured(model, x[None], g[None], f"the {what} state's", 0)
    return x, g


def _retract(model, g: np.ndarray, f: np.ndarray, h: float) -> np.ndarray | None:
    """g_k τ(h f_k) for each node, or None when an increment is outside its chart."""
    g, f = np.ascontiguousarray(g), np.ascontiguousarray(f)
    out = np.empty_like(g)
    if model.lib.symvi_path_retract(model.ptr(g), model.ptr(f), len(g), h, model.ptr(out)):
        return None
    return out


def _moved(model, x: np.ndarray, g: np.ndarray, eta: np.ndarray, scale: float,
           p: np.ndarray):
    """Copies of the nodes (x, g) moved by τ(scale·η) each, or None off the chart."""
    x, g = np.array(x, dtype=float), np.array(g, dtype=float)
    eta = np.ascontiguousarray(eta, dtype=float)
    if model.lib.symvi_path_move(model.ptr(x), model.ptr(g), model.ptr(eta), len(eta),
                                 scale, model.ptr(p)):
        return None
    return x, g


def attach(model, result: BVPResult, h: float, p: np.ndarray) -> BVPResult:
    """``result`` of the node problem as the States solve's: node times at the half steps,
    ``t_states`` = k·h (so that ``T`` is N·h, failed or not) and, where the path is
    finite, the states at those times — the elements' midpoints, node k moved by
    τ(h v_k/2) — as ``states``."""
    if not len(result.t):
        return result
    base = replace(result, t=result.t - 0.5 * h, t_states=h * np.arange(len(result.t) - 1))
    if result.f is None:
        return base
    f = np.asarray(result.f, dtype=float)
    count = len(f)
    x = np.asarray(result.x, dtype=float)[:count] if model.m else np.zeros((count, 0))
    blocks = result.g if isinstance(result.g, tuple) else (result.g,)
    g = np.concatenate([np.asarray(b, dtype=float).reshape(len(b), -1)[:count]
                        for b in blocks], axis=1) if model.matrix_dims else np.zeros((count, 0))
    v = node_velocities(model, result.x if model.m else x, f, h)
    finite = all(np.isfinite(a).all() for a in (x, g, v))
    middle = _moved(model, x, g, v, 0.5 * h, p) if finite else None
    if middle is None:               # a failed solve's last iterate, off every chart
        return base
    return replace(base, states=State(v=v, x=middle[0] if model.m else None,
                                      g=model.configurations(middle[1])))
