"""The phases of a bounded whole-trajectory solve (issue 21): which start the
interior point gets, and what follows when it fails.

A cold start solves the problem without its inequalities first and starts the interior
point (:mod:`.interior`) from that optimum (or that solve's last iterate); where the
interior point stalls or runs out of iterations, the penalty stages (:mod:`.penalty`)
move the start toward the bounds and it starts again; where that fails the same way,
the stages continue to a certificate of local infeasibility. A warm start (a previous
result) goes to the active-set Newton (:mod:`.polish`) first, from the previous active
set. Each phase's verdict is the interior point's SUCCESS rule.
"""
from __future__ import annotations

import numpy as np

from .interior import InteriorPoint
from .paths import Path
from .penalty import STAGES
from .results import BVPResult, Status

#: The failures after which the interior point starts again (and then tests infeasibility).
FAILED = (Status.STALLED, Status.MAX_ITERATIONS)


def bounded(model, problem, path: Path, maxiter: int, xtol: float, unbounded=None,
            nearly_feasible=None, infeasibility=None, active=None) -> BVPResult:
    """The interior-point solve of :func:`.bvp.solve_bvp` for a model with inequalities:
    its result, SUCCESS only at a verified minimum within the tolerance (module
    docstring).

    ``unbounded(problem, path, maxiter, xtol)`` → (start or None, iterations,
    converged), where given (a cold start), first solves the problem without
    inequalities from the guess; the interior-point iteration starts from that optimum
    (or that solve's last iterate) where it exists, from the guess otherwise, and the
    result counts every solve's iterations. The equality
    solver's globalisation is the better tested of the two far from a solution: from
    perturbed guesses whose torques exceed the bounds 400-fold, the interior-point steps
    were cut to α ≈ 10⁻² by the fraction-to-the-boundary rule and stalled; from the
    unbounded optimum it needs 20–30 iterations. Where the interior point then stalls or
    runs out of iterations, ``nearly_feasible(problem, optimum, maxiter, xtol)`` →
    (start, iterations, stages) moves that optimum toward the bounds by a quadratic
    penalty (:mod:`.penalty`) and the interior point starts again from there — a retry,
    not the first choice: on the cart-pole swing-up the penalised start is the worse one
    (MAX_ITERATIONS at N = 60, against SUCCESS in 33 iterations from the optimum). Where
    that fails the same way, ``infeasibility(problem, start, maxiter, xtol)`` →
    (certificate or None, iterations) continues the penalty stages: a certificate
    (:class:`.penalty.Infeasibility`) makes the result INFEASIBLE.

    ``active``: a warm start's active set (the previous result's, its multipliers in
    ``path``): the active-set Newton (:mod:`.polish`) is tried first from there, and the
    interior point runs only where it fails — along a continuation whose active set
    barely changes, a few Newton steps instead of a barrier solve.
    """
    if active is not None:
        warm = _warm(problem, path, active, xtol)
        if warm is not None:
            return warm
    optimum, first, converged = unbounded(problem, path, maxiter, xtol) \
        if unbounded is not None else (None, 0, False)
    without = "the optimum without bounds" if converged else \
        "the last iterate without bounds"
    phase = f"from {without} ({first} Newton iterations), " if optimum is not None else ""
    # a copy: the interior point sets the bound multipliers of the path it starts from
    ip, end, iterations, status, message = _interior(
        problem, optimum.copy() if optimum is not None else path, maxiter, xtol)
    total = first + iterations
    if status in FAILED and optimum is not None and nearly_feasible is not None:
        start, more, stages = nearly_feasible(problem, optimum, maxiter, xtol)
        total += more
        if stages:
            retry = _interior(problem, start, maxiter, xtol)
            total += retry[2]
            # kept unless it failed the same way: a SUCCESS, or an ILL_CONDITIONED
            # that states the accuracy reached, says more than the first stall
            if retry[3] not in FAILED:
                ip, end, iterations, status, message = retry
                before = total - iterations
                phase = (f"after an interior point from {without} failed, from "
                         f"there moved toward the bounds by "
                         f"{stages} penalty stage{'s' if stages > 1 else ''} ({before} "
                         f"iterations before), ")
        if status in FAILED and stages == len(STAGES) and infeasibility is not None:
            certificate, more = infeasibility(problem, start, maxiter, xtol)
            total += more
            if certificate is not None:
                end = certificate.least_violation(ip.inequalities, problem)
                ip.s = np.maximum(-ip.inequalities.values, 0.0)     # active: the violated
                status, message = Status.INFEASIBLE, (
                    f"{certificate.describe(ip.inequalities.names, problem.h)}; the interior "
                    f"point failed: {ip.failure}")
    if status == Status.SUCCESS:
        message = f"{phase}interior point: {iterations} iterations{message}"
    return ip.result(end, total, status, message)


def _warm(problem, path: Path, active: np.ndarray, xtol: float) -> BVPResult | None:
    """The result of the active-set Newton from a warm start's ``path`` and ``active``
    set where it ends at a verified minimum within the tolerance, else None."""
    problem.shift, problem.penalty, problem.convex = 0.0, 0.0, False
    ip = InteriorPoint(problem, path.copy(), xtol)      # its copy's z are the barrier's
    finished = ip.finish(path, xtol * (1.0 + problem.size(path)), active)
    if finished is None:
        return None
    end, message, steps = finished
    return ip.result(end, steps, Status.SUCCESS,
                     f"warm start from the previous active set{message}")


def _interior(problem, path: Path, maxiter: int, xtol: float):
    """(InteriorPoint, path, iterations, status, message) of the interior-point
    iteration from ``path``, the minimum test applied to a converged one."""
    problem.shift, problem.penalty, problem.convex = 0.0, 0.0, False
    ip = InteriorPoint(problem, path, xtol)
    path, iterations, status, message = ip.solve(path, maxiter)
    if status == Status.SUCCESS and ip.verified is not path:   # the active-set Newton's is
        status, message = ip.minimum(path, message)
    return ip, path, iterations, status, message
