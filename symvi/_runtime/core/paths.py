"""Discrete paths as nodes: boundary data, initial guesses and element fibres.

A node is its base point x (m numbers) and the configurations g of the matrix-group
factors (d×d each, flattened and concatenated). Elements follow from consecutive nodes in
C (``symvi_path_fibres``): a pair factor's fibre is the next node's coordinates, a group
factor's is ξ = τ⁻¹(g_k⁻¹g_{k+1})/h. On an action groupoid the base points must follow
the configurations, x_{k+1} = φ(x_k, g_k⁻¹g_{k+1}); :func:`check_consistent` says where
they do not.

A model's initial data for the step map come in the layout its groupoid names
(``INFO.initial_layout``, :data:`INITIAL_LAYOUTS`): the first K nodes where an element
is the pair of its nodes, else the first base point, configurations and fibres.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np

from . import arguments
from .geometry import check_base_points, check_configurations
from .results import BVPResult, Status


@dataclass(frozen=True)
class Path:
    """Nodes (x, g), element fibres f and window multipliers lam of a discrete path."""

    x: np.ndarray    # (nodes, m)
    g: np.ndarray    # (nodes, Σ d²)
    f: np.ndarray    # (nodes − 1, n)
    lam: np.ndarray  # (windows, s)
    #: The end conditions' multipliers ν (at least one number: a pointer for C).
    nu: np.ndarray = field(default_factory=lambda: np.zeros(1))
    #: The horizon, where it is an unknown (a free final time: ``bvp/bordered.py``).
    T: float | None = None

    def copy(self) -> "Path":
        return replace(self, x=self.x.copy(), g=self.g.copy(), f=self.f.copy(),
                       lam=self.lam.copy(), nu=self.nu.copy())


@dataclass(frozen=True)
class Resampled:
    """A start the run time made itself from a solution at another number of steps
    (:mod:`.bvp.sequence`): free nodes in the layout of :class:`Path` — base points
    (count, m), configurations (count, Σ d²) — accepted wherever nodes are parsed; and,
    where the solution had them, every window's multipliers (λ, then the bound
    multipliers z, the C layout) and active set, a warm start like a previous result's;
    with an unknown end its last r nodes (x, g), the end's first guess."""

    x: np.ndarray
    g: np.ndarray
    lam: np.ndarray | None = None
    active: np.ndarray | None = None
    last: tuple[np.ndarray, np.ndarray] | None = None


def flat_configurations(model, value, count: int, what: str) -> np.ndarray:
    """(count, Σ d²) from one (count, d, d) array per group factor."""
    dims = model.matrix_dims
    blocks = [value] if len(dims) == 1 else list(value)
    if len(blocks) != len(dims):
        raise ValueError(f"{what} need {len(dims)} arrays, one per matrix-group factor")
    return np.concatenate([arguments.finite_array(b, (count, d, d), what).reshape(count, -1)
                           for b, d in zip(blocks, dims)], axis=1)


