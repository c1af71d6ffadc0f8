"""Whole-trajectory solve: Newton on all free nodes at once (DESIGN.md §4).

The public solve and its fixed-horizon phase: the options checked once
(:class:`.options.SolveOptions`) and passed whole to the phases — the Newton iteration
(:mod:`.newton`), the bounded solve (:mod:`.bounded`), the free horizon (:mod:`.horizon`)
— and what the fixed-horizon solve concludes. The unknowns are corrections η_j of the free
nodes, applied as the node variation g → g·τ(η) (pair groupoid: q_j += η_j; matrix
groups: g_j ← g_j τ(η_j), which keeps the product of the increments equal to g_0⁻¹g_N),
and, with constraints, the multipliers λ^k of every window (paper §3.2, eq.
``constrainedso``). Beside it: :mod:`.assembly` (the banded system, its solves and
updates), :mod:`.lifted` (the same corrections from a system with κ ∝ N² instead of N⁴,
and its inertia), :mod:`.globalisation` (descent, natural and backtracking steps) and
:mod:`.optimality` (the second-order test and the inertia correction).
"""
from __future__ import annotations

from dataclasses import replace
from typing import Callable, Mapping

import numpy as np

from ..core import arguments
from . import boundary_states, guesses, sequence
from .assembly import Problem
from .bordered import HorizonProblem
from .band import cholesky_pivot
from .gauge import check_boundary
from .horizon import free_horizon
from .diagnosis import diagnose
from ..core.model_info import Kernel
from .newton import newton
from .optimality import second_order
from ..core.options import SolveOptions
from ..core.paths import Path, Resampled, initial_path
from ..core.progress import ProgressLine
from ..core.results import BVPResult, Status
from ..core.storage import check_path_memory as check_memory


def solve_steps(model, n_steps: int, from_states: bool) -> int:
    """N of a whole-trajectory solve of ``model``, checked: the model must have such a
    solve (and take States as boundary data where they are given), and N leaves a free
    node between the fixed ends."""
    info = model.info
    if not info.whole_trajectory:
        raise ValueError(f"model {model.name!r}: no whole-trajectory solve on kind "
                         f"{info.kind!r}")
    if from_states:
        boundary_states.check_supported(model)
    r = model.order
    return arguments.count(n_steps, "n_steps", 2 * r - from_states, why=(
        " (States fix the first and last elements, and one free node lies between them)"
        if from_states else
        f" ({r} fixed node{'s' if r > 1 else ''} at each end of an order-{r} problem and at "
        f"least one free node between them)"))


