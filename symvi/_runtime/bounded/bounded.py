"""The phases of a bounded whole-trajectory solve (issues 21 and 50): which start the
interior point gets, and what follows when it fails.

The interior point (:mod:`.interior`) starts from the guess. Where it stalls or runs
out of iterations, a cold start solves the problem without its inequalities and starts
the interior point again from that optimum (or that solve's last iterate); where that
fails the same way, the penalty stages (:mod:`.penalty`) move the start toward the
bounds and it starts again; where that fails too, the stages continue to a certificate
of local infeasibility. A warm start (a previous result) goes to the active-set Newton
(:mod:`.polish`) first, from the previous active set. Each phase's verdict is the
interior point's SUCCESS rule. With the horizon an unknown (:mod:`.bvp.bordered`) only
the interior point from the guess runs (:func:`bounded_horizon`).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .interior import InteriorPoint
from ..bvp.newton import newton
from ..bvp.optimality import NEAR_FIRST_SHIFT
from ..core.options import NEAR_MU, SolveOptions
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

    The interior point starts from the guess (issue 50): with the filter line search,
    the barrier problems judged by their residuals and the active set handed to the
    active-set Newton once identified and Mehrotra's barrier rule, the cart-pole
    swing-up from its default guess takes 58 and 51 iterations at N = 100 and 1000
    (from the optimum without bounds, as before, 21 and 336) and ends at the lower of
    its two minima, the one IPOPT finds from the same start (20.41 at N = 1000, against
    32.29). Where it stalls or runs out of
    iterations, a ``cold`` start goes on from the optimum without bounds
    (:func:`_from_the_unbounded_optimum`): the planar flyer's straight-line guess
    crosses its keep-out disc, a concave constraint whose curvature the barrier's
    multipliers turn into the Hessian's, and no inertia correction up to 10³ gives a
    step there. The result counts every phase's iterations. ``ftol`` is not used.

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
    if cold and options.interior_start == "unbounded":
        return _from_the_unbounded_optimum(problem, path, options)
    # a previous result (without its active set) is a start near a solution
    ip, end, iterations, status, message = _interior(problem, path, options, near=not cold)
    if status in FAILED and cold:
        return _from_the_unbounded_optimum(problem, path, options, iterations, ip.failure)
    if status == Status.SUCCESS:
        start = "the guess" if cold else "the warm start"
        message = f"interior point from {start}: {iterations} iterations{message}"
    return ip.result(end, iterations, status, message)


def bounded_horizon(problem, path: Path, options: SolveOptions, cold: bool,
                    active: np.ndarray | None = None) -> BVPResult:
    """:func:`bounded` with the horizon an unknown (``problem`` a
    :class:`.bordered.HorizonProblem`): the warm start's active-set Newton, then the
    interior point from the guess — not the penalty phases, which hold the horizon, and
    whose certificate of infeasibility would be one for this horizon only (a horizon too
    short for the bounds is lengthened, not INFEASIBLE: issue 50) — and, where it stalls or
    runs out of iterations from a cold start, again from the optimum without bounds. Its
    failure is the caller's to answer (:func:`.bvp.solve_bvp`: the outer iteration on
    T)."""
    options = options.replace(ftol=0.0)
    if active is not None:
        warm = _warm(problem, path, active, options)
        if warm is not None:
            return replace(warm, message=f"{warm.message}; free horizon T = {warm.T:.12g}")
    ip, end, iterations, status, message = _interior(problem, path, options, near=not cold)
    phase = f"interior point from {'the guess' if cold else 'the warm start'}"
    if status in FAILED and cold and not problem.model.info.pure_minimum_time:
        # as bounded()'s: from the optimum without bounds, T free there too (perturbed
        # starts of the double integrator stalled at μ = 10, primal infeasibility 4–240;
        # pure minimum time has none: without bounds its Newton matrix is zero)
        near = options.replace(mu_start=min(options.mu_start, NEAR_MU))
        optimum, first, _ = unbounded(problem, path, near)
        if optimum is not None:
            retry = _interior(problem, optimum, near, near=True)
            if retry[3] not in FAILED:
                spent = iterations + first
                ip, end, iterations, status, message = retry
                iterations += spent
                phase = (f"after the interior point from the guess failed, from the optimum "
                         f"without bounds ({first} Newton iterations), interior point")
    if status == Status.SUCCESS:
        message = f"{phase}, the horizon an unknown: {iterations} iterations{message}"
    return ip.result(end, iterations, status, f"{message}; free horizon T = {end.T:.12g}")


def _from_the_unbounded_optimum(problem, path: Path, options: SolveOptions, spent: int = 0,
                                failure: str | None = None) -> BVPResult:
    """The solve from the optimum without bounds (``options.interior_start``), or after
    the interior point from the guess failed (``spent`` iterations, ``failure`` its
    message): the problem without its inequalities solved from the guess
    (:func:`unbounded`), the interior point from that optimum (or that solve's last
    iterate); where it stalls or runs out of iterations,
    :func:`.penalty.nearly_feasible` moves that optimum toward the bounds by a quadratic
    penalty and the interior point starts again from there; where that fails the same
    way, :func:`.penalty.infeasibility` continues the penalty stages: a certificate
    (:class:`.penalty.Infeasibility`) makes the result INFEASIBLE."""
    options = options.replace(mu_start=min(options.mu_start, NEAR_MU))
    problem.first_shift = NEAR_FIRST_SHIFT      # issue 21's route, as it was tuned
    optimum, first, converged = unbounded(problem, path, options)
    without = "the optimum without bounds" if converged else \
        "the last iterate without bounds"
    before = "" if failure is None else \
        f"after the interior point from the guess failed ({spent} iterations: {failure}), "
    phase = before + (f"from {without} ({first} Newton iterations), "
                      if optimum is not None else "")
    ip, end, iterations, status, message = _interior(
        problem, optimum if optimum is not None else path, options, near=True)
    total = spent + first + iterations
    if status in FAILED and optimum is not None:
        start, more, stages = nearly_feasible(problem, optimum, options)
        total += more
        if stages:
            retry = _interior(problem, start, options, near=True)
            total += retry[2]
            # kept unless it failed the same way: a SUCCESS, or an ILL_CONDITIONED
            # that states the accuracy reached, says more than the first stall
            if retry[3] not in FAILED:
                ip, end, iterations, status, message = retry
                phase = (f"{before}from {without}, moved toward the bounds by {stages} "
                         f"penalty stage{'s' if stages > 1 else ''} ({total - iterations} "
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


def _interior(problem, path: Path, options: SolveOptions, near: bool = False):
    """(InteriorPoint, path, iterations, status, message) of the interior-point
    iteration from ``path``, the minimum test applied to a converged one; ``near``: a
    start near a solution (:class:`.interior.InteriorPoint`)."""
    problem.shift, problem.penalty, problem.convex = 0.0, 0.0, False
    path = path.copy()      # the interior point sets the bound multipliers of its start
    ip = InteriorPoint(problem, path, options, near)
    path, iterations, status, message = ip.solve(path)
    if status == Status.SUCCESS and ip.verified is not path:   # the active-set Newton's is
        status, message = ip.minimum(path, message)
        if status == Status.SADDLE:
            # a KKT point to the tolerance whose active set is not yet the minimum's: the
            # pure minimum-time double integrator at N = 1600, T within 2e-10 of T* but
            # four windows 2e-5 off their bound, where W = 0 fixes nothing
            finished = ip.finish(path, options.xtol * (1.0 + problem.size(path)))
            if finished is not None:
                path, status = finished[0], Status.SUCCESS
                message = f" (its active set finished at the KKT point){finished[1]}"
    return ip, path, iterations + ip.active_set_steps, status, message
