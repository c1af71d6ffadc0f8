"""The whole-trajectory Newton iteration and its verdicts (DESIGN.md §4): damped Newton
on a :class:`.assembly.Problem` from a path, SUCCESS on full corrections within the
tolerance with their rounding floor, ILL_CONDITIONED where rounding bounds the error
above it (issue 20).

A function the phases import and call with the solve's :class:`.options.SolveOptions`:
the fixed-horizon solve (:mod:`.bvp`), the start without bounds (:mod:`.bounded`) and
the penalty stages (:mod:`.penalty`). Its globalisation is :mod:`.globalisation`.
"""
from __future__ import annotations

import math

import numpy as np

from .globalisation import descent_step, line_search, natural_step
from ..core.log import IterationLog
from ..core.options import SolveOptions
from ..core.results import Status

#: A Newton correction at the residual's rounding level within this factor of the
#: rounding floor (:meth:`.assembly.Problem.rounding_correction`), and not half the one
#: before, is noise: iterating on cannot shrink it (the heavy top with rotors at
#: N = 10⁵ and xtol = 1e-9: 60 iterations, 590 s, corrections between 1e-5 and 1e-3
#: against a floor of 2e-4).
NOISE = 10.0


def newton(problem, state, options: SolveOptions, phase: str = "whole trajectory"):
    """Damped Newton on ``problem`` from ``state`` under ``options`` (``maxiter``,
    ``xtol``, ``ftol``, ``verbose``: each iteration's residual norm and step on stderr,
    named by ``phase``); returns (state, residual norms, step norms, status, message)."""
    from scipy.linalg import LinAlgError

    maxiter, xtol, ftol = options.maxiter, options.xtol, options.ftol
    norms, steps, corrections = [], [], [np.inf]
    problem.log = log = IterationLog(f"{phase}: Newton", options.verbose)
    for it in range(maxiter):
        try:
            state, taken, status, message = _iteration(problem, state, it, xtol, ftol, norms,
                                                       corrections)
        except LinAlgError as exc:
            # a shifted or gauged Newton matrix with a zero pivot in its band LU
            return state, norms, steps, Status.SINGULAR_JACOBIAN, (
                f"singular Newton matrix at iteration {it} ({exc})")
        log.report(it, f": {status.name}" if status is not None else "")
        if taken is not None:
            steps.append(taken)
        if status is not None:
            if status is Status.SUCCESS and taken is not None:
                # the residual of the path returned, after the last update (with the
                # Jacobian that the second-order test of a minimum needs next)
                norms.append(_residual_norm(problem, state, problem.minimise))
            return state, norms, steps, status, message
    norms.append(_residual_norm(problem, state))
    return (state, norms, steps, Status.MAX_ITERATIONS,
            f"Newton's method did not converge in {maxiter} iterations")


def _measure(problem, state, res: np.ndarray) -> None:
    """The iteration's row of the log (:mod:`..core.log`) at ``state``, its residual
    ``res``: the cost, the constraint rows' and the node rows' residuals, the horizon."""
    rows = problem.constraint_rows(state)
    problem.log.measured(mu=math.nan, objective=problem.merit(state)[0],
                         primal=float(np.abs(res[:rows.size][rows]).max(initial=0.0)),
                         dual=float(np.abs(res[:rows.size][~rows]).max(initial=0.0)),
                         complementarity=math.nan,
                         T=math.nan if state.T is None else state.T)


def _residual_norm(problem, state, with_jacobian: bool = False) -> float:
    return float(np.abs(problem.assemble(state, with_jacobian)[0]).max(initial=0.0))


def _iteration(problem, state, it: int, xtol: float, ftol: float, norms: list,
               corrections: list):
    """One damped Newton iteration from ``state`` (its residual norm appended to
    ``norms``, its full Newton correction to ``corrections``): (state, step taken or
    None, final status or None, message)."""
    from scipy.linalg import LinAlgError

    res, ab, bw, finite = problem.assemble(state, True)
    norms.append(float(np.abs(res).max(initial=0.0)))
    _measure(problem, state, res)
    if not finite:
        return state, None, Status.NON_FINITE, f"non-finite residual or Jacobian at iteration {it}"
    try:
        delta = problem.solve(ab, bw, -res)
    except LinAlgError:
        # even at R = 0: the solution is then not isolated (e.g. L_d ≡ 0)
        return state, None, Status.SINGULAR_JACOBIAN, f"singular Jacobian at iteration {it}"
    if norms[-1] <= ftol:
        return state, None, Status.SUCCESS, ""
    # SUCCESS only on full Newton corrections, the estimate of the error left (a damped
    # step may be short far from the solution), with the rounding floor beside them
    size = problem.correction_norm(delta, state)
    tolerance = xtol * (1.0 + problem.size(state))
    corrections.append(size)
    problem.log.correction(size)
    level = problem.rounding_level(ab, bw, state)
    problem.level = level
    if size <= tolerance and not problem.held:
        return _within_tolerance(problem, state, ab, bw, res, delta, size, tolerance,
                                 corrections[-2], it)
    taken, problem.last_shift, problem.last_trials = None, 0.0, 0
    if norms[-1] <= level:
        # the floor costs an update, a residual and a solve: only once Newton stops
        # contracting
        floor = problem.rounding_correction(ab, bw, state, res) \
            if size > corrections[-2] / 2 else 0.0
        if tolerance < floor and size <= NOISE * floor:
            return state, None, *_rounding_limited(
                f"the residual ({norms[-1]:.1e}) is at its rounding level ({level:.1e}) "
                f"and the Newton correction ({size:.1e}) is of the size of the one "
                f"that undoes rounding the path's unknowns by one unit in the last "
                f"place ({floor:.1e})", max(size, floor), tolerance)
        state, taken = natural_step(problem, state, delta, ab, bw, size)
        problem.convex = False
    if taken is None and problem.minimise:
        state, taken = descent_step(problem, state, res, ab, bw, delta,
                                    contracting=size <= corrections[-2] / 4)
    if taken is None and norms[-1] > level:
        state, taken = line_search(problem, state, delta, res)
        problem.convex = False
    if taken is None:
        if norms[-1] <= level:  # no descent left below the rounding level
            return state, None, *_rounding_limited(
                f"the residual ({norms[-1]:.1e}) is at its rounding level ({level:.1e}), "
                f"where the Newton correction, the estimated error of the path, is "
                f"{size:.1e}", size, tolerance)
        return state, None, Status.STALLED, f"line search stalled at iteration {it}"
    full = float(np.abs(delta).max(initial=0.0))
    problem.log.step(alpha=taken / full if full > 0 else 1.0, shift=problem.last_shift,
                     trials=problem.last_trials)
    return state, taken, None, ""


