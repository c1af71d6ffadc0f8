"""A free final time with inequalities: the horizon T = N·h that minimises J_d + ρ·T by
an outer iteration (issue 21). Without inequalities the horizon is an unknown of the
Newton system itself (:mod:`.bordered`), which converges in the iterations of one solve.

The whole-trajectory solve at a fixed h gives the optimal discrete cost J*(T). Its
derivative needs no second solve: by the envelope theorem dJ*/dT = (1/N) ∂ℒ/∂h, the
partial derivative of the Lagrangian ℒ = Σ_w [L_d + λ·Φ_d + z·c] at the optimal path
and multipliers with the groupoid elements held fixed (the compiled ``horizon`` kernel:
∂L_d/∂h, ∂Φ_d/∂h, ∂c/∂h per window, and ρ). The optimal horizon solves the scalar
equation F'(T) = dJ*/dT + ρ = 0, by secant steps safeguarded by bisection once F' has
changed sign, each inner solve warm-started from the last (its fibres rescaled to keep
the elements); a trial horizon whose solve fails (too short for the bounds: no path
meets them) is moved halfway back to the last solved one. SUCCESS needs every inner
solve's SUCCESS and the secant's estimate of the distance to the root,
|F'(T)| / |F''(T)|, within xtol·(1 + T). The outer iterations and retries are the
solve's options (``horizon_maxiter``, ``horizon_retries``: :class:`.options.SolveOptions`).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..core.model_info import Kernel
from ..core.options import SolveOptions
from ..core.results import BVPResult, Status


def slope(model, result: BVPResult, p) -> float:
    """F'(T) = dJ*/dT + ρ at a solved path (module docstring)."""
    N = result.t.size - 1
    h = float(result.t[1])
    x = result.x if result.x is not None else np.zeros((N + 1, 0))
    values = model.along_vector(Kernel.HORIZON, x, result.f, h, p)
    lam = result.multipliers if result.multipliers is not None else np.zeros((len(values), 0))
    z = result.bound_multipliers if result.bound_multipliers is not None \
        else np.zeros((len(values), 0))
    weights = np.hstack([np.ones((len(values), 1)), lam, z])
    derivative = float((values[:, :weights.shape[1]] * weights).sum())
    if result.end_multipliers is not None:     # ν·∂ψ/∂h of the end conditions
        last = np.concatenate([x[-2], result.f[-1]])
        derivative += float(model.kernel_outputs(Kernel.END_HORIZON, last, p, h)[0]
                            @ result.end_multipliers)
    return derivative / N + float(values[0, -1])


def free_horizon(newton, solve, model, p, N: int, h: float,
                 options: SolveOptions) -> BVPResult:
    """Minimise J* + ρT over T from T = N·h under the solve's ``options``: ``newton()``, the
    solve with T an unknown of its Newton system (:mod:`.bordered`), unless
    ``options.horizon_method`` is 'secant'; where that fails with inequalities, or with
    'secant', the outer iteration (:func:`outer`). ``solve(h, guess)`` is the
    fixed-horizon whole-trajectory solve at step h from ``guess`` (a previous result, or
    None for the solve's own guess), everything else as the solve was asked
    (:func:`.bvp.fixed_horizon`)."""
    if options.horizon_method == "secant":
        if model.info.pure_minimum_time:
            raise ValueError("horizon_method='secant' minimises the fixed-horizon optimum "
                             "J*(T) + ρT over T, and in pure minimum time J* is zero "
                             "wherever T is feasible: use horizon_method='newton'")
        return outer(solve, model, p, N, h, options)
    first = newton()
    if first.success or not model.inequalities or model.info.pure_minimum_time:
        # pure minimum time has no fixed-horizon optimum for the secant to move: every
        # feasible path costs nothing at a fixed T
        return first
    result = outer(solve, model, p, N, h, options)
    if result.success:
        return replace(result, message=(
            f"{result.message} (the horizon as an unknown of the interior point failed "
            f"first: {first.status.name}, {first.message})"))
    # the outer iteration's INFEASIBLE would certify one horizon only (a hunt: a first
    # guess 0.3 T* at xtol = 1e-3): the free horizon's failure is the first one's
    return replace(first, message=(
        f"{first.message}; the outer iteration on T failed too ({result.status.name}: "
        f"{result.message})"))


def outer(solve, model, p, N: int, h: float, options: SolveOptions) -> BVPResult:
    """The outer iteration of :func:`free_horizon` (module docstring)."""
    xtol = options.xtol
    T, result = N * h, solve(h, None)
    if not result.success:
        return _failed(result, T, "at the first horizon")
    history = [(T, slope(model, result, p))]     # (horizon, F') of every solve
    bracket = None
    step = 0.1 * T
    for _ in range(options.horizon_maxiter):
        T_now, g_now = history[-1]
        if len(history) == 1:
            T_next = T_now - np.sign(g_now) * step
        else:
            T_prev, g_prev = history[-2]
            curvature = (g_now - g_prev) / (T_now - T_prev)
            if curvature > 0:
                distance = abs(g_now / curvature)
                if max(abs(T_now - T_prev), distance) <= xtol * (1 + T_now):
                    return _converged(result, history, distance)
                T_next = T_now - g_now / curvature
            else:
                T_next = T_now - np.sign(g_now) * step
        if bracket is not None:
            low, high = bracket
            if not low < T_next < high:
                T_next = 0.5 * (low + high)
        T_next = max(T_next, 0.5 * T_now)        # the horizon stays positive
        trial = solve(T_next / N, result)
        for _ in range(options.horizon_retries):
            if trial.success:
                break
            # a horizon too short for the bounds (or a solve that failed there): halfway
            # back towards the last solved one
            T_next = 0.5 * (T_next + T_now)
            trial = solve(T_next / N, result)
        if not trial.success:
            return _failed(trial, T_next, f"at horizon T = {T_next:.6g}")
        result = trial
        history.append((T_next, slope(model, result, p)))
        bracket = _bracket(history)
        step *= 2.0
    return replace(result, status=Status.MAX_ITERATIONS, message=(
        f"the free horizon did not converge in {options.horizon_maxiter} steps (last T = "
        f"{history[-1][0]:.10g}, dJ/dT + ρ = {history[-1][1]:.2e}); {result.message}"))


def _bracket(history) -> tuple[float, float] | None:
    """The tightest (T_low, T_high) around the root of F' among the horizons tried."""
    below = [T for T, g in history if g < 0]
    above = [T for T, g in history if g > 0]
    if not below or not above:
        return None
    return max(below), min(above)


def _converged(result: BVPResult, history, distance: float) -> BVPResult:
    T, g = history[-1]
    return replace(result, message=(
        f"free horizon T = {T:.12g} after {len(history)} solves (dJ/dT + ρ = {g:.2e}, "
        f"estimated distance to the optimal T {distance:.1e}); last solve: "
        f"{result.message}"))


def _failed(result: BVPResult, T: float, where: str) -> BVPResult:
    return replace(result, message=f"free horizon: the solve {where} failed: {result.message}")
