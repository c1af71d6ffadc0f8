"""Whole-trajectory solve: Newton on all free nodes at once (DESIGN.md §4).

The residual at node j involves nodes j−r … j+r, so the Jacobian is block-banded; C
assembles it in LAPACK band layout and SciPy's ``solve_banded`` factorises it, so one
iteration costs O(N). On the pair groupoid the unknowns are the nodes q_j themselves; on
a matrix Lie group they are the configurations g_j, corrected multiplicatively
(g_j ← g_j τ(η_j)), which keeps the product of the increments equal to g_0⁻¹g_N.
"""
from __future__ import annotations

import numpy as np

from . import arguments
from .results import BVPResult, Status


class _Pair:
    """Unknowns: the interior nodes q_r … q_{N−r} (state: all nodes)."""

    approximate_updates = False

    def __init__(self, model, p, h):
        self.model, self.p, self.h, self.r = model, p, h, model.order

    def assemble(self, nodes, with_jacobian: bool):
        return _assemble(self.model, self.model.lib.symvi_bvp_assemble, nodes, nodes.shape[0],
                         nodes.shape[0] - 2 * self.r, self.p, self.h, with_jacobian)

    def moved(self, nodes, delta, alpha, exact=True):
        trial = nodes.copy()
        trial[self.r:-self.r] += alpha * delta.reshape(-1, self.model.n)
        return trial

    def size(self, nodes) -> float:
        return float(np.abs(nodes).max())

    def magnitudes(self, nodes) -> np.ndarray:
        return np.abs(nodes[self.r:-self.r]).reshape(-1)


class _Group:
    """Unknowns: corrections η_j of the free configurations (state: (g, ξ)).

    Corrections above ``RELOG`` recompute ξ from the configurations (exactly on the group);
    smaller ones move ξ by its first-order change, exact to O(|η|²) ≤ 1e-14, and so avoid
    rounding ξ to ε/h, which a second-order residual would amplify by 1/h². ``exact=False``
    asks for the first-order change whatever the size (the line search's second try).
    """

    RELOG = 1e-7
    approximate_updates = True

    def __init__(self, model, p, h):
        self.model, self.p, self.h, self.r = model, p, h, model.order

    def assemble(self, state, with_jacobian: bool):
        xi = state[1]
        return _assemble(self.model, self.model.lib.symvi_group_bvp_assemble, xi, xi.shape[0],
                         xi.shape[0] + 1 - 2 * self.r, self.p, self.h, with_jacobian)

    def moved(self, state, delta, alpha, exact=True):
        m = self.model
        g, xi = state[0].copy(), state[1].copy()
        failed = m.ffi.new("long *")
        relog = int(exact and alpha * float(np.abs(delta).max(initial=0.0)) > self.RELOG)
        code = m.lib.symvi_group_bvp_update(m.ptr(g), m.ptr(xi), m.ptr(delta), alpha,
                                            xi.shape[0], m.ptr(self.p), self.h, relog, failed)
        return (g, xi) if code == 0 else None

    def size(self, state) -> float:
        return 1.0

    def magnitudes(self, state) -> np.ndarray:
        return np.ones((state[1].shape[0] + 1 - 2 * self.r) * self.model.n)


def _assemble(model, function, data, count: int, free_nodes: int, p, h, with_jacobian: bool):
    """Residuals at the free nodes and (optionally) their banded Jacobian, from C.

    ``function`` is the C assembler, called on ``data`` (nodes, resp. increments) and
    their ``count``; the Jacobian comes in LAPACK band layout with ``bw`` sub- and
    super-diagonals.
    """
    unknown = free_nodes * model.n
    bw = int(model.lib.symvi_bvp_bandwidth())
    res = np.zeros(unknown)
    ab = np.zeros((2 * bw + 1, unknown)) if with_jacobian else None
    code = function(model.ptr(data), count, model.ptr(p), h, model.ptr(res),
                    model.ptr(ab) if with_jacobian else model.ffi.NULL)
    return res, ab, bw, code == 0


