"""A start inside (nearly) the bounds for the interior point: the cost plus a quadratic
penalty on the violated inequalities, solved by the equality solver (issue 21).

A cold bounded solve first solves the problem without its inequalities
(:func:`.bounded.unbounded`) and starts the interior point at its optimum. Where that
optimum violates them widely, the interior point may fail from there, and
:func:`.bounded.bounded` retries from the start built here: a planar flyer whose unbounded optimum brakes with a forward-only
thruster (f₁ < 0 on 107 of 199 windows) STALLED after 11 iterations — the fraction to
the boundary cut the slack steps to α = 10⁻³…10⁻⁷, the bound multipliers grew to 10⁷
and the inertia correction shifted the Hessian by 10³ of its scale. Minimising first

    S + ρ/2 Σ max(0, c)²,    ρ = 10² h, then 10⁴ h

(the cost weighs a window by h; Gauss–Newton Hessian S'' + ρ GᵀG on the violated rows,
assembled by the barrier's elimination in C with z = ρ, s = 1, μ = 0) brings the
violations to about 10⁻¹ and 5·10⁻³ of their scale on that flyer, from where the
interior point converges in 16–18 iterations. Each stage is warm-started from the last;
a stage that fails leaves the last start.

The penalties of the stages are the solve's options
(:attr:`.options.SolveOptions.penalty_stages`, then ``certifying_stages``); each stage is
the Newton iteration of :mod:`.newton` under the solve's options.

The same stages, continued tenfold at a time to ρ = 10⁸ h, tell an infeasible problem
from a failed solve (:func:`infeasibility`): with feasible bounds the largest violation
of the penalised minimiser falls like z*/ρ (the torque-limited slew at N = 40: 100-fold
per hundredfold ρ at τ_max = 9.5, 50-fold at 9.0, 0.1 % above the least feasible limit),
while without a feasible path it converges to the least violation reachable (0.9922 …
0.9917 at τ_max = 8.5, 0.1808 … 0.1804 at 8.9, over ρ = 10⁴ h … 10⁸ h): a stationary
point of the violation, where the cost's pull is ∇S/ρ. Tenfold, because at N = 1000 the
hundredfold stage from 10⁴ h ran out of 200 Newton iterations.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..bvp.assembly import Problem
from .barrier import Inequalities
from ..bvp.newton import newton
from ..core.options import SolveOptions
from ..core.paths import Path
from ..core.results import Status

#: The factor by which the largest violation must fall per certifying stage
#: (:attr:`.options.SolveOptions.certifying_stages`) for the bounds to count as feasible.
CONVERGED = 0.5
#: A certifying stage counts where its node corrections are this small (relative).
SETTLED = 1e-6


class PenalisedProblem(Problem):
    """:class:`.assembly.Problem` of S + ρ/2 Σ max(0, c)² (residual, Gauss–Newton
    Jacobian and merit), ``inequalities`` the solve's :class:`.barrier.Inequalities`."""

    def __init__(self, base: Problem, inequalities: Inequalities, rho: float):
        super().__init__(base.model, base.p, base.h)
        self.inequalities, self.rho = inequalities, rho
        self.first_shift = base.first_shift

    def assemble(self, path: Path, with_jacobian: bool, weights: np.ndarray | None = None):
        ineq = self.inequalities
        finite = ineq.evaluate(path, self.p, self.h)      # which rows the penalty weighs
        violated = np.ascontiguousarray(self.rho * (ineq.values > 0.0))
        res, ab, bw, assembled = super().assemble(path, with_jacobian, violated)
        finite = finite and assembled
        if finite:
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
        with np.errstate(over="ignore"):        # a wild trial step: inf, rejected
            return cost + 0.5 * self.rho * float((excess * excess).sum()), noise


def nearly_feasible(problem: Problem, path: Path,
                    options: SolveOptions) -> tuple[Path, int, int]:
    """(start, Newton iterations, stages solved): ``path`` (the optimum without
    inequalities) moved by the penalty stages (``options.penalty_stages``) where it
    violates an inequality, else unchanged."""
    inequalities = Inequalities(problem.model, path.x.shape[0])
    if not inequalities.evaluate(path, problem.p, problem.h) or \
            not (inequalities.values > 0.0).any():
        return path, 0, 0
    count = solved = 0
    for rho in options.penalty_stages:
        moved, steps, status, _ = _stage(problem, inequalities, path, rho, options)
        count += steps
        if status != Status.SUCCESS:
            break
        path, solved = moved, solved + 1
    return path, count, solved


