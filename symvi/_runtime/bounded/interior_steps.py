"""Steps of the interior-point iteration (:mod:`.interior`): the barrier problem's merit,
and how a step along the reduced Newton correction is found and taken.

Armijo backtracking on the ℓ1 exact penalty of the barrier problem,
S − μh Σ log s + ν(‖Φ_d‖₁ + ‖c + s‖₁), the trial's slacks reset to −c where the
fraction to the boundary allows (:func:`reset`), from the fraction-to-the-boundary step, the node
block shifted by the inertia correction and by the curvature test of
:func:`.globalisation.descent_step` where the step still meets negative curvature; backtracking on the KKT residual's norm where the merit
rejects a Newton step (the Maratos effect); Deuflhard's natural monotonicity test near
the solution, where the merit's rounding hides the decrease. Each takes the
:class:`.interior.InteriorPoint` ``ip`` and returns the moved path or None.
"""
from __future__ import annotations

import numpy as np

from .barrier import TAU_MIN, boundary_step, safeguarded
from ..bvp.optimality import MAX_SHIFT, next_shift
from ..core.paths import Path

#: Relative size of a correction below which a full step whose merit decrease is rounding
#: may be taken by the natural monotonicity test instead (:func:`_natural`).
NEAR = 1e-6
#: The shortest step taken along a direction while a larger shift could still be tried:
#: a Newton step far along a nearly flat direction of the reduced Hessian (the cart-pole
#: swing-up from a local optimum without bounds: curvature 2e-3 along a step of 0.8)
#: passes the merit only at α ≈ 2⁻¹³ again and again, while a shifted, shorter step
#: makes progress (that start: 4 iterations instead of 100 without convergence).
SHORT = 2.0**-8


def merit(ip, path: Path, s: np.ndarray, nu: float) -> float:
    """The barrier problem's ℓ1 exact penalty S − μh Σ log s + ν(‖Φ_d‖₁ + ‖c + s‖₁)."""
    problem = ip.problem
    if not ip.inequalities.evaluate(path, problem.p, problem.step(path)):
        return np.inf
    value = problem.merit(path)[0] - ip.mu * ip.unit * float(np.log(s).sum()) \
        + nu * float(np.abs(ip.inequalities.values + s).sum())
    if ip.rows.any():
        res, _, _, finite = problem.assemble(path, False)
        value = value + nu * float(np.abs(res[ip.rows]).sum()) if finite else np.inf
    return value


def step(ip, path: Path, res, ab, bw: int, delta, ds, dz, Gd, error: float,
         shift: float | None = None):
    """A step along the reduced correction (shifted by the inertia correction
    :meth:`.interior.InteriorPoint.inertia_shift`, and further where it is no descent or
    meets negative curvature, as in :func:`.globalisation.descent_step`), cut by the
    fraction-to-the-boundary rule and Armijo backtracking on :func:`merit`; near
    the solution, where the merit's rounding hides the step's decrease, the full
    step by Deuflhard's natural monotonicity test (:func:`_natural`). The moved
    path, or None. ``shift``: the inertia correction at ``path``, where the caller has
    found it (:func:`.filter_steps.filter_step`)."""
    from scipy.linalg import LinAlgError

    problem, mu = ip.problem, ip.mu * ip.unit
    c, nodes = ip.inequalities.values.copy(), ip.nodes
    scale = ip.scale
    if shift is None:
        shift = ip.inertia_shift(path, bw, problem.shift)
    while shift <= MAX_SHIFT:
        if shift > 0.0:
            try:
                delta = problem.solve(ab, bw, -res, shift * scale, nodes)
            except LinAlgError:
                shift = next_shift(shift, ip.first_shift)
                continue
            ds, dz, Gd = ip.steps(delta, path, mu, c)
        moved = _backtrack(ip, path, ab, bw, delta, ds, dz, Gd, c, shift * scale,
                           SHORT if shift < 1e2 else 2.0**-20)
        if moved is None and shift == 0.0:
            moved = _natural(ip, path, ab, bw, delta, ds, dz, error) \
                if error <= NEAR * (1.0 + problem.size(path)) \
                else _residual_search(ip, path, delta, ds, dz, c)
        if moved is not None:
            ip.log.step(shift=shift)
            problem.shift = shift / 10 if shift > ip.first_shift else 0.0
            return moved
        shift = next_shift(shift, ip.first_shift)
    return None


def _backtrack(ip, path: Path, ab, bw: int, delta, ds, dz, Gd, c, shift: float,
               min_alpha: float = 2.0**-20):
    """Armijo backtracking on :func:`merit` from the fraction-to-the-boundary step down
    to ``min_alpha``, if ``delta`` is a descent direction with positive curvature; else
    None."""
    problem, mu = ip.problem, ip.mu * ip.unit
    rows, nodes = ip.rows, ip.nodes
    z, s = ip.z(path).copy(), ip.s
    lam, phi_d = problem.multipliers(path), ip.stencil[rows]
    infeasibility = float(np.abs(phi_d).sum() + np.abs(c + s).sum())
    # ν ≥ 1.5 max |multiplier| after the step, by Powell's rule as in descent_step
    wanted = 1.5 * max(float(np.abs(lam + delta[rows]).max(initial=0.0)),
                       float(np.abs(z + dz).max(initial=0.0)))
    nu = problem.penalty = max(wanted, 0.5 * (problem.penalty + wanted))
    descent = float(ip.stencil[nodes] @ delta[nodes] + lam @ phi_d - (z * Gd).sum()) \
        - mu * float((ds / s).sum()) - nu * infeasibility
    if descent >= 0 or problem.curvature(ab, bw, delta, nodes, shift) <= 0:
        return None
    cost, noise = problem.merit(path)
    if -descent <= noise * (1 + nu):
        return None
    base = cost - mu * float(np.log(s).sum()) + nu * infeasibility
    tau = max(TAU_MIN, 1.0 - ip.mu)
    alpha = boundary_step(s, ds, tau)
    while alpha >= min_alpha:
        ip.log.trial()
        trial = problem.moved(path, delta, alpha)
        slacks = None if trial is None else reset(ip, trial, s, s + alpha * ds, tau)
        if slacks is not None and merit(ip, trial, slacks, nu) <= base + 1e-4 * alpha * descent:
            return accept(ip, trial, slacks, z, dz, boundary_step(z, dz, tau), alpha)
        alpha /= 2
    return None