def solve_bvp(model, start, end, n_steps: int, h: float, params=None, *, guess=None,
              maxiter: int = 50, xtol: float = 1e-12, ftol: float = 0.0,
              raise_on_failure: bool = False) -> BVPResult:
    """Solve for the free nodes with the first and last r nodes fixed (r the order).

    Parameters
    ----------
    start, end : the fixed nodes. Pair groupoid: (r, n) arrays q_0 … q_{r−1} and
        q_{N−r+1} … q_N. Matrix Lie group: (r, d, d) configurations g_0 … g_{r−1} and
        g_{N−r+1} … g_N.
    n_steps : N, the number of elements (N + 1 nodes).
    guess : the free nodes q_r … q_{N−r} ((N + 1 − 2r, n)), resp. configurations
        ((N + 1 − 2r, d, d)); default: interpolation between the fixed ends (linear, resp.
        g_{r−1} τ(s·τ⁻¹(g_{r−1}⁻¹ g_{N−r+1}))).
    maxiter, xtol, ftol : Newton stops when the update ‖Δ‖∞ ≤ xtol·(1 + size) or the
        residual ‖R‖∞ ≤ ftol. A backtracking line search on ‖R‖₂ globalises it.
    """
    info = model.info
    if not (info["bvp"] or info.get("group_bvp")):
        raise ValueError(f"model {model.name!r}: whole-trajectory solves are available on the "
                         f"pair groupoid and on matrix Lie groups, not on kind {info['kind']!r}")
    r = model.order
    N = arguments.count(n_steps, "n_steps", 2 * r)
    h, p = arguments.step_size(h), model.params(params)
    xtol, ftol = arguments.tolerance(xtol, "xtol"), arguments.tolerance(ftol, "ftol")
    maxiter = arguments.count(maxiter, "maxiter", 1)
    if info["bvp"]:
        problem, state = _Pair(model, p, h), _pair_state(model, start, end, N, guess)
    else:
        problem, state = _Group(model, p, h), _group_state(model, start, end, N, guess, p, h)
        if isinstance(state, BVPResult):
            return state.raise_for_status() if raise_on_failure else state
    state, norms, steps, status, message = _newton(problem, state, maxiter, xtol, ftol)
    if status == Status.SUCCESS:
        message = (f"converged in {len(steps)} Newton iterations, residual norm "
                   f"{norms[-1]:.3e}{message}")
    else:
        message += f"; residual norm {norms[-1]:.3e}"
    common = dict(t=h * np.arange(N + 1), iterations=len(steps),
                  residual_norms=np.array(norms), step_norms=np.array(steps), status=status,
                  message=message)
    if info["bvp"]:
        result = BVPResult(q=state, **common)
    else:
        d = model.matrix_dims[0]
        result = BVPResult(g=state[0].reshape(-1, d, d), f=state[1], **common)
    return result.raise_for_status() if raise_on_failure else result


def _newton(problem, state, maxiter: int, xtol: float, ftol: float):
    """Damped Newton; returns (state, residual norms, step norms, status, message)."""
    from scipy.linalg import LinAlgError, solve_banded

    norms, steps, status, message = [], [], Status.MAX_ITERATIONS, ""
    for it in range(maxiter):
        res, ab, bw, finite = problem.assemble(state, True)
        norms.append(float(np.abs(res).max(initial=0.0)))
        if not finite:
            status, message = Status.NON_FINITE, f"non-finite residual or Jacobian at iteration {it}"
            break
        if norms[-1] <= ftol:
            status = Status.SUCCESS
            break
        try:
            delta = solve_banded((bw, bw), ab, -res, check_finite=False)
        except (LinAlgError, ValueError):
            status, message = Status.SINGULAR_JACOBIAN, f"singular Jacobian at iteration {it}"
            break
        size = float(np.abs(delta).max(initial=0.0))
        if size <= xtol * (1.0 + problem.size(state)):
            # Already converged: round-off defeats a line search.
            moved = problem.moved(state, delta, 1.0)
            state, taken = (moved, size) if moved is not None else (state, None)
        else:
            state, taken = _line_search(problem, state, delta, res)
        if taken is None:
            level = _rounding_level(ab, bw, problem.magnitudes(state))
            if norms[-1] <= level:
                status = Status.SUCCESS  # no descent left below the rounding level
                message = f" (at the rounding level {level:.1e} of the residual)"
            else:
                status, message = Status.STALLED, f"line search stalled at iteration {it}"
            break
        steps.append(taken)
        if taken <= xtol * (1.0 + problem.size(state)):
            status = Status.SUCCESS
            norms.append(float(np.abs(problem.assemble(state, False)[0]).max(initial=0.0)))
            break
    else:
        message = f"Newton's method did not converge in {maxiter} iterations"
    return state, norms, steps, status, message


def _rounding_level(ab: np.ndarray, bw: int, u: np.ndarray) -> float:
    """Attainable residual: 16 ε ‖ |J| u ‖∞, u the unknowns' magnitudes (first order).

    When the line search finds no descent from a residual below it, Newton has converged
    as far as floating point allows, even if its update, amplified by the condition
    number (∝ N⁴ for fourth differences), still exceeds xtol.
    """
    scale = np.zeros_like(u)
    for d in range(2 * bw + 1):
        offset = d - bw  # row = column + offset
        if offset >= 0:
            scale[offset:] += np.abs(ab[d, : u.size - offset]) * u[: u.size - offset]
        else:
            scale[:offset] += np.abs(ab[d, -offset:]) * u[-offset:]
    return 16 * np.finfo(float).eps * float(scale.max(initial=0.0))