def _within_tolerance(problem, state, ab, bw: int, res, delta, size: float,
                      tolerance: float, previous: float, it: int):
    """The iteration once the full Newton correction Δ of ``state`` is within the
    tolerance: (state, step taken, status or None, message) as :func:`_iteration`.

    To first order the error of ``state`` is at most ‖Δ‖∞ plus the rounding noise of R
    amplified by J⁻¹, which the rounding floor estimates
    (:meth:`.assembly.Problem.rounding_correction`, with this J and R): SUCCESS when the
    sum is within the tolerance, returning state + Δ, closer still where Newton
    contracts. A correction small by cancellation against that noise (the heavy top with
    rotors at N = 10⁴ passed two in a row below 1.9e-7 by luck, its multipliers 1e-6
    off) is caught by the floor; a first small correction that did not halve the one
    before is judged at the next iteration. Where the floor exceeds the tolerance, or a
    non-contracting correction and the floor together do, the path is
    ``ILL_CONDITIONED``.

    Corrections that do not shrink at all are no estimate, unless they are rounding's
    noise (within :data:`NOISE` floors): Newton goes on.

    Corrections that shrink only linearly, by a rate ρ = ‖Δ_k‖/‖Δ_{k−1}‖ in (½, 1) (a
    Newton matrix so ill-conditioned that its solves are inexact: minimum jerk at
    N = 2500 took 94 iterations at ρ ≈ 0.91), leave an error ρ/(1 − ρ)·‖Δ‖ after the step,
    which takes the place of ‖Δ‖: below the tolerance with the floor, SUCCESS; above it,
    Newton goes on."""
    moved = problem.moved(state, delta, 1.0)    # round-off defeats a line search
    if moved is None:
        return state, None, Status.STALLED, (
            f"the full Newton step leaves the retraction's chart at iteration {it}")
    contracting = size <= previous / 2
    if not contracting and previous > tolerance:
        return moved, size, None, ""
    rate = size / previous
    slow = not contracting and rate < 1.0
    error = size * rate / (1.0 - rate) if slow else size
    floor = problem.rounding_correction(ab, bw, state, res)
    if not (contracting or slow) and size > NOISE * floor:
        # a correction that did not shrink, and is not rounding's noise, estimates no
        # error: far from a free horizon's optimum Newton moves T by about T/4 per
        # iteration, corrections 30× below the distance (a hunt: T = 0.025 returned for
        # T* = 0.21 at xtol = 1e-2, within xtol·(1 + size) of nodes of size 1)
        return moved, size, None, ""
    if tolerance / EDGE < error + MARGIN * floor:
        # near the edge one direction could be luck: two more (each a residual and a
        # solve; always taking them cost rigid_body_oc at N = 1000 4.7 → 5.9 ms)
        floor = max(floor, problem.rounding_correction(ab, bw, state, res, range(1, 3)))
    if error + MARGIN * floor <= tolerance:
        linear = (f" (shrinking linearly by {rate:.2f}: error estimate {error:.1e})"
                  if slow else "")
        return moved, size, Status.SUCCESS, (
            f"; last Newton correction {size:.1e}{linear}, rounding floor {floor:.1e}")
    if (contracting or slow) and floor < tolerance:
        return moved, size, None, ""
    return moved, size, *_rounding_limited(
        f"the Newton correction ({size:.1e}) is within the tolerance, but with the one "
        f"that undoes rounding the path's unknowns by one unit in the last place "
        f"({floor:.1e}) it bounds the error by {size + floor:.1e}", size + floor, tolerance)


#: Where the correction plus one rounding floor comes within this factor of the
#: tolerance, the floor takes two more random directions: across eight, the floors of
#: cart_pole_oc at N = 1000 varied within 4×.
EDGE = 4.0
#: The floor is a sample — the largest of at most three random directions — of a noise
#: whose worst direction can be larger: SUCCESS asks the correction plus this many floors
#: to be within the tolerance. An order-5 minimum-jerk-like solve at N = 150 was 4.9 off
#: with a correction 0.33 and a floor 2.0 under a tolerance 4.0.
MARGIN = 2.0


def _rounding_limited(finding: str, attainable: float, tolerance: float):
    """Status and message when rounding, not Newton, bounds the error left (``finding``
    says how it showed, ``attainable`` the estimate of that error) above the tolerance:
    never SUCCESS (issue 20). The correction is rounding noise amplified by the
    conditioning of the Newton matrix, so its size is the attainable accuracy."""
    return Status.ILL_CONDITIONED, (
        f"{finding} > the tolerance xtol·(1 + size) = {tolerance:.1e}: rounding amplified "
        f"by the Newton matrix's conditioning limits the attainable accuracy to about "
        f"{attainable:.0e}; accept it with a larger xtol, or use fewer steps")