def solve_bvp(model, start, end, n_steps: int, h: float | None = None,
              params: Mapping[str, float] | None = None, *, T: float | None = None,
              guess: str | np.ndarray | tuple | BVPResult | Callable | None = None,
              maxiter: int = SolveOptions.unset("maxiter"),
              xtol: float = SolveOptions.unset("xtol"),
              ftol: float = SolveOptions.unset("ftol"), options: SolveOptions | None = None,
              raise_on_failure: bool = False, progress: bool | None = None,
              **keywords) -> BVPResult:
    """Solve for the free nodes (and multipliers) with the first and last r nodes fixed
    (or, with end conditions, only the first).

    Parameters
    ----------
    start, end : :class:`State` s at t = 0 and t = T (second-order problems on any
        groupoid): ``State(x=q, v=q̇)``, ``State(g=g, v=ξ)``, ``State(x=q, g=g, v=…)``. Each
        fixes the element whose midpoint it is; the states are then on the grid t_k = k·h,
        k = 0 … N, the nodes at the half steps, and the cost and path converge at order 2
        on [0, T] (:mod:`.boundary_states`); ``res.states`` holds the solved ones.
        Or the fixed nodes 0 … r−1 and N−r+1 … N (r the order). Pair groupoid:
        (r, n) arrays of nodes q. Matrix Lie group: (r, d, d) configurations. Groupoids
        with both (action groupoids, products): ``(x, g)``, base points (r, m) and
        configurations (r, d, d) — a tuple of such arrays with several group factors.
        On an action groupoid the base points must follow the configurations. With end
        conditions (``optimal_control(..., end="free" or ψ)``) the last r nodes are
        unknowns and ``end`` their first guess, or None: a previous result's ``guess``
        last nodes, else the start's last node held; ``res.end_multipliers`` holds ν.
    n_steps : N, the number of elements: N + 1 nodes t_k = k·h, k = 0 … N, on [0, T]
        (from States: N + 1 states t_k = k·h on [0, T], N + 1 elements, N + 2 nodes).
    h, T : the step h, or the horizon T = N·h (keyword; give one of them). With a free
        horizon (``optimal_control(..., time_cost=ρ)``) the first guess of it, the
        result's ``T`` the optimal horizon: an unknown of the same Newton system
        (:mod:`.bordered`), with States as boundary data converging at order 2; where
        that fails with inequalities, an outer iteration of fixed-horizon solves
        (:mod:`.horizon`) is tried from the start.
    params : parameter overrides (mapping name → value); the others keep the defaults
        compiled in (``INFO.defaults``).
    guess : the free nodes r … N−r in the same layout (from States: nodes 2 … N − 1 of the
        N + 2, N − 2 of them), or how to interpolate them between
        the fixed ends: ``"cubic"`` (default) matches the end velocities as well as the
        positions (in τ-coordinates at g_{r−1} on groups, the base points moved along;
        the chord when r = 1, as there are no end velocities), and
        ``"chord"`` the positions only: g_{r−1} τ(s·τ⁻¹(g_{r−1}⁻¹ g_{N−r+1})).
        Multipliers start at zero. With no guess of its own (None, ``"cubic"``,
        ``"chord"``) a solve of many steps (by default N ≥ 2000) starts from the
        solution at a few (250) resampled, with its multipliers and active set, where
        the boundary data carry to that step (mesh sequencing, :mod:`.sequence`; the
        result counts both solves' iterations). Or a previous :class:`BVPResult` with the same
        number of steps (a warm start: other boundary data, other parameters, a
        continuation): its free nodes, its multipliers, and its fibres where both nodes
        are unchanged; with bounds also its bound multipliers and active set, from which
        the active-set Newton is tried before the interior point (:mod:`.polish`).
        A previous result at another number of steps is resampled on the groupoid to
        this one's, with its multipliers and active set (:mod:`.guesses`); a function
        ``guess(t)`` returning a :class:`State` gives the free nodes' positions (x, g) at
        their times — on every groupoid, without building its node layout.
    options, keywords : a :class:`.options.SolveOptions` (or a mapping of its fields),
        or its fields as keywords (``maxiter=``, ``xtol=``, ``ftol=``, ``verbose=``, …;
        an options object and a keyword for one field are refused together): it goes whole to every phase of the solve. A name that is not an
        option is refused by name with the list of the valid ones. The main ones:
    maxiter, xtol, ftol : SUCCESS when the full Newton correction ‖Δ‖∞ — the estimate
        of the error left in the path (unknowns: node corrections and multipliers) —
        plus the rounding floor below is at most xtol·(1 + size), size the largest
        unknown (:func:`.newton._within_tolerance`), or when ‖R‖∞ ≤ ftol. The floor counts
        twice (a sample of the rounding noise can miss its worst direction), and
        corrections shrinking only linearly, by ρ > ½ per iteration, count as the error
        ρ/(1 − ρ)·‖Δ‖ they leave.
        Where the residual reaches its rounding level first, its norm is noise: the
        full step is taken if it passes Deuflhard's natural monotonicity test, else
        the cost's descent step is tried; a path whose correction still exceeds the
        tolerance there is ``ILL_CONDITIONED``, never SUCCESS, and the message gives
        the correction as the attainable accuracy. The Newton matrix of a second-order
        problem on its nodes has κ ∝ N⁴, which exhausts double precision near N = 10⁵;
        second-order models (with or without constraints, on pair, matrix-group and
        action factors) solve for the same corrections with the lifted system from
        N = 2000 on (κ ∝ N², :mod:`.lifted`): cubic_spline within 3e-12 of the exact
        cubic at N = 10⁵, where the node formulation reached 4e-5. The rounding
        floor is the correction that undoes rounding the path's unknowns by one unit in
        the last place (:meth:`.assembly.Problem.rounding_correction`): a small
        correction can be luck where that floor is larger. The default of 100
        iterations (SLSQP's) leaves room for constrained problems started far from
        feasibility: the non-planar heavy top from the chord guess takes 52–73.
        Optimal-control problems are globalised on their cost (with constraints: its
        ℓ1 exact penalty S + ν‖Φ_d‖₁) with a shifted Hessian and Armijo backtracking,
        other problems and the last steps by backtracking on ‖R‖₂. With inequalities
        (bounded controls) the solve is a primal–dual interior-point Newton
        (:mod:`.interior`, whose docstring states its SUCCESS rule); ``ftol`` is unused.
    raise_on_failure : raise :class:`NewtonError` (carrying the failed result and its
        iteration history) instead of returning a failed result.
    progress : a line on stderr naming the phase, the iteration and its correction, shown
        once the solve has run a few seconds (:mod:`..core.progress`) and erased at its
        end: True, False, or None (the default) for one when stderr is a terminal and
        ``verbose`` is off (its rows say as much). The batch calls show a bar instead.
    """
    from_states = boundary_states.given(start, end)
    N = solve_steps(model, n_steps, from_states)
    h, p = arguments.step_of(h, T, N), model.params(params)
    options = SolveOptions.of(options, dict(maxiter=maxiter, xtol=xtol, ftol=ftol) | keywords,
                              "solve_bvp")
    check_memory(model, N + from_states)
    with ProgressLine(f"solve_bvp {model.name}", progress):
        result = _sequenced(model, start, end, N, h, p, guess, options, from_states) \
            if sequence.applies(model, N, guess, options) else None
        if result is None:
            result = _solve(model, start, end, N, h, p, guess, options, from_states)
    result = replace(result, labels=model.labels)
    return result.raise_for_status() if raise_on_failure else result