def _line_search(problem, state, delta, res, min_alpha: float = 2.0**-12):
    """Backtrack α = 1, ½, … until ‖R‖₂ decreases (Armijo, c = 1e-4).

    Each α is tried with the exact update, then with the first-order one (on groups,
    recomputing ξ from the configurations adds a rounding floor to the residual that a
    small final correction cannot get below).
    """
    base = float(np.dot(res, res))
    alpha = 1.0
    while alpha >= min_alpha:
        for exact in (True, False) if problem.approximate_updates else (True,):
            trial = problem.moved(state, delta, alpha, exact)
            if trial is None:
                continue
            trial_res, _, _, finite = problem.assemble(trial, False)
            if finite and float(np.dot(trial_res, trial_res)) <= (1 - 1e-4 * alpha) * base:
                return trial, alpha * float(np.abs(delta).max(initial=0.0))
        alpha /= 2
    return state, None


def _pair_state(model, start, end, N: int, guess) -> np.ndarray:
    r, n = model.order, model.n
    start = arguments.finite_array(start, (r, n), f"start nodes q_0..q_{r - 1}")
    end = arguments.finite_array(end, (r, n), f"end nodes q_{N - r + 1}..q_{N}")
    count = N + 1 - 2 * r
    if guess is None:
        s = np.linspace(0.0, 1.0, count + 2)[1:-1, None]
        interior = (1 - s) * start[-1] + s * end[0]
    else:
        interior = arguments.finite_array(guess, (count, n), "guess of the interior nodes")
    return np.concatenate([start, interior, end])


def _group_state(model, start, end, N: int, guess, p, h):
    """(g, ξ) from the fixed and guessed configurations, or a failed BVPResult."""
    r, d = model.order, model.matrix_dims[0]
    start = arguments.finite_array(start, (r, d, d), f"start configurations g_0..g_{r - 1}")
    end = arguments.finite_array(end, (r, d, d), f"end configurations g_{N - r + 1}..g_{N}")
    count = N + 1 - 2 * r
    if guess is None:
        chord = _increments(model, np.stack([start[-1], end[0]]), p, 1.0,
                            lambda k: f"the default guess (pass guess=...): g_{r - 1}⁻¹ "
                                      f"g_{N - r + 1}, between the fixed ends,")
        if isinstance(chord, BVPResult):
            return chord
        s = np.linspace(0.0, 1.0, count + 2)[1:-1]
        interior = np.stack([_retract(model, start[-1], chord[0], a) for a in s]) \
            if count else np.zeros((0, d, d))
    else:
        interior = arguments.finite_array(guess, (count, d, d), "guess of the free configurations")
    g = np.ascontiguousarray(np.concatenate([start, interior, end]))
    xi = _increments(model, g, p, h, lambda k: f"the initial path: w_{k} = g_{k}⁻¹ g_{k + 1}")
    return xi if isinstance(xi, BVPResult) else (g.reshape(N + 1, -1), xi)


def _retract(model, g, eta, alpha) -> np.ndarray:
    out = np.zeros_like(g)
    model.lib.symvi_group_retract(model.ptr(np.ascontiguousarray(g)),
                                  model.ptr(np.ascontiguousarray(eta)), alpha, model.ptr(out))
    return out


def increments(model, g, h: float, params=None) -> np.ndarray:
    """ξ_k = τ⁻¹(g_k⁻¹ g_{k+1})/h of a path of configurations g (K, d, d).

    Raises ValueError naming the element when an increment is outside the retraction's
    chart (Cayley: a half-turn; exp: a rotation angle ≥ π).
    """
    if not model.info.get("group_bvp"):
        raise ValueError(f"model {model.name!r} is not on a matrix Lie group")
    d, shape = model.matrix_dims[0], np.shape(g)
    if len(shape) != 3 or shape[0] < 2:
        raise ValueError(f"configurations g must have shape (K ≥ 2, {d}, {d}), got {shape}")
    g = arguments.finite_array(g, (shape[0], d, d), "configurations g")
    out = _increments(model, g, model.params(params), arguments.step_size(h),
                      lambda k: f"w_{k} = g_{k}⁻¹ g_{k + 1}")
    if isinstance(out, BVPResult):
        raise ValueError(out.message)
    return out


def _increments(model, g, p, h, describe):
    """ξ_k = τ⁻¹(g_k⁻¹ g_{k+1})/h in C, or a failed BVPResult naming the element."""
    g = np.ascontiguousarray(g, dtype=np.float64)
    xi = np.zeros((g.shape[0] - 1, model.n))
    failed = model.ffi.new("long *")
    code = model.lib.symvi_group_increments(model.ptr(g), g.shape[0], model.ptr(p), h,
                                            model.ptr(xi), failed)
    if code == 0:
        return xi
    status = Status(code)
    k = int(failed[0])
    reason = {Status.OUTSIDE_CHART: "is outside the retraction's chart (Cayley: a half-turn, "
                                    "I + W singular; exp: rotation angle ≥ π)",
              Status.SINGULAR_JACOBIAN: "has a singular configuration"}.get(
        status, "could not be converted to an increment")
    message = f"the increment of {describe(k)} {reason}"
    return BVPResult(t=np.zeros(0), iterations=0, residual_norms=np.zeros(0),
                     step_norms=np.zeros(0), status=status, message=message)
