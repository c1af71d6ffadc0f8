"""Steps of the interior point found by the filter line search (:mod:`.filter`; issue 50):
backtracking from the fraction-to-the-boundary step along the inertia-corrected Newton
direction until the filter accepts the trial (its slacks reset to −c where the fraction
to the boundary allows, :func:`.interior_steps.reset`). Where the filter accepts no step
down to its smallest α, the step of :mod:`.interior_steps` (Armijo on the barrier
problem's ℓ1 penalty, with its own shifts and fallbacks) is taken instead.
"""
from __future__ import annotations

import numpy as np

from .barrier import TAU_MIN, boundary_step
from .filter import Filter
from .interior_steps import accept, reset, step
from ..core.paths import Path


def filter_step(ip, path: Path, res, ab, bw: int, delta, ds, dz, Gd, error: float):
    """The moved path of one interior-point iteration from ``path`` (the reduced system
    ``res``, ``ab`` assembled there, ``delta`` its correction and ``ds``, ``dz``, ``Gd`` the
    eliminated steps), or None where no step is found."""
    from scipy.linalg import LinAlgError

    problem = ip.problem
    c = ip.inequalities.values.copy()
    if ip.filter is None:
        ip.filter = Filter(infeasibility(ip, path, ip.stencil, c, ip.s))
    if ip.filter_mu != ip.mu:           # a new barrier problem: its φ is another function
        ip.filter.reset()
        ip.filter_mu = ip.mu
    shift = ip.inertia_shift(path, bw, problem.shift)
    direction = (delta, ds, dz, Gd)
    # inf: no shift up to MAX_SHIFT makes the step descend (inertia_shift): no solve
    # (inf·0 on the unshifted rows filled the matrix with NaN), the merit's steps next
    if 0.0 < shift < np.inf:
        try:
            shifted = problem.solve(ab, bw, -res, shift * ip.scale, ip.nodes)
            direction = (shifted, *ip.steps(shifted, path, ip.mu * ip.unit, c))
        except LinAlgError:
            direction = None
    moved = None if direction is None or not np.isfinite(shift) else \
        _search(ip, path, *direction, c)
    if moved is not None:
        ip.log.step(shift=shift)
        problem.shift = shift / 10 if shift > ip.first_shift else 0.0
        return moved
    # the trials evaluated c elsewhere: the merit's step needs it at path (and the same
    # inertia correction, not found again)
    ip.inequalities.evaluate(path, problem.p, problem.step(path))
    return step(ip, path, res, ab, bw, delta, ds, dz, Gd, error, shift)


def infeasibility(ip, path: Path, stencil: np.ndarray, c: np.ndarray, s: np.ndarray) -> float:
    """θ = ‖Φ_d‖₁ + ‖c + s‖₁ at ``path`` (``stencil``: its residual, whose constraint
    rows are Φ_d; ``c`` its inequalities)."""
    return float(np.abs(stencil[ip.rows]).sum() + np.abs(c + s).sum())


def _search(ip, path: Path, delta, ds, dz, Gd, c):
    """Backtracking on the filter from the fraction-to-the-boundary step: the moved path
    (slacks and multipliers set), or None below the filter's smallest step."""
    problem, mu, flt = ip.problem, ip.mu * ip.unit, ip.filter
    s, z = ip.s, ip.z(path).copy()
    lam, rows, nodes = problem.multipliers(path), ip.rows, ip.nodes
    theta = infeasibility(ip, path, ip.stencil, c, s)
    cost, noise = problem.merit(path)
    phi = cost - mu * float(np.log(s).sum())
    slope = float(ip.stencil[nodes] @ delta[nodes] + lam @ ip.stencil[rows]
                  - (z * Gd).sum()) - mu * float((ds / s).sum())
    tau = max(TAU_MIN, 1.0 - ip.mu)
    alpha, alpha_z = boundary_step(s, ds, tau), boundary_step(z, dz, tau)
    smallest = flt.smallest_step(slope, theta)
    while alpha >= smallest:
        ip.log.trial()
        trial = problem.moved(path, delta, alpha)
        slacks = None if trial is None else reset(ip, trial, s, s + alpha * ds, tau)
        measured = None if slacks is None else _measure(ip, trial, slacks, mu)
        if measured is not None:
            verdict = flt.verdict(alpha, slope, theta, phi, *measured, noise)
            if verdict is not None:
                if verdict == "h":
                    flt.augment(theta, phi)
                return accept(ip, trial, slacks, z, dz, alpha_z, alpha)
        alpha /= 2
    return None


def _measure(ip, trial: Path, slacks: np.ndarray, mu: float):
    """(θ, φ) at ``trial`` with ``slacks`` (its inequalities already evaluated), or None
    where something is not finite."""
    problem = ip.problem
    res, _, _, finite = problem.assemble(trial, False)
    if not finite:
        return None
    theta = infeasibility(ip, trial, res, ip.inequalities.values, slacks)
    phi = problem.merit(trial)[0] - mu * float(np.log(slacks).sum())
    return (theta, phi) if np.isfinite(theta) and np.isfinite(phi) else None