def reset(ip, trial: Path, s: np.ndarray, stepped: np.ndarray, tau: float):
    """The slacks at ``trial``: −c where that keeps them within the fraction to the
    boundary (−c ≥ (1 − τ)s), else the stepped ones s + αΔs; None where c is not finite.
    The step linearises c + s = 0, and c is curved (a control is a nonlinear function of
    three nodes): with the stepped slacks the merit's ν‖c + s‖₁ grew like α² and rejected
    every step longer than α ≈ 10⁻³ (the cart-pole swing-up at N = 700 crept at α = 1/8
    for 200 iterations at μ = 1.6e-4); with the slacks reset the merit weighs the barrier
    −μh log(−c) instead, and the same solve reached μ = 6.4e-6 in 12 iterations (a slack
    reset, as in Byrd, Nocedal & Waltz's KNITRO)."""
    problem = ip.problem
    if not ip.inequalities.evaluate(trial, problem.p, problem.step(trial)):
        return None
    exact = -ip.inequalities.values
    return np.where(exact >= (1.0 - tau) * s, exact, stepped)


def _kkt_norm(ip, path: Path, s: np.ndarray, c: np.ndarray | None = None) -> float:
    """‖(∇ℒ, Φ_d, c + s, s∘z − μh)‖₂ of the barrier problem's KKT system at ``path``
    (its multipliers z in ``path``), c evaluated unless given."""
    from scipy.linalg.blas import dnrm2

    problem = ip.problem
    res, _, _, finite = problem.assemble(path, False)
    if c is None:
        finite = finite and ip.inequalities.evaluate(path, problem.p, problem.step(path))
        c = ip.inequalities.values
    if not finite:
        return np.inf
    parts = (res, (c + s).ravel(), (s * ip.z(path) - ip.mu * ip.unit).ravel())
    return float(np.sqrt(sum(float(dnrm2(v)) ** 2 for v in parts)))


def _residual_search(ip, path: Path, delta, ds, dz, c):
    """Backtracking on the KKT residual's norm from the fraction-to-the-boundary step,
    when the merit rejects a Newton step for the second-order growth of ν‖Φ_d‖₁ (the
    Maratos effect: the cart-pole's swing-up, started at the optimum without bounds,
    stalled at its first step); the equality solver falls back the same way
    (:func:`.globalisation.line_search`). The moved path, or None."""
    tau = max(TAU_MIN, 1.0 - ip.mu)
    z = ip.z(path).copy()
    base = _kkt_norm(ip, path, ip.s, c)
    alpha, alpha_z = boundary_step(ip.s, ds, tau), boundary_step(z, dz, tau)
    while alpha >= 2.0**-12:
        ip.log.trial()
        trial = ip.problem.moved(path, delta, alpha)
        if trial is not None:
            s = ip.s + alpha * ds
            trial.lam[:, ip.s_count:] = z + min(alpha, alpha_z) * dz
            if _kkt_norm(ip, trial, s) <= np.sqrt(1 - 1e-4 * alpha) * base:
                return accept(ip, trial, s, z, dz, min(alpha, alpha_z), alpha)
        alpha /= 2
    return None


def _natural(ip, path: Path, ab, bw: int, delta, ds, dz, error: float):
    """The full step (to the boundary) if the correction the same reduced matrix gives
    at the moved path is smaller than ``error``, the one it makes: Deuflhard's natural
    monotonicity test, which needs no merit function. Else None."""
    problem, h = ip.problem, ip.unit
    tau = max(TAU_MIN, 1.0 - ip.mu)
    alpha, z = boundary_step(ip.s, ds, tau), ip.z(path).copy()
    trial = problem.moved(path, delta, alpha)
    if trial is None:
        return None
    s = ip.s + alpha * ds
    trial.lam[:, ip.s_count:] = safeguarded(z + boundary_step(z, dz, tau) * dz, s, ip.mu * h)
    res, _, _, finite = problem.assemble(trial, False)
    finite = finite and ip.reduce(trial, s, res, problem.inequality_rates(trial))
    if not finite:
        return None
    simplified = problem.solve(ab, bw, -res)
    if not float(np.abs(simplified).max(initial=0.0)) < error:
        return None
    ip.s = s
    ip.log.step(alpha=alpha)
    return trial


def accept(ip, trial: Path, s: np.ndarray, z, dz, alpha_z: float, alpha: float) -> Path:
    """``trial`` with the slacks ``s`` and the multipliers z + α_z Δz (safeguarded) set,
    the step α recorded."""
    ip.s = s
    trial.lam[:, ip.s_count:] = safeguarded(z + alpha_z * dz, s, ip.mu * ip.unit)
    ip.log.step(alpha=alpha)
    return trial
