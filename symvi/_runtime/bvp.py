"""Whole-trajectory solve: Newton on all interior nodes at once (second-order problems).

The residual at node j involves nodes j−r … j+r, so the Jacobian is block-banded; C
assembles it in LAPACK band layout and SciPy's ``solve_banded`` factorises it, so one
iteration costs O(N).
"""
from __future__ import annotations

import numpy as np

from . import arguments
from .results import BVPResult, Status


def _assemble(model, nodes, p, h, with_jacobian: bool):
    unknown = nodes.shape[0] * model.n - 2 * model.order * model.n
    bw = int(model.lib.symvi_bvp_bandwidth())
    res = np.zeros(unknown)
    ab = np.zeros((2 * bw + 1, unknown)) if with_jacobian else None
    code = model.lib.symvi_bvp_assemble(model.ptr(nodes), nodes.shape[0], model.ptr(p), h,
                                        model.ptr(res),
                                        model.ptr(ab) if with_jacobian else model.ffi.NULL)
    return res, ab, bw, code == 0


def solve_bvp(model, start, end, n_steps: int, h: float, params=None, *, guess=None,
              maxiter: int = 50, xtol: float = 1e-12, ftol: float = 0.0,
              raise_on_failure: bool = False) -> BVPResult:
    """Solve for q_r … q_{N−r} with the first and last r nodes fixed (r the order).

    Parameters
    ----------
    start, end : (r, n) the fixed nodes q_0 … q_{r−1} and q_{N−r+1} … q_N.
    n_steps : N, the number of elements (N + 1 nodes).
    guess : (N + 1 − 2r, n) initial interior nodes; default linear interpolation.
    maxiter, xtol, ftol : Newton stops when the update ‖Δq‖∞ ≤ xtol·(1 + ‖q‖∞) or the
        residual ‖R‖∞ ≤ ftol. A backtracking line search on ‖R‖₂ globalises it.
    """
    if not model.info["bvp"]:
        raise ValueError(f"model {model.name!r}: whole-trajectory solves need a groupoid whose "
                         f"base points are the unknowns (kind {model.info['kind']!r})")
    from scipy.linalg import LinAlgError, solve_banded

    r, n = model.order, model.n
    N = arguments.count(n_steps, "n_steps", 2 * r)
    h, p = arguments.step_size(h), model.params(params)
    xtol, ftol = arguments.tolerance(xtol, "xtol"), arguments.tolerance(ftol, "ftol")
    start = arguments.finite_array(start, (r, n), f"start nodes q_0..q_{r - 1}")
    end = arguments.finite_array(end, (r, n), f"end nodes q_{{N-{r - 1}}}..q_N")
    count = N + 1 - 2 * r
    if guess is None:
        interior = _default_nodes(start, end, count)
    else:
        interior = arguments.finite_array(guess, (count, n), "guess of the interior nodes")
    nodes = np.concatenate([start, interior, end])
    norms, steps, status, message = [], [], Status.MAX_ITERATIONS, ""
    for it in range(arguments.count(maxiter, "maxiter", 1)):
        res, ab, bw, finite = _assemble(model, nodes, p, h, True)
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
        delta = delta.reshape(count, n)
        if np.abs(delta).max(initial=0.0) <= xtol * (1.0 + np.abs(nodes).max()):
            nodes = nodes.copy()
            nodes[r:-r] += delta  # already converged: round-off defeats a line search
            taken = float(np.abs(delta).max(initial=0.0))
        else:
            nodes, taken = _line_search(model, nodes, delta, res, p, h)
        if taken is None:
            if norms[-1] <= _rounding_level(ab, bw, nodes, r):
                status = Status.SUCCESS  # no descent left below the rounding level
            else:
                status, message = Status.STALLED, f"line search stalled at iteration {it}"
            break
        steps.append(taken)
        if taken <= xtol * (1.0 + np.abs(nodes).max()):
            status = Status.SUCCESS
            norms.append(float(np.abs(_assemble(model, nodes, p, h, False)[0]).max(initial=0.0)))
            break
    else:
        message = f"Newton's method did not converge in {maxiter} iterations"
    iterations = len(steps)
    if status == Status.SUCCESS:
        message = f"converged in {iterations} Newton iterations, residual norm {norms[-1]:.3e}"
    else:
        message += f"; residual norm {norms[-1]:.3e}"
    result = BVPResult(t=h * np.arange(N + 1), q=nodes, iterations=iterations,
                       residual_norms=np.array(norms), step_norms=np.array(steps),
                       status=status, message=message)
    return result.raise_for_status() if raise_on_failure else result


def _rounding_level(ab: np.ndarray, bw: int, nodes: np.ndarray, r: int) -> float:
    """Attainable residual: 16 ε ‖ |J| |q| ‖∞ (the residual's rounding error, to first order).

    When the line search finds no descent from a residual below it, Newton has converged
    as far as floating point allows, even if its update, amplified by the condition
    number (∝ N⁴ for fourth differences), still exceeds xtol.
    """
    u = np.abs(nodes[r:-r]).reshape(-1)
    scale = np.zeros_like(u)
    for d in range(2 * bw + 1):
        offset = d - bw  # row = column + offset
        if offset >= 0:
            scale[offset:] += np.abs(ab[d, : u.size - offset]) * u[: u.size - offset]
        else:
            scale[:offset] += np.abs(ab[d, -offset:]) * u[-offset:]
    return 16 * np.finfo(float).eps * float(scale.max(initial=0.0))


def _default_nodes(start: np.ndarray, end: np.ndarray, count: int) -> np.ndarray:
    """Linear interpolation between the last start node and the first end node."""
    s = np.linspace(0.0, 1.0, count + 2)[1:-1, None]
    return (1 - s) * start[-1] + s * end[0]


def _line_search(model, nodes, delta, res, p, h, min_alpha: float = 2.0**-12):
    """Backtrack α = 1, ½, … until ‖R(q + αΔ)‖₂ decreases (Armijo, c = 1e-4)."""
    r = model.order
    base = float(np.dot(res, res))
    alpha = 1.0
    while alpha >= min_alpha:
        trial = nodes.copy()
        trial[r:-r] += alpha * delta
        trial_res, _, _, finite = _assemble(model, trial, p, h, False)
        if finite and float(np.dot(trial_res, trial_res)) <= (1 - 1e-4 * alpha) * base:
            return trial, alpha * float(np.abs(delta).max(initial=0.0))
        alpha /= 2
    return nodes, None
