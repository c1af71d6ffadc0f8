"""Globalisation of the whole-trajectory Newton iteration: descent steps on the cost or its
exact penalty, the natural-monotonicity step at the rounding level, and backtracking on
the residual norm. Each takes (problem, state, …) and returns (state, step length taken
or None when it found no acceptable step).
"""
from __future__ import annotations

import numpy as np

from .optimality import MAX_SHIFT, convexifying_shift, next_shift
from ..core.paths import Path


def descent_step(problem, state, res, ab, bw, delta, contracting: bool = False,
                 min_alpha: float = 2.0**-12):
    """A descent step on the cost S = Σ L_d, or with constraints Φ_d on its ℓ1 exact
    penalty φ = S + ν‖Φ_d‖₁ (Nocedal & Wright §18.3, ν above the largest new multiplier).
    ν may fall again, halfway per iteration (Powell's rule): far from feasibility the
    first Newton steps can carry multipliers orders of magnitude above the solution's,
    and a ν that only grew would leave φ blind to S (heavy top, rest to rest over a
    vertical turn of 0.3 rad: no convergence in 300 iterations; with the rule, 208).

    The Newton (SQP) step keeps J_Φ d = −Φ_d, so φ's slope along it is
    R_η·d + λ·Φ_d − ν‖Φ_d‖₁ with R_η the node rows of the residual. When that is not
    negative, or with constraints the Hessian W = ∂R_η/∂η of S + λ·Φ_d has no positive
    curvature along the step's node part (d_ηᵀ W d_η ≤ 0), the node block is shifted by
    μ·max|diag| (Nocedal & Wright §3.4) until both hold; then Armijo backtracking on φ.
    μ shrinks again after full steps. While ν‖Φ_d‖₁ is large the slope is blind to W:
    steps into its negative curvature pass, are cut to α ≈ 2⁻⁸, and Newton settles on a
    saddle of S on the constraints (the 0.3 rad turn: 208 iterations to a KKT point with
    curvature −4.6 on the constraints' tangent space; with the test, 26–28 to a minimum of
    lower cost). This is the curvature test of inertia-free line searches (Chiang &
    Zavala 2016), standing in for the inertia of a symmetric indefinite factorisation,
    which LAPACK lacks for band matrices; it cannot exclude a saddle approached along
    positive curvature. Far from a minimum it keeps Newton away from saddles and maxima
    of S, where the residual-norm merit is content to go.

    Without constraints W is the whole Newton matrix and its inertia is known (from a band
    Cholesky factorisation, or for the lifted system from its block LDLᵀ:
    :meth:`.assembly.Problem.definite`): the shift starts at the smallest that makes W + μ·I
    positive definite (:func:`.optimality.convexifying_shift`, modified Newton), so no
    step heads for a saddle (the battery: rigid_body_oc from the zero guess at N = 1000
    in 17 iterations instead of 353; double_pendulum_oc from a perturbed guess to its
    minimum instead of a saddle). That test is skipped while Newton ``contracting`` (its
    correction at most a quarter of the one before) continues a run of full unshifted
    steps from a verified iterate: the iterates stay within a third of its correction, so
    the definiteness found there carries (rigid_body_oc at N = 1000: two band Cholesky
    factorisations of four saved), and the final test still verifies the minimum. With constraints the same correction on W + ρAᵀA was
    measured worse for the heavy top with rotors (19 of 22 battery guesses instead of 21
    at N = 100), so the curvature test stays; a saddle reached anyway is caught after
    convergence (:func:`.bvp._minimum`).

    Returns (state, None) when φ cannot resolve the step (near convergence, the predicted
    change is below its rounding level) or no shift helps; a step that climbs φ is
    shifted, never handed back, since the residual-norm line search would then climb S.
    """
    from scipy.linalg import LinAlgError

    rows = problem.constraint_rows(state)
    nodes, lam, phi_d = ~rows, problem.multipliers(state), res[rows]
    infeasibility = float(np.abs(phi_d).sum())

    previous = problem.penalty

    def slope(delta):
        """φ's slope along ``delta``, after setting ν by Powell's rule (1978):
        ν = max(ν̂, (ν_previous + ν̂)/2), ν̂ = 1.5 max|λ + Δλ|."""
        if rows.any():
            wanted = 1.5 * float(np.abs(lam + delta[rows]).max(initial=0.0))
            problem.penalty = max(wanted, 0.5 * (previous + wanted))
        return float(res[nodes] @ delta[nodes] + lam @ phi_d) - problem.penalty * infeasibility

    cost, noise = problem.merit(state)
    if abs(slope(delta)) <= noise * (1 + problem.penalty):
        return state, None
    # the band's unknowns (a free horizon's T follows them: .bordered)
    scale = float(np.abs(ab[2 * bw][nodes[:ab.shape[1]]]).max(initial=0.0))
    shift = problem.shift
    if not rows.any() and not (contracting and problem.convex):
        shift = convexifying_shift(lambda mu: problem.definite(ab, bw, mu * scale), shift,
                                   problem.first_shift)
    while shift <= MAX_SHIFT:
        if shift > 0.0:
            try:
                delta = problem.solve(ab, bw, -res, shift * scale, nodes)
            except LinAlgError:         # this shift makes the matrix singular: the next
                shift = next_shift(shift, problem.first_shift)
                continue
        descent, nu, alpha = slope(delta), problem.penalty, 1.0
        if rows.any() and problem.curvature(ab, bw, delta, nodes, shift * scale) <= 0.0:
            descent = 0.0       # into W's negative curvature: shift instead
        while descent < 0.0 and alpha >= min_alpha:
            problem.last_trials += 1
            trial = problem.moved(state, delta, alpha)
            if trial is not None and penalty(problem, trial, rows, nu) \
                    <= cost + nu * infeasibility + 1e-4 * alpha * descent:
                problem.shift = shift / 10 if alpha == 1.0 and shift > problem.first_shift else \
                    (0.0 if alpha == 1.0 else shift)
                problem.convex = not rows.any() and alpha == 1.0 and shift == 0.0
                problem.last_shift = shift      # the iteration log's (relative to W's)
                return trial, alpha * float(np.abs(delta).max(initial=0.0))
            alpha /= 2
        shift = next_shift(shift, problem.first_shift)
    return state, None