def nodes(model, value, count: int, what: str, first: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Parse ``count`` nodes, numbered from ``first``: base points (count, m) on a pair
    groupoid, configurations (count, d, d) on a Lie group, ``(x, g)`` when there are both;
    each checked against its geometry (:mod:`.geometry`)."""
    x, g = _parse_nodes(model, value, count, what)
    check_configurations(model, g, f"{what} configurations", first)
    check_base_points(model, x, f"{what} base points", first)
    check_configured(model, x, g, what, first)
    return x, g


def held(model) -> bool:
    """Whether every base coordinate is an entry of the configuration (a group acting on
    itself, ``ActionGroupoid.on_itself``, alone or with other group factors): then the
    configurations alone determine the base points."""
    base = model.info.configuration_base
    return bool(base) and min(base) >= 0


def held_base_points(model, g: np.ndarray) -> np.ndarray:
    """The base points a group acting on itself holds in its flat configurations ``g``
    (one node, or nodes along the first axis): their entries (:func:`held`)."""
    return g[..., list(model.info.configuration_base)]


def _axes(value) -> int:
    """The number of array axes of ``value``; a sequence of arrays of different shapes
    (one per group factor: SE(2)'s 3×3 and SE(3)'s 4×4) has one more than its fewest."""
    try:
        return int(np.ndim(value))
    except ValueError:
        return 1 + min(_axes(part) for part in value)


def _configured(model, value) -> bool:
    """Whether ``value`` holds configurations alone where every base coordinate is an
    entry of the configuration (a group acting on itself): not an (x, g) pair, whose x
    is a 2-D array of base points."""
    if not held(model) or isinstance(value, Resampled):
        return False
    pair = isinstance(value, (tuple, list)) and len(value) == 2 \
        and _axes(value[0]) == 2 and _axes(value[1]) >= 3
    return not pair


def check_configured(model, x: np.ndarray, g: np.ndarray, what: str, first: int = 0,
                     alone: str = "the configurations alone (their base points are filled "
                                  "from them)") -> None:
    """Base points that are configuration entries must equal them (a group acting on
    itself, ``ActionGroupoid.on_itself``): otherwise the path inequalities on them would
    hold for another configuration than the path's, and a step map's base points (the
    dynamics) would follow another path than its configurations. ``alone`` is the data
    without base points the caller accepts, offered where every base coordinate is an
    entry."""
    base = np.asarray(model.info.configuration_base, dtype=int)
    held_at = np.flatnonzero(base >= 0)
    if not held_at.size or not x.shape[0]:
        return
    gap = np.abs(x[:, held_at] - g[:, base[held_at]]) / (1.0 + np.abs(g[:, base[held_at]]))
    k, i = np.unravel_index(np.argmax(gap), gap.shape)
    if gap[k, i] > 1e-9:
        advice = f"{alone} or base points" if held(model) else "base points"
        raise ValueError(
            f"{what} base point {model.info.coordinate_names[held_at[i]]} of node {first + k} "
            f"is {x[k, held_at[i]]:.12g}, but the configuration's entry it stands for is "
            f"{g[k, base[held_at[i]]]:.12g}: give {advice} equal to their entries")


def _parse_nodes(model, value, count: int, what: str) -> tuple[np.ndarray, np.ndarray]:
    m, dims = model.m, model.matrix_dims
    if isinstance(value, Resampled):
        return (arguments.finite_array(value.x, (count, m), f"{what} base points"),
                arguments.finite_array(value.g, (count, sum(d * d for d in dims)),
                                       f"{what} configurations"))
    if not dims:
        return arguments.finite_array(value, (count, m), f"{what} nodes"), np.zeros((count, 0))
    if m == 0 or _configured(model, value):
        g = flat_configurations(model, value, count, f"{what} configurations")
        return held_base_points(model, g), g
    try:
        x, g = value
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be (x, g): base points ({count}, {m}) and "
                         f"configurations ({count}, d, d)") from None
    return (arguments.finite_array(x, (count, m), f"{what} base points"),
            flat_configurations(model, g, count, f"{what} configurations"))


def _failure(message: str, status: Status) -> BVPResult:
    return BVPResult(t=np.zeros(0), iterations=0, residual_norms=np.zeros(0),
                     step_norms=np.zeros(0), status=status, message=message)


REASONS = {Status.OUTSIDE_CHART: "is outside the retraction's chart (Cayley: a half-turn, "
                                 "I + W singular; exp: rotation angle ≥ π)",
           Status.SINGULAR_JACOBIAN: "has a singular configuration"}


def fibres(model, x, g, p, h, describe, f=None):
    """Element fibres of the nodes (x, g) in C, or a failed BVPResult naming the element."""
    f = np.zeros((x.shape[0] - 1, model.n)) if f is None else f
    failed = model.ffi.new("long *")
    code = model.lib.symvi_path_fibres(model.ptr(x), model.ptr(g), model.ptr(f), x.shape[0],
                                       model.ptr(p), h, 0, failed)
    if code == 0:
        return f
    status = Status(code)
    reason = REASONS.get(status, "could not be converted to an increment")
    return _failure(f"the increment of {describe(int(failed[0]))} {reason}", status)


def interpolate(model, x, g, a: int, b: int, p, describe, cubic: bool = False):
    """Fill nodes a < j < b (in place) on the chord from node a to node b or, ``cubic``,
    on the cubic that also matches the velocities of nodes a − 1 → a and b → b + 1; or
    fail (a failed BVPResult)."""
    code = model.lib.symvi_path_interpolate(model.ptr(x), model.ptr(g), a, b, int(cubic),
                                            model.ptr(p))
    if code == 0:
        return None
    status = Status(code)
    return _failure(f"the increment of {describe} {REASONS.get(status, 'failed')}", status)


def check_consistent(model, x, f, p, h, what: str, tol: float = 1e-9) -> None:
    """Raise ValueError when a base point is not the target of the element before it."""
    if model.m == 0:
        return
    where = model.ffi.new("long *")
    gap = model.lib.symvi_path_mismatch(model.ptr(x), model.ptr(f), x.shape[0], model.ptr(p),
                                        h, where)
    scale = 1.0 + float(np.abs(x).max(initial=0.0))
    if not gap <= tol * scale:
        k = int(where[0])
        raise ValueError(
            f"inconsistent {what}: the base point of node {k + 1} differs by {gap:.3e} from "
            f"the target β of element {k} (on an action groupoid x_{k + 1} must be "
            f"φ(x_{k}, g_{k}⁻¹ g_{k + 1}))")


def initial_path(model, start, end, N: int, guess, p, h):
    """The Path the Newton iteration starts from, or a failed BVPResult.

    Fixed nodes 0…r−1 and N−r+1…N; free nodes from ``guess``: an array of them, or an
    interpolation between nodes r−1 and N−r+1 (:func:`interpolate`): ``"cubic"`` (the
    default) matches the boundary velocities too when r ≥ 2 — the chord would jump from
    them to its own, a velocity jump of O(1) whose accelerations O(1/h) put the first
    Newton iterate far from feasibility and its multipliers far from the solution's —
    ``"chord"`` matches the positions only.

    With an unknown end (``model.end_free``) ``end`` is the first guess of the last r
    nodes: by default a previous result's, else the last start node held.
    """
    r = model.order
    sx, sg = nodes(model, start, r, "start")
    previous = guess if isinstance(guess, BVPResult) else None
    if model.end_free and end is None:
        ex, eg = _last_nodes(model, previous, r) if previous is not None else \
            guess.last if isinstance(guess, Resampled) and guess.last is not None else \
            (np.repeat(sx[-1:], r, axis=0), np.repeat(sg[-1:], r, axis=0))
    else:
        ex, eg = nodes(model, end, r, "end", N - r + 1)
    count = N + 1 - 2 * r
    if previous is not None:
        guess = _free_nodes(model, previous, N)
    if guess is None or isinstance(guess, str):
        interpolated = _interpolated(model, (sx, sg), (ex, eg), count, guess or "cubic", p)
        if isinstance(interpolated, BVPResult):
            return interpolated
        x, g = interpolated
    else:
        gx, gg = nodes(model, guess, count, "guess of the free", r)
        x, g = np.concatenate([sx, gx, ex]), np.concatenate([sg, gg, eg])
    x, g = np.ascontiguousarray(x), np.ascontiguousarray(g)
    f = fibres(model, x, g, p, h, lambda k: f"the initial path: w_{k} = g_{k}⁻¹ g_{k + 1}")
    if isinstance(f, BVPResult):
        return f
    # every window's λ, then the multipliers z of its inequalities (the C layout)
    count = model.constraints + len(model.inequalities)
    windows = N + 1 - r if count else 0
    lam = np.zeros((windows, count))
    # a failed result's multipliers are no start: an INFEASIBLE one's λ reach 1e9, and
    # the tolerance, relative to the path's size, then passed corrections of 3e-4
    solved = previous is not None and previous.success
    if solved:
        f, lam = _kept(model, previous, x, g, f, lam, h)
    elif isinstance(guess, Resampled) and guess.lam is not None \
            and guess.lam.shape == lam.shape:
        lam = np.array(guess.lam, dtype=float)
    check_consistent(model, x, f, p, h, "boundary data or guess")
    nu = np.zeros(max(model.end_count, 1))
    if solved and previous.end_multipliers is not None \
            and previous.end_multipliers.shape == (model.end_count,):
        nu[:model.end_count] = previous.end_multipliers
    return Path(x, g, f, lam, nu)


def _last_nodes(model, previous: BVPResult, r: int) -> tuple[np.ndarray, np.ndarray]:
    """The last r nodes (x, g) of a previous result."""
    count = previous.t.size
    x = previous.x[-r:] if previous.x is not None else np.zeros((r, 0))
    g = flat_configurations(model, previous.g, count, "guess configurations")[-r:] \
        if model.matrix_dims else np.zeros((r, 0))
    return np.array(x, dtype=float), g


def _free_nodes(model, previous: BVPResult, N: int):
    """The free nodes r … N−r of a previous solve, in the layout of ``guess``: a warm start
    (the same problem with other boundary data or parameters, or a continuation)."""
    steps = previous.t.size - 1
    if previous.f is None or steps != N:
        raise ValueError(f"guess: a previous result warm-starts a solve with its own number "
                         f"of steps ({max(steps, 0)}), not n_steps = {N}"
                         + ("" if previous.f is not None else " (it holds no path)"))
    free = slice(model.order, N + 1 - model.order)
    g = previous.g
    g = None if g is None else (g[free] if not isinstance(g, tuple) else tuple(b[free] for b in g))
    if not model.matrix_dims:
        return previous.x[free]
    return g if model.m == 0 else (previous.x[free], g)


def _kept(model, previous: BVPResult, x, g, f, lam, h: float):
    """The previous solve's fibres on the elements whose nodes are unchanged (recomputed
    from the nodes, a group fibre would be rounded to ε/h) and its multipliers. A group
    fibre is its increment over h (ξ = τ⁻¹(w)/h): solved with another step it is
    rescaled by h_previous/h, which keeps the element w (kept as it was, a warm start at
    another h returned SUCCESS on fibres that were not the configurations' increments,
    at 46 % above the optimal cost). A kept fibre must also agree with the one recomputed
    from the nodes to 1e-8 of its element. The multipliers are kept where their shapes
    match: λ, and a bounded problem's z (the active-set Newton's warm start,
    :func:`.bounded.bounded`)."""
    count = x.shape[0]
    old_x = previous.x if previous.x is not None else np.zeros((count, 0))
    old_g = flat_configurations(model, previous.g, count, "guess configurations") \
        if model.matrix_dims else np.zeros((count, 0))
    same = (x == old_x).all(axis=1) & (g == old_g).all(axis=1)
    if previous.f.shape == f.shape:
        keep = same[:-1] & same[1:]
        old = np.array(previous.f, dtype=float)
        scaled = model.step_scaled
        step = float(previous.t[1] - previous.t[0]) if previous.t.size > 1 else h
        if step != h:
            old[:, scaled] *= step / h
        # only fibres that are the elements of the new nodes (to far more than the
        # recomputed ones' rounding): a previous result edited or inconsistent is not
        # carried into the path
        units = np.where(scaled, h, 1.0)
        agree = (np.abs((old - f) * units) <= 1e-8 * (1.0 + np.abs(old * units))).all(axis=1)
        f = np.where((keep & agree)[:, None], old, f)
    lam = np.array(lam, dtype=float)
    s = model.constraints
    for part, previous_part in ((slice(0, s), previous.multipliers),
                                (slice(s, None), previous.bound_multipliers)):
        if previous_part is not None and np.shape(previous_part) == lam[:, part].shape:
            lam[:, part] = previous_part     # λ, then the bound multipliers z
    return np.ascontiguousarray(f), lam


GUESSES = ("cubic", "chord")


def _interpolated(model, start, end, count: int, guess: str, p):
    """Nodes (x, g) with the free ones interpolated, or a failed BVPResult. Without end
    velocities (an end element outside the retraction's chart: :func:`fibres` then
    names it) the chord."""
    if guess not in GUESSES:
        raise ValueError(f"guess must be an array of the free nodes or one of {GUESSES}, "
                         f"got {guess!r}")
    r = model.order
    x = np.concatenate([start[0], np.zeros((count, model.m)), end[0]])
    g = np.concatenate([start[1], np.zeros((count, start[1].shape[1])), end[1]])
    if guess == "cubic" and r >= 2 and interpolate(model, x, g, r - 1, count + r, p, "",
                                                  cubic=True) is None:
        return x, g
    failed = interpolate(model, x, g, r - 1, count + r, p,
                         f"the initial guess (pass guess=... the free nodes): "
                         f"g_{r - 1}⁻¹ g_{count + r}, between the fixed ends,")
    return (x, g) if failed is None else failed


def increments(model, g, h: float, params=None) -> np.ndarray:
    """ξ_k = τ⁻¹(g_k⁻¹ g_{k+1})/h of a path of configurations g (K, d, d).

    Raises ValueError naming the element when an increment is outside the retraction's
    chart (Cayley: a half-turn; exp: a rotation angle ≥ π).
    """
    if model.m or len(model.matrix_dims) != 1:
        raise ValueError(f"model {model.name!r} is not on a matrix Lie group")
    d, shape = model.matrix_dims[0], np.shape(g)
    if len(shape) != 3 or shape[0] < 2:
        raise ValueError(f"configurations g must have shape (K ≥ 2, {d}, {d}), got {shape}")
    g = arguments.finite_array(g, (shape[0], d, d), "configurations g").reshape(shape[0], -1)
    check_configurations(model, g, "configurations g")
    out = fibres(model, np.zeros((shape[0], 0)), g, model.params(params),
                 arguments.step_size(h), lambda k: f"w_{k} = g_{k}⁻¹ g_{k + 1}")
    if isinstance(out, BVPResult):
        raise ValueError(out.message)
    return out


# -- initial data of the step map, in the layout the groupoid names ----------------------
@dataclass(frozen=True)
class InitialLayout:
    """How initial data are given: ``read(model, initial)`` → the stencil prefix
    (x_0, f_0, …, f_{K−2}) flattened and the configurations g_0 (:meth:`.compiled.
    CompiledModel.initial_state`); ``describe(K, n)`` what to give, for messages."""

    read: Callable[[Any, Any], tuple[np.ndarray, np.ndarray]]
    describe: Callable[[int, int], str]


def _read_nodes(model, initial) -> tuple[np.ndarray, np.ndarray]:
    """The first K nodes, (K, n): an element is the pair of its nodes, so they are
    x_0 = q_0 and the fibres f_j = q_{j+1} in a row."""
    K = model.stencil_elements
    nodes = arguments.finite_array(initial, (K, model.n),
                                   f"initial nodes (the first {K} nodes q_0..q_{K - 1})")
    return nodes.reshape(-1), np.zeros(1)


def _read_elements(model, initial) -> tuple[np.ndarray, np.ndarray]:
    """``(x_0, g_0, f)``: the first base point, the configurations of the matrix-group
    factors (one (d, d) matrix, or a sequence of them; optional, identity by default)
    and the first K−1 fibre parts; ``(g_0, f)`` without base points, or where every base
    coordinate is an entry of g (a group acting on itself: x_0 is filled from g_0, and a
    given x_0 must be its entries, :func:`check_configured` — the step map moves x_0 and
    g_0 by the same increments, so a base point off g_0 makes a path whose
    configurations are not its base points)."""
    K, m = model.stencil_elements, model.m
    parts = list(initial) if isinstance(initial, (tuple, list)) else [initial]
    alone = held(model) and len(parts) == 2 and _axes(parts[0]) >= 2
    x0 = [] if m == 0 or alone else parts.pop(0) if parts else None
    fibres = parts.pop() if parts else None
    if fibres is None or len(parts) > 1:
        layout = "(g_0, f)" if m == 0 else "(x_0, f) or (x_0, g_0, f)"
        raise ValueError(f"initial data must be {layout}")
    fibres = arguments.finite_array(fibres, (K - 1, model.n),
                                    f"initial increments (the first {K - 1} fibre parts)")
    g0 = model.configuration(parts[0] if parts else None)
    if model.matrix_dims:
        check_configurations(model, g0[None, :], "initial configuration g_0")
    if alone:
        x0 = held_base_points(model, g0)
    x0 = arguments.finite_array(x0, (m,), "initial base point x_0")
    check_base_points(model, x0[None, :], "initial base point x_0")
    check_configured(model, x0[None, :], g0[None, :], "initial", 0,
                     "(g_0, f), x_0 filled from g_0 (the identity unless given),")
    return np.concatenate([x0, fibres.reshape(-1)]), g0


#: The layouts of initial data, by the name a package records (``"nodes"`` where the
#: groupoid says its elements are pairs of nodes, :mod:`symvi.groupoids.base`).
INITIAL_LAYOUTS = {
    "nodes": InitialLayout(_read_nodes, lambda K, n: f"the first {K} nodes, an array ({K}, {n})"),
    "elements": InitialLayout(_read_elements, lambda K, n: f"its first {K - 1} elements"),
}


def initial_layout(model) -> InitialLayout:
    """The layout of ``model``'s initial data."""
    return INITIAL_LAYOUTS[model.info.initial_layout]


def node_velocities(model, x: np.ndarray, f: np.ndarray, h: float) -> np.ndarray:
    """The velocity of each element of a path (nodes x, fibres f), per fibre coordinate:
    the difference quotient (x_{k+1, j} − x_{k, j})/h of the base coordinate j the fibre
    copies at the target node (``INFO.fibre_nodes``: a pair factor), else the fibre
    itself (ξ on a group)."""
    nodes = np.asarray(model.info.fibre_nodes, dtype=int)
    copies = nodes >= 0
    out = np.array(f, dtype=float, copy=True)
    if copies.any():
        x = np.asarray(x, dtype=float)[:len(out) + 1, nodes[copies]]
        out[:, copies] = (x[1:] - x[:-1]) / h
    return out