@dataclass(frozen=True)
class Infeasibility:
    """A local certificate that the inequalities admit no path: the largest violation of
    the penalised minimisers (``violations``, at ``penalties`` ρ/h) stopped falling, at
    ``worst`` = (window, inequality) of the last, ``path``."""

    violations: tuple[float, ...]
    penalties: tuple[float, ...]
    worst: tuple[int, int]
    path: Path = field(compare=False, repr=False)

    def least_violation(self, inequalities: Inequalities, problem: Problem) -> Path:
        """The last penalised minimiser, the path the certificate describes, with the
        penalty's estimate of the bound multipliers, z = ρh·max(0, c) (its stationarity
        is that of the Lagrangian with these z); :attr:`Inequalities.values` at it."""
        path, s = self.path.copy(), problem.model.constraints
        inequalities.evaluate(path, problem.p, problem.h)
        path.lam[:, s:] = self.penalties[-1] * problem.h * np.maximum(inequalities.values, 0.0)
        return path

    def describe(self, names: tuple[str, ...], h: float) -> str:
        w, k = self.worst
        trail = ", ".join(f"{v:.4g}" for v in self.violations)
        return (f"the bounds admit no solution near this start: minimising the cost plus "
                f"ρ/2 Σ max(0, c)², the largest violation stayed at {trail} as ρ grew from "
                f"{self.penalties[0]:.0e} h to {self.penalties[-1]:.0e} h (feasible bounds "
                f"let it fall like 1/ρ) — a stationary point of the violation, the worst "
                f"{names[k]!r} at window {w} (t = {(w + 1) * h:.4g}); the path returned is "
                f"that last penalised minimiser. Loosen the bounds, "
                f"lengthen the horizon, or try another guess (the certificate is local)")


def infeasibility(problem: Problem, start: Path,
                  options: SolveOptions) -> tuple[Infeasibility | None, int]:
    """(certificate or None, Newton iterations): the penalty stages
    ``options.certifying_stages`` continued from ``start``, the last stage of
    :func:`nearly_feasible`; a certificate
    where the largest violation fell by less than :data:`CONVERGED` at every stage and
    stayed above rounding (module docstring). A stage solved only to ILL_CONDITIONED
    still counts: the violation needs no more digits."""
    inequalities = Inequalities(problem.model, start.x.shape[0])
    violations, path, count = [_violation(inequalities, problem, start)], start, 0
    for rho in options.certifying_stages:
        moved, steps, status, stage = _stage(problem, inequalities, path, rho, options)
        count += steps
        if status not in (Status.SUCCESS, Status.ILL_CONDITIONED) or \
                not _settled(stage, moved):
            return None, count
        path = moved
        violations.append(_violation(inequalities, problem, path))
        if not violations[-1] > max(CONVERGED * violations[-2], _floor(inequalities)):
            return None, count
    worst = np.unravel_index(int(np.argmax(inequalities.values)), inequalities.values.shape)
    return Infeasibility(tuple(violations),
                         (options.penalty_stages[-1],) + options.certifying_stages,
                         (int(worst[0]), int(worst[1])), path), count


def _stage(problem: Problem, inequalities: Inequalities, path: Path, rho: float,
           options: SolveOptions):
    """(minimiser, Newton iterations, status, the stage's problem) of
    S + ρh/2 Σ max(0, c)² from ``path`` (``options.ftol`` unused)."""
    stage = PenalisedProblem(problem, inequalities, rho * problem.h)
    start = path.copy()
    start.lam[:, problem.model.constraints:] = 0.0      # the penalty stands for z·c
    moved, _, steps, status, _ = newton(stage, start, options.replace(ftol=0.0),
                                        f"penalty stage ρ = {rho:.0e} h")
    return moved, len(steps), status, stage


def _settled(stage: PenalisedProblem, path: Path) -> bool:
    """Whether the Newton correction of the node corrections at ``path`` is within
    :data:`SETTLED` of the nodes' scale: the equality solver's own rule measures it against
    the largest unknown, and the multipliers of a penalised problem grow with ρ (a
    perturbed start of the cart-pole swing-up at N = 1000 "solved" the stage ρ = 10⁸ h
    with a correction of 4.0, its violation unmoved since 10⁴ h: a false certificate)."""
    res, ab, bw, finite = stage.assemble(path, True)
    if not finite:
        return False
    delta = stage.solve(ab, bw, -res)
    nodes = ~stage.constraint_rows(path)
    scale = 1.0 + float(np.abs(path.x).max(initial=0.0))
    return bool(np.abs(delta[nodes]).max(initial=0.0) <= SETTLED * scale)


def _violation(inequalities: Inequalities, problem: Problem, path: Path) -> float:
    """The largest violation max(0, c) at ``path`` (its values left in ``inequalities``)."""
    if not inequalities.evaluate(path, problem.p, problem.h):
        return np.inf
    return float(np.maximum(inequalities.values, 0.0).max(initial=0.0))


def _floor(inequalities: Inequalities) -> float:
    """A violation below this is rounding of c, not evidence: 10⁶ ε of c's scale."""
    return 1e6 * np.finfo(float).eps * (1.0 + float(np.abs(inequalities.values).max(initial=0.0)))
