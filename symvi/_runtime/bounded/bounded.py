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
from ..bvp.newton import newton
from ..core.options import SolveOptions
from ..core.paths import Path
from .penalty import infeasibility, nearly_feasible
from ..core.results import BVPResult, Status

#: The failures after which the interior point starts again (and then tests infeasibility).
FAILED = (Status.STALLED, Status.MAX_ITERATIONS)


def bounded(problem, path: Path, options: SolveOptions, cold: bool,
            active: np.ndarray | None = None) -> BVPResult:
    """The interior-point solve of :func:`.bvp.solve_bvp` for a model with inequalities,
    under the solve's ``options``: its result, SUCCESS only at a verified minimum within
    the tolerance (module docstring).

    A ``cold`` start first solves the problem without inequalities from the guess
    (:func:`unbounded`); the interior-point iteration starts from that optimum
    (or that solve's last iterate) where it exists, from the guess otherwise, and the
    result counts every solve's iterations. The equality
    solver's globalisation is the better tested of the two far from a solution: from
    perturbed guesses whose torques exceed the bounds 400-fold, the interior-point steps
    were cut to α ≈ 10⁻² by the fraction-to-the-boundary rule and stalled; from the
    unbounded optimum it needs 20–30 iterations. Where the interior point then stalls or
    runs out of iterations, :func:`.penalty.nearly_feasible` moves that optimum toward
    the bounds by a quadratic penalty and the interior point starts again from there — a
    retry, not the first choice: on the cart-pole swing-up the penalised start is the
    worse one (MAX_ITERATIONS at N = 60, against SUCCESS in 33 iterations from the
    optimum). Where that fails the same way, :func:`.penalty.infeasibility` continues the
    penalty stages: a certificate (:class:`.penalty.Infeasibility`) makes the result
    INFEASIBLE. ``ftol`` is not used by any of them.

    ``active``: a warm start's active set (the previous result's, its multipliers in
    ``path``): the active-set Newton (:mod:`.polish`) is tried first from there, and the
    interior point runs only where it fails — along a continuation whose active set
    barely changes, a few Newton steps instead of a barrier solve.
    """
    options = options.replace(ftol=0.0)
    if active is not None:
        warm = _warm(problem, path, active, options)
        if warm is not None:
            return warm
    optimum, first, converged = unbounded(problem, path, options) if cold else \
        (None, 0, False)
    without = "the optimum without bounds" if converged else \
        "the last iterate without bounds"
    phase = f"from {without} ({first} Newton iterations), " if optimum is not None else ""
    # a copy: the interior point sets the bound multipliers of the path it starts from
    ip, end, iterations, status, message = _interior(
        problem, optimum.copy() if optimum is not None else path, options)
    total = first + iterations
    if status in FAILED and optimum is not None:
        start, more, stages = nearly_feasible(problem, optimum, options)
        total += more
        if stages:
            retry = _interior(problem, start, options)
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
        if status in FAILED and stages == len(options.penalty_stages):
            certificate, more = infeasibility(problem, start, options)
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


def unbounded(problem, path: Path, options: SolveOptions):
    """(start or None, Newton iterations, converged): the problem without its
    inequalities (their multipliers held at zero) solved from ``path``, the interior-point
    solve's start (:func:`bounded`); None where that solve ended on a
    non-finite value, diverged or left the chart. An unconverged last iterate is start
    enough, the iterations having moved it downhill from the guess: the cart-pole
    swing-up at N = 1000 from the cubic guess needs 112 Newton iterations without bounds,
    and after a hundred the interior point had started from the guess and stalled."""
    solved, _, steps, status, _ = newton(problem, path.copy(), options,
                                        "start without bounds")
    problem.shift, problem.penalty, problem.convex = 0.0, 0.0, False
    usable = status not in (Status.NON_FINITE, Status.DIVERGED, Status.OUTSIDE_CHART)
    return (solved if usable else None), len(steps), status == Status.SUCCESS


def _warm(problem, path: Path, active: np.ndarray, options: SolveOptions) -> BVPResult | None:
    """The result of the active-set Newton from a warm start's ``path`` and ``active``
    set where it ends at a verified minimum within the tolerance, else None."""
    problem.shift, problem.penalty, problem.convex = 0.0, 0.0, False
    ip = InteriorPoint(problem, path.copy(), options)   # its copy's z are the barrier's
    finished = ip.finish(path, options.xtol * (1.0 + problem.size(path)), active)
    if finished is None:
        return None
    end, message, steps = finished
    return ip.result(end, steps, Status.SUCCESS,
                     f"warm start from the previous active set{message}")


def _interior(problem, path: Path, options: SolveOptions):
    """(InteriorPoint, path, iterations, status, message) of the interior-point
    iteration from ``path``, the minimum test applied to a converged one."""
    problem.shift, problem.penalty, problem.convex = 0.0, 0.0, False
    ip = InteriorPoint(problem, path, options)
    path, iterations, status, message = ip.solve(path)
    if status == Status.SUCCESS and ip.verified is not path:   # the active-set Newton's is
        status, message = ip.minimum(path, message)
    return ip, path, iterations, status, message