def _sequenced(model, start, end, N: int, h: float, p, guess, options: SolveOptions,
               from_states: bool) -> BVPResult | None:
    """:func:`.sequence.sequenced` with :func:`_solve` as each of its solves."""
    def solve(start, end, steps, step, guess, options):
        return _solve(model, start, end, steps, step, p, guess, options, from_states)
    return sequence.sequenced(solve, model, start, end, N, h, p, guess, options,
                              from_states)


def _solve(model, start, end, N: int, h: float, p, guess, options: SolveOptions,
           from_states: bool) -> BVPResult:
    """:func:`solve_bvp` once its arguments are checked: from States, with a free
    horizon, or at the step h."""
    info = model.info
    guess = guesses.converted(model, guess, N + from_states, h, p, from_states)
    if from_states:
        nodes = (boundary_states.element_nodes(model, start, h, p, "start"),
                 boundary_states.element_nodes(model, end, h, p, "end"))
        result = fixed_horizon(model, *nodes, N + 1, h, p, guess, options, (start, end))
        solved = info.free_horizon and len(result.t)    # the horizon found, h = T/N
        result = boundary_states.attach(model, result, result.T / (N + 1) if solved else h, p)
    elif info.free_horizon:
        result = free_horizon(
            lambda: fixed_horizon(model, start, end, N, h, p, guess, options),
            lambda step, previous: fixed_horizon(model, start, end, N, step, p, (
                guess if previous is None else previous), options, horizon=False),
            model, p, N, h, options)
    else:
        result = fixed_horizon(model, start, end, N, h, p, guess, options)
    return result