def penalty(problem, path: Path, rows: np.ndarray, nu: float) -> float:
    """φ = S + ν‖Φ_d‖₁ at ``path`` (S alone without constraints)."""
    cost = problem.merit(path)[0]
    if not rows.any():
        return cost
    res, _, _, finite = problem.assemble(path, False)
    return cost + nu * float(np.abs(res[rows]).sum()) if finite else np.inf


def natural_step(problem, state, delta, ab, bw: int, size: float):
    """The full Newton step from a residual at its rounding level, where the residual's
    norm is noise and cannot judge it: taken when it passes Deuflhard's natural
    monotonicity test (the correction the same Newton matrix gives at the new point is
    smaller), else (state, None)."""
    from scipy.linalg import LinAlgError

    problem.last_trials += 1
    trial = problem.moved(state, delta, 1.0)
    if trial is None:
        return state, None
    trial_res, _, _, finite = problem.assemble(trial, False)
    try:
        simplified = problem.solve(ab, bw, -trial_res, at=trial) if finite else None
    except LinAlgError:
        simplified = None
    if simplified is None or not float(np.abs(simplified).max(initial=0.0)) < size:
        return state, None
    return trial, size


def line_search(problem, state, delta, res, min_alpha: float = 2.0**-12):
    """Backtrack α = 1, ½, … until ‖R‖₂ decreases (Armijo on ½‖R‖², c = 1e-4). The norms
    by BLAS's scaled dnrm2: a residual of 1e160 (a degenerate problem far from any
    solution) must compare, not overflow in a dot product."""
    from scipy.linalg.blas import dnrm2

    base = float(dnrm2(res))
    alpha = 1.0
    while alpha >= min_alpha:
        problem.last_trials += 1
        trial = problem.moved(state, delta, alpha)
        if trial is not None:
            trial_res, _, _, finite = problem.assemble(trial, False)
            if finite and float(dnrm2(trial_res)) <= np.sqrt(1 - 1e-4 * alpha) * base:
                return trial, alpha * float(np.abs(delta).max(initial=0.0))
        alpha /= 2
    return state, None
