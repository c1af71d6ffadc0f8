"""A start inside (nearly) the bounds for the interior point: the cost plus a quadratic
penalty on the violated inequalities, solved by the equality solver (issue 21).

A cold bounded solve first solves the problem without its inequalities
(:func:`.bvp._unbounded`) and starts the interior point at its optimum. Where that
optimum violates them widely, the interior point may fail from there, and
:func:`.interior.bounded` retries from the start built here: a planar flyer whose unbounded optimum brakes with a forward-only
thruster (f₁ < 0 on 107 of 199 windows) STALLED after 11 iterations — the fraction to
the boundary cut the slack steps to α = 10⁻³…10⁻⁷, the bound multipliers grew to 10⁷
and the inertia correction shifted the Hessian by 10³ of its scale. Minimising first

    S + ρ/2 Σ max(0, c)²,    ρ = 10² h, then 10⁴ h

(the cost weighs a window by h; Gauss–Newton Hessian S'' + ρ GᵀG on the violated rows,
assembled by the barrier's elimination in C with z = ρ, s = 1, μ = 0) brings the
violations to about 10⁻¹ and 5·10⁻³ of their scale on that flyer, from where the
interior point converges in 16–18 iterations. Each stage is warm-started from the last;
a stage that fails leaves the last start.
"""
from __future__ import annotations

import numpy as np

from .assembly import Problem
from .barrier import Inequalities
from .paths import Path

#: The penalties ρ/h of the successive stages.
STAGES = (1e2, 1e4)


class PenalisedProblem(Problem):
    """:class:`.assembly.Problem` of S + ρ/2 Σ max(0, c)² (residual, Gauss–Newton
    Jacobian and merit), ``inequalities`` the solve's :class:`.barrier.Inequalities`."""

    def __init__(self, base: Problem, inequalities: Inequalities, rho: float):
        super().__init__(base.model, base.p, base.h)
        self.inequalities, self.rho = inequalities, rho

    def assemble(self, path: Path, with_jacobian: bool):
        res, ab, bw, finite = super().assemble(path, with_jacobian)
        ineq = self.inequalities
        finite = finite and ineq.evaluate(path, self.p, self.h)   # add_barrier: G
        if finite:
            violated = np.ascontiguousarray(self.rho * (ineq.values > 0.0))
            finite = ineq.add_barrier(path, self.p, self.h, violated, np.ones_like(violated),
                                      0.0, res, ab if with_jacobian else None)
        if with_jacobian:
            self._last = (path, (res, ab, bw, finite))
        return res, ab, bw, finite

    def merit(self, path: Path) -> tuple[float, float]:
        cost, noise = super().merit(path)
        if not self.inequalities.evaluate(path, self.p, self.h):
            return np.inf, noise
        excess = np.maximum(self.inequalities.values, 0.0)
        return cost + 0.5 * self.rho * float((excess * excess).sum()), noise


def nearly_feasible(problem: Problem, path: Path, newton, maxiter: int,
                    xtol: float) -> tuple[Path, int, int]:
    """(start, Newton iterations, stages solved): ``path`` (the optimum without
    inequalities) moved by the penalty stages where it violates an inequality, else
    unchanged. ``newton`` is :func:`.bvp._newton`."""
    from .results import Status

    inequalities = Inequalities(problem.model, path.x.shape[0])
    if not inequalities.evaluate(path, problem.p, problem.h) or \
            not (inequalities.values > 0.0).any():
        return path, 0, 0
    count = solved = 0
    for rho in STAGES:
        stage = PenalisedProblem(problem, inequalities, rho * problem.h)
        moved, _, steps, status, _ = newton(stage, path.copy(), maxiter, xtol, 0.0)
        count += len(steps)
        if status != Status.SUCCESS:
            break
        path, solved = moved, solved + 1
    return path, count, solved