def fixed_horizon(model, start, end, N: int, h: float, p, guess,
                  options: SolveOptions, states=None, horizon: bool = True) -> BVPResult:
    """The whole-trajectory solve at the step h under ``options``: see :func:`solve_bvp`
    (with inequalities, :func:`.bounded.bounded`). A free horizon without inequalities
    is an unknown of the same Newton system, h its first guess (:mod:`.bordered`);
    ``states``, the (start, end) States whose elements ``start`` and ``end`` are;
    ``horizon=False``: a free horizon's model solved at the step h (:mod:`.horizon`)."""
    path = initial_path(model, start, end, N, guess, p, h)
    if isinstance(path, BVPResult):
        return path
    if model.info.free_horizon and horizon:
        steps = N - (states is not None)         # h = T/N of the States' grid
        path = replace(path, T=steps * h)
        problem = HorizonProblem(model, p, steps, states)
    else:
        problem = Problem(model, p, h)
    if model.inequalities:
        # bvp/'s one import of bounded/, made only for a model with inequalities:
        # bounded/ builds on bvp/, and a model without bounds never loads it.
        from ..bounded.barrier import check_boundary_data, check_intervals
        from ..bounded.bounded import bounded, bounded_horizon
        check_intervals(model, path, p, h)
        check_boundary_data(model, path, p, h)
        # a previous result that failed is a guess of nodes only (core.paths.initial_path);
        # a solution at another N resampled is a warm start where it carries its active set
        cold = not ((isinstance(guess, BVPResult) and guess.success)
                    or (isinstance(guess, Resampled) and guess.active is not None))
        active = None if cold or guess.active is None \
            or guess.active.shape != path.lam[:, model.constraints:].shape else guess.active
        solve = bounded_horizon if path.T is not None else bounded
        return solve(problem, path, options, cold, active)
    if model.info.gauges:
        check_boundary(model, path, problem.perturbed(path), p, h)
    path, norms, steps, status, message = newton(problem, path, options)
    if path.T is not None:
        h = path.T / problem.N
        message += f"; free horizon T = {path.T:.12g}"
    if status == Status.SUCCESS and problem.minimise:
        status, message = _minimum(problem, path, message)
    if status == Status.SUCCESS:
        # the residual's terms are of size level / 16ε: at N = 10⁵ a residual of 1e2 is
        # rounding in terms of 1e16
        terms = problem.level / (16 * np.finfo(float).eps) if problem.level else 0.0
        context = f", {norms[-1] / terms:.0e} of its terms" if terms and norms[-1] > 1.0 else ""
        message = (f"converged in {len(steps)} Newton iterations, residual norm "
                   f"{norms[-1]:.3e}{context}{message}")
    else:
        message += f"; residual norm {norms[-1]:.3e}" + _why(problem, path, status)
    result = _result(model, path, p, h, dict(
        t=h * np.arange(N + 1), iterations=len(steps), residual_norms=np.array(norms),
        step_norms=np.array(steps), status=status, message=message,
        history=problem.log.history()))
    return _finite(result)


def _minimum(problem: Problem, path: Path, message: str) -> tuple[Status, str]:
    """An optimal-control solve is a SUCCESS only at a minimum: the second-order test
    (:func:`.optimality.second_order`) on the converged path, else SADDLE."""
    _, ab, bw, finite = problem.assembled(path)
    if finite and problem.lifted_system is not None:
        minimum, excess = problem.lifted_system.minimum()
        if minimum and problem.curvature_beyond_band(ab, bw) > 0:
            return Status.SUCCESS, message
        pivot = (f" ({excess} negative eigenvalues, from the lifted system's inertia)"
                 if excess > 0 else " (a vanishing pivot in the lifted system's inertia: "
                 "the Hessian is singular to working precision)")
    else:
        verdict = second_order(ab, bw, problem.constraint_rows(path)[:ab.shape[1]],
                               lambda: cholesky_pivot(problem.model, ab, bw)) if finite else None
        if verdict is not None and verdict.minimum \
                and problem.curvature_beyond_band(ab, bw) > 0:
            return Status.SUCCESS, message
        pivot = "" if verdict is None else (
            f" (Cholesky pivot {verdict.pivot:.1e} of W + ρAᵀA at ρ = {verdict.rho:.1e})")
    return Status.SADDLE, (
        f"converged to a stationary point of the cost{message}, but not to a verified "
        f"minimum: the Hessian of the Lagrangian is not positive definite on the "
        f"constraints' tangent space{pivot} — a saddle or maximum; start from another guess")


