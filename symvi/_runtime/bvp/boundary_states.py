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
from ..core.model_info import Kernel
from ..core.paths import node_velocities
from ..core.results import BVPResult, State


def _moves_nodes(model) -> bool:
    """Whether every fibre coordinate is a copy of a base coordinate at the target node and
    every base coordinate is copied (``INFO.fibre_nodes``; a pair groupoid): then a
    state's velocity moves the base point, x ∓ h v/2."""
    nodes = np.asarray(model.info.fibre_nodes, dtype=int)
    return bool((nodes >= 0).all()) and sorted(nodes.tolist()) == list(range(model.m))


def _base_rate(model, v: np.ndarray) -> np.ndarray:
    """ẋ of a state of velocity v: v_a moves the base coordinate its fibre copies."""
    rate = np.zeros(model.m)
    rate[np.asarray(model.info.fibre_nodes, dtype=int)] = v
    return rate


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
    if not (_moves_nodes(model) or model.m == 0):
        raise ValueError(f"model {name!r}: States as boundary data need a pair groupoid or "
                         f"matrix Lie groups (this is a {model.info.kind} groupoid); give "
                         f"the first and last two nodes")
    if model.m and model.info.has_kernel(Kernel.MANIFOLD):
        raise ValueError(f"model {name!r}: its positions lie on a declared manifold, which "
                         f"q ∓ hv/2 leaves; give the first and last two nodes")
    if model.end_free or model.end_count:
        raise ValueError(f"model {name!r}: its end is free or given by end conditions; give "
                         f"the start as nodes (a State fixes both ends)")


def element_nodes(model, state: State, h: float, what: str):
    """The two nodes of the element whose midpoint is ``state``, in the layout of
    :func:`.bvp.solve_bvp`'s ``start``/``end``: (2, n) nodes on a pair groupoid, (2, d, d)
    configurations (a tuple of them with several group factors) on Lie groups."""
    v = arguments.finite_array(state.v, (model.n,), f"the {what} state's velocity v")
    if model.m:
        x = arguments.finite_array(state.x, (model.m,), f"the {what} state's position x")
        check_base_points(model, x[None], f"the {what} state's position x")
        rate = _base_rate(model, v)
        return np.stack([x - 0.5 * h * rate, x + 0.5 * h * rate])
    g = model.configuration(state.g, f"the {what} state's configuration g")
    check_configurations(model, g[None], f"the {what} state's configuration g")
    first = _retract(model, g[None], v[None], -0.5 * h)
    second = None if first is None else _retract(model, first, v[None], h)
    if second is None:
        raise ValueError(f"the {what} state's velocity is outside the retraction's chart at "
                         f"h = {h:g} (Cayley: a half-turn; exp: an angle ≥ π per step); "
                         f"take more steps")
    return model.configurations(np.concatenate([first, second]))


def _retract(model, g: np.ndarray, f: np.ndarray, h: float) -> np.ndarray | None:
    """g_k τ(h f_k) for each node, or None when an increment is outside its chart."""
    g, f = np.ascontiguousarray(g), np.ascontiguousarray(f)
    out = np.empty_like(g)
    if model.lib.symvi_path_retract(model.ptr(g), model.ptr(f), len(g), h, model.ptr(out)):
        return None
    return out


def attach(model, result: BVPResult, h: float) -> BVPResult:
    """``result`` of the node problem as the States solve's: node times at the half steps,
    ``t_states`` = k·h (so that ``T`` is N·h, failed or not) and, where the path is
    finite, the states at those times (the elements' midpoints) as ``states``."""
    if not len(result.t):
        return result
    base = replace(result, t=result.t - 0.5 * h, t_states=h * np.arange(len(result.t) - 1))
    if result.f is None:
        return base
    f = np.asarray(result.f, dtype=float)
    if model.m:
        x = np.asarray(result.x, dtype=float)
        return replace(base, states=State(v=node_velocities(model, x, f, h),
                                          x=0.5 * (x[1:] + x[:-1])))
    blocks = result.g if isinstance(result.g, tuple) else (result.g,)
    g = np.concatenate([np.asarray(b, dtype=float).reshape(len(b), -1) for b in blocks], axis=1)
    finite = np.isfinite(g).all() and np.isfinite(f).all()
    middle = _retract(model, g[:-1], f, 0.5 * h) if finite else None
    if middle is None:               # a failed solve's last iterate, off every chart
        return base
    return replace(base, states=State(v=f.copy(), g=model.configurations(middle)))