def _finite(result: BVPResult) -> BVPResult:
    """A converged solve whose outputs are not all finite is NON_FINITE, not a success."""
    if not result.success:
        return result
    outputs = {"x": "nodes are", "g": "configurations are", "f": "fibres are",
               "multipliers": "multipliers are", "controls": "controls are", "cost": "cost is"}
    for name, what in outputs.items():
        values = getattr(result, name)
        parts = values if isinstance(values, tuple) else (values,)
        if values is not None and not all(np.isfinite(v).all() for v in parts):
            return replace(result, status=Status.NON_FINITE, message=(
                f"{result.message}, but its {what} not finite (magnitudes overflow double "
                f"precision)"))
    return result


#: Below this many steps a Newton matrix singular to working precision is not the
#: conditioning's growth with N (heavy_top_rotors_oc_variational at N = 4: 1/κ = 0).
FEW_STEPS = 50


def _why(problem: Problem, path: Path, status: Status) -> str:
    """Why Newton failed, for its message: the constraints (:mod:`.diagnosis`: dependent,
    or not to be met), else double precision (:func:`_conditioning`)."""
    if status in (Status.SINGULAR_JACOBIAN, Status.STALLED, Status.MAX_ITERATIONS):
        found = diagnose(problem, path)
        if found is not None:
            return found.describe(path.x.shape[0] - 1, problem.h)
    return _conditioning(problem, path, status)


def _conditioning(problem: Problem, path: Path, status: Status) -> str:
    """Why Newton failed, when the reason is double precision itself: the Newton matrix
    at the returned path is singular to working precision (1/κ < ε). Its conditioning
    grows like N^{2r} (differences of order 2r), so a large N can exhaust it — then
    rounding may dominate the solves and no globalisation helps."""
    if status not in (Status.MAX_ITERATIONS, Status.STALLED):
        return ""
    _, ab, bw, finite = problem.assembled(path)
    rcond = problem.reciprocal_condition(ab, bw) if finite else np.inf
    if rcond >= np.finfo(float).eps:
        return ""
    growth = 2 if problem.lifted_system is not None else 2 * problem.model.order
    text = (f"; the Newton matrix is singular to working precision (reciprocal condition "
            f"number {rcond:.1e} < ε), so rounding may dominate its solves")
    if path.x.shape[0] - 1 < FEW_STEPS:     # not the growth with N: a degenerate problem
        return text + " — with so few steps the discrete problem is degenerate; use more"
    return text + f": its conditioning grows like N^{growth} — use fewer steps"


def _result(model, path: Path, p, h, common: dict) -> BVPResult:
    r = model.order
    windows = path.f.shape[0] - r + 1
    cost = float(model.along_vector(Kernel.LAGRANGIAN, path.x, path.f, h, p).sum())
    controls = (model.along_vector(Kernel.CONTROLS, path.x, path.f, h, p)
                if model.info.controls else None)
    return BVPResult(x=path.x if model.m else None, f=path.f,
                     g=model.configurations(path.g) if model.matrix_dims else None,
                     multipliers=path.lam if model.constraints else None,
                     end_multipliers=path.nu[:model.end_count].copy()
                     if model.end_count else None,
                     controls=controls, cost=cost if windows > 0 else 0.0,
                     kind=model.info.kind, **common)
