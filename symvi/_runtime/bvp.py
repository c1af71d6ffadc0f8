"""Whole-trajectory solve: Newton on all free nodes at once (DESIGN.md §4).

The residual at node j involves nodes j−r … j+r, so the Jacobian is block-banded; C
assembles it in LAPACK's band storage and ``dgbsv`` factorises it, so one iteration costs
O(N). The unknowns are corrections η_j of the free nodes, applied as the
node variation g → g·τ(η) (pair groupoid: q_j += η_j; matrix groups: g_j ← g_j τ(η_j),
which keeps the product of the increments equal to g_0⁻¹g_N), and, with constraints, the
multipliers λ^k of every window (paper §3.2, eq. ``constrainedso``).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from . import arguments
from .gauge import Gauge, check_boundary
from .paths import Path, initial_path
from .results import BVPResult, Status
from .storage import check_path_memory as check_memory


class _Problem:
    """Newton's view of a path: residuals, banded Jacobian and updates, all in C.

    An update composes each group fibre exactly, τ(hξ') = τ(−η_k) τ(hξ) τ(η_{k+1}), in
    increment-minus-identity arithmetic: recomputing ξ from the configurations instead
    would round it to ε/h, which the fourth-order structure of a second-order residual
    amplifies into O(1) errors of the slowest modes at N = 10⁵.
    """

    def __init__(self, model, p, h):
        self.model, self.p, self.h = model, p, h
        #: An optimal-control problem minimises its cost: Newton steps are then globalised
        #: on the cost itself, or with constraints on its ℓ1 exact penalty (see
        #: :func:`_descent_step`).
        self.minimise = bool(model.info.get("controls"))
        self.shift, self.penalty = 0.0, 0.0
        self._band = self._work = None   # reused: fresh pages are slow to touch at large N
        self.gauge = None

    def merit(self, path: Path) -> tuple[float, float]:
        """The cost S = Σ L_d and the size of its rounding error."""
        terms = self.model.along_vector("lagrangian", path.x, path.f, self.h, self.p)
        return float(terms.sum()), float(np.abs(terms).sum()) * 64 * np.finfo(float).eps

    def assemble(self, path: Path, with_jacobian: bool):
        m, n_nodes = self.model, path.x.shape[0]
        unknown = int(m.lib.symvi_bvp_unknowns(n_nodes))
        bw = int(m.lib.symvi_bvp_bandwidth())
        res, ab = np.zeros(unknown), None
        if with_jacobian:
            if self._band is None or self._band.shape != (3 * bw + 1, unknown):
                self._band = np.zeros((3 * bw + 1, unknown), order="F")
                self._work = np.zeros_like(self._band, order="F")
            ab = self._band
        code = m.lib.symvi_bvp_assemble(m.ptr(path.x), m.ptr(path.f), m.ptr(path.lam), n_nodes,
                                        m.ptr(self.p), self.h, m.ptr(res),
                                        m.ptr(ab.T) if with_jacobian else m.ffi.NULL)
        if with_jacobian and m.info.get("gauges"):
            if self.gauge is None:
                self.gauge = Gauge(m, n_nodes)
            self.gauge.update(path, self.p, self.h)
        return res, ab, bw, code == 0

    def solve(self, ab, bw: int, rhs: np.ndarray, shift: float = 0.0,
              shifted: np.ndarray | None = None) -> np.ndarray:
        """Solve (J + shift·D) x = rhs with LAPACK's banded LU (dgbsv), J in the band
        storage of :meth:`assemble` (left intact: the work copy is factorised), D the
        identity on the unknowns ``shifted`` (a mask; default all). Exactly dependent
        constraints are replaced by their gauge condition (:mod:`.gauge`)."""
        from scipy.linalg import LinAlgError
        from scipy.linalg.lapack import dgbsv

        rhs = self._newton_matrix(ab, bw, rhs, shift, shifted)
        _, _, x, info = dgbsv(bw, bw, self._work, rhs, overwrite_ab=True)
        if info != 0:
            raise LinAlgError(f"dgbsv: singular at column {info}" if info > 0 else "dgbsv")
        return x

    def reciprocal_condition(self, ab, bw: int) -> float:
        """LAPACK's estimate (dgbcon, 1-norm) of 1/κ of the Newton matrix of :meth:`solve`
        without shift: below ε rounding may dominate its solves."""
        from scipy.linalg.lapack import dgbcon, dgbtrf

        self._newton_matrix(ab, bw, np.zeros(self._work.shape[1]))
        norm = float(np.abs(self._work[bw:]).sum(axis=0).max(initial=0.0))
        lu, pivots, info = dgbtrf(self._work, bw, bw, overwrite_ab=True)
        return 0.0 if info != 0 else float(dgbcon(bw, bw, lu, pivots, norm)[0])

    def _newton_matrix(self, ab, bw: int, rhs: np.ndarray, shift: float = 0.0,
                       shifted: np.ndarray | None = None) -> np.ndarray:
        """Fill the work band with the matrix :meth:`solve` factorises (J, its shift, the
        gauge rows); returns the matching right-hand side."""
        np.copyto(self._work, ab)
        if shift:
            self._work[2 * bw] += shift if shifted is None else shift * shifted
        return rhs if self.gauge is None else self.gauge.apply(self._work, bw, rhs)

    def moved(self, path: Path, delta, alpha):
        m, trial = self.model, path.copy()
        failed = m.ffi.new("long *")
        code = m.lib.symvi_bvp_update(m.ptr(trial.x), m.ptr(trial.g), m.ptr(trial.f),
                                      m.ptr(trial.lam), m.ptr(delta), alpha, path.x.shape[0],
                                      m.ptr(self.p), self.h, failed)
        return trial if code == 0 else None

    def perturbed(self, path: Path) -> Path:
        """``path`` with every free node moved by a fixed pseudo-random variation of size
        1e-2 (its ends kept): a second path between the same ends."""
        r, blocks = self.model.order, self._blocks(path)
        delta = 1e-2 * np.random.default_rng(0).uniform(-1.0, 1.0, (len(blocks), self.model.n
                                                                     + self.model.constraints))
        delta[(blocks < r) | (blocks > path.x.shape[0] - 1 - r)] = 0.0
        moved = self.moved(path, delta.reshape(-1), 1.0)
        if moved is None:
            raise ValueError("cannot vary the initial path to check the declared symmetries")
        return moved

    def size(self, path: Path) -> float:
        """Scale of the unknowns for the relative step tolerance."""
        floor = 1.0 if self.model.matrix_dims else 0.0
        return max(floor, float(np.abs(path.x).max(initial=0.0)),
                   float(np.abs(path.lam).max(initial=0.0)))

    def _blocks(self, path: Path) -> np.ndarray:
        """The nodes of the C assembler's blocks: each holds a node correction η_t (n
        unknowns, its residual rows) and, with constraints, the multipliers of window
        t − 1 (s unknowns, the rows of its constraints Φ_d)."""
        r, s = self.model.order, self.model.constraints
        t0 = r - 1 if s else r
        return np.arange(t0, path.x.shape[0] - t0)

    def constraint_rows(self, path: Path) -> np.ndarray:
        """Mask of the multiplier unknowns (= constraint rows) in the block layout."""
        n, s = self.model.n, self.model.constraints
        return np.tile(np.r_[np.zeros(n, bool), np.ones(s, bool)], len(self._blocks(path)))

    def multipliers(self, path: Path) -> np.ndarray:
        """The multipliers λ in the block layout (their rows of :meth:`constraint_rows`)."""
        if not self.model.constraints:
            return np.zeros(0)
        return path.lam[self._blocks(path) - 1].reshape(-1)

    def magnitudes(self, path: Path) -> np.ndarray:
        """Magnitude of every unknown, in the block layout of the C assembler: a node
        correction is as precise as the fibres meeting there (a group fibre is held as
        its increment hξ, a pair fibre is the node itself), a multiplier as itself."""
        m, s = self.model, self.model.constraints
        blocks = self._blocks(path)
        scaled = np.array(m.info.get("step_scaled") or [False] * m.n, dtype=bool)
        before = np.abs(path.f[np.maximum(blocks - 1, 0)])
        after = np.abs(path.f[np.minimum(blocks, path.f.shape[0] - 1)])
        eta = np.where(scaled, self.h * np.maximum(before, after), before)
        lam = np.abs(path.lam[blocks - 1]) if s else np.zeros((len(blocks), 0))
        return np.concatenate([eta, lam], axis=1).reshape(-1)


def solve_bvp(model, start, end, n_steps: int, h: float, params=None, *, guess=None,
              maxiter: int = 100, xtol: float = 1e-9, ftol: float = 0.0,
              raise_on_failure: bool = False) -> BVPResult:
    """Solve for the free nodes (and multipliers) with the first and last r nodes fixed.

    Parameters
    ----------
    start, end : the fixed nodes 0 … r−1 and N−r+1 … N (r the order). Pair groupoid:
        (r, n) arrays of nodes q. Matrix Lie group: (r, d, d) configurations. Groupoids
        with both (action groupoids, products): ``(x, g)``, base points (r, m) and
        configurations (r, d, d) — a tuple of such arrays with several group factors.
        On an action groupoid the base points must follow the configurations.
    n_steps : N, the number of elements (N + 1 nodes).
    guess : the free nodes r … N−r in the same layout, or how to interpolate them between
        the fixed ends: ``"cubic"`` (default) matches the end velocities as well as the
        positions (in τ-coordinates at g_{r−1} on groups, the base points moved along;
        the chord when r = 1, as there are no end velocities), and
        ``"chord"`` the positions only: g_{r−1} τ(s·τ⁻¹(g_{r−1}⁻¹ g_{N−r+1})).
        Multipliers start at zero.
    maxiter, xtol, ftol : SUCCESS when the full Newton correction ‖Δ‖∞ — the estimate
        of the error left in the path (unknowns: node corrections and multipliers) —
        is at most xtol·(1 + size) in two iterations in a row (at the rounding level
        one correction can be small by cancellation), size the largest unknown, or
        when ‖R‖∞ ≤ ftol.
        Where the residual reaches its rounding level first, its norm is noise: the
        full step is taken if it passes Deuflhard's natural monotonicity test, else
        the cost's descent step is tried; a path whose correction still exceeds the
        tolerance there is ``ILL_CONDITIONED``, never SUCCESS, and the message gives
        the correction as the attainable accuracy (the Newton matrix of a second-order
        problem has κ ∝ N⁴; cubic_spline: about 1e-10 at N = 10³, 1e-7 at 10⁴, 1e-4
        at 10⁵, each within a factor 2–4 of the true error). The default of 100
        iterations (SLSQP's) leaves room for constrained problems started far from
        feasibility: the non-planar heavy top from the chord guess takes 52–73.
        Optimal-control problems are globalised on their cost (with constraints: its
        ℓ1 exact penalty S + ν‖Φ_d‖₁) with a shifted Hessian and Armijo backtracking,
        other problems and the last steps by backtracking on ‖R‖₂.
    raise_on_failure : raise :class:`NewtonError` (carrying the failed result and its
        iteration history) instead of returning a failed result.
    """
    info = model.info
    if not info["whole_trajectory"]:
        raise ValueError(f"model {model.name!r}: no whole-trajectory solve on kind "
                         f"{info['kind']!r}")
    r = model.order
    N = arguments.count(n_steps, "n_steps", 2 * r, why=(
        f" ({r} fixed node{'s' if r > 1 else ''} at each end of an order-{r} problem and at "
        f"least one free node between them)"))
    h, p = arguments.step_size(h), model.params(params)
    xtol, ftol = arguments.tolerance(xtol, "xtol"), arguments.tolerance(ftol, "ftol")
    maxiter = arguments.iterations(maxiter)
    check_memory(model, N)
    path = initial_path(model, start, end, N, guess, p, h)
    if isinstance(path, BVPResult):
        return path.raise_for_status() if raise_on_failure else path
    problem = _Problem(model, p, h)
    if info.get("gauges"):
        check_boundary(model, path, problem.perturbed(path), p, h)
    path, norms, steps, status, message = _newton(problem, path, maxiter, xtol, ftol)
    if status == Status.SUCCESS:
        message = (f"converged in {len(steps)} Newton iterations, residual norm "
                   f"{norms[-1]:.3e}{message}")
    else:
        message += f"; residual norm {norms[-1]:.3e}" + _conditioning(problem, path, status)
    result = _result(model, path, p, h, dict(
        t=h * np.arange(N + 1), iterations=len(steps), residual_norms=np.array(norms),
        step_norms=np.array(steps), status=status, message=message))
    result = _finite(result)
    return result.raise_for_status() if raise_on_failure else result


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


def _conditioning(problem: _Problem, path: Path, status: Status) -> str:
    """Why Newton failed, when the reason is double precision itself: the Newton matrix
    at the returned path is singular to working precision (1/κ < ε). Its conditioning
    grows like N^{2r} (differences of order 2r), so a large N can exhaust it — then
    rounding may dominate the solves and no globalisation helps."""
    if status not in (Status.MAX_ITERATIONS, Status.STALLED):
        return ""
    _, ab, bw, finite = problem.assemble(path, True)
    rcond = problem.reciprocal_condition(ab, bw) if finite else np.inf
    if rcond >= np.finfo(float).eps:
        return ""
    r = problem.model.order
    return (f"; the Newton matrix is singular to working precision (reciprocal condition "
            f"number {rcond:.1e} < ε), so rounding may dominate its solves: its "
            f"conditioning grows like N^{2 * r} — use fewer steps")


def _result(model, path: Path, p, h, common: dict) -> BVPResult:
    r = model.order
    windows = path.f.shape[0] - r + 1
    cost = float(model.along_vector("lagrangian", path.x, path.f, h, p).sum())
    controls = (model.along_vector("controls", path.x, path.f, h, p)
                if model.info["controls"] else None)
    return BVPResult(x=path.x if model.m else None, f=path.f,
                     g=model.configurations(path.g) if model.matrix_dims else None,
                     multipliers=path.lam if model.constraints else None,
                     controls=controls, cost=cost if windows > 0 else 0.0,
                     kind=model.info["kind"], **common)


def _newton(problem, state, maxiter: int, xtol: float, ftol: float):
    """Damped Newton; returns (state, residual norms, step norms, status, message)."""
    from scipy.linalg import LinAlgError

    norms, steps, corrections = [], [], [np.inf]
    for it in range(maxiter):
        try:
            state, taken, status, message = _iteration(problem, state, it, xtol, ftol, norms,
                                                       corrections)
        except LinAlgError as exc:
            # a shifted or gauged Newton matrix that LAPACK could not factorise
            return state, norms, steps, Status.SINGULAR_JACOBIAN, (
                f"singular Newton matrix at iteration {it} (LAPACK: {exc})")
        if taken is not None:
            steps.append(taken)
        if status is not None:
            if status is Status.SUCCESS and taken is not None:
                # the residual of the path returned, after the last update
                norms.append(_residual_norm(problem, state))
            return state, norms, steps, status, message
    norms.append(_residual_norm(problem, state))
    return (state, norms, steps, Status.MAX_ITERATIONS,
            f"Newton's method did not converge in {maxiter} iterations")


def _residual_norm(problem, state) -> float:
    return float(np.abs(problem.assemble(state, False)[0]).max(initial=0.0))


def _iteration(problem, state, it: int, xtol: float, ftol: float, norms: list,
               corrections: list):
    """One damped Newton iteration from ``state`` (its residual norm appended to
    ``norms``, its full Newton correction to ``corrections``): (state, step taken or
    None, final status or None, message)."""
    from scipy.linalg import LinAlgError

    res, ab, bw, finite = problem.assemble(state, True)
    norms.append(float(np.abs(res).max(initial=0.0)))
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
    # step may be short far from the solution), and on two in a row: at the rounding
    # level one correction can be small by cancellation, the error e and the rounding
    # noise J⁻¹n in it nearly opposite, while the next path's error is J⁻¹n.
    size = float(np.abs(delta).max(initial=0.0))
    tolerance = xtol * (1.0 + problem.size(state))
    corrections.append(size)
    level = _rounding_level(ab[bw:], bw, problem.magnitudes(state))
    if size <= tolerance:
        moved = problem.moved(state, delta, 1.0)    # round-off defeats a line search
        if moved is not None and corrections[-2] <= tolerance:
            return moved, size, Status.SUCCESS, (
                f"; last Newton corrections {corrections[-2]:.1e}, {size:.1e}")
        if moved is not None:
            return moved, size, None, ""
        return state, None, Status.STALLED, (
            f"the full Newton step leaves the retraction's chart at iteration {it}")
    else:
        taken = None
        if norms[-1] <= level:
            state, taken = _natural_step(problem, state, delta, ab, bw, size)
        if taken is None and problem.minimise:
            state, taken = _descent_step(problem, state, res, ab, bw, delta)
        if taken is None and norms[-1] > level:
            state, taken = _line_search(problem, state, delta, res)
    if taken is None:
        if norms[-1] <= level:  # no descent left below the rounding level
            return state, None, *_rounding_limited(norms[-1], level, size, tolerance)
        return state, None, Status.STALLED, f"line search stalled at iteration {it}"
    return state, taken, None, ""


def _rounding_limited(norm: float, level: float, size: float, tolerance: float):
    """Status and message when the residual is at its rounding level but the Newton
    correction there — the estimate of the error left in the path — exceeds the
    tolerance: never SUCCESS (issue 20). The correction is rounding noise amplified by
    the conditioning of the Newton matrix, so its size is the attainable accuracy."""
    return Status.ILL_CONDITIONED, (
        f"the residual ({norm:.1e}) is at its rounding level ({level:.1e}), where the "
        f"Newton correction, the estimated error of the path, is {size:.1e} > the "
        f"tolerance xtol·(1 + size) = {tolerance:.1e}: rounding amplified by the Newton "
        f"matrix's conditioning limits the attainable accuracy to about {size:.0e}; "
        f"accept it with a larger xtol, or use fewer steps")


def _rounding_level(ab: np.ndarray, bw: int, u: np.ndarray) -> float:
    """Attainable residual: 16 ε ‖ |J| u ‖∞, u the unknowns' magnitudes (first order);
    ``ab`` holds J's 2 bw + 1 diagonals, ab[bw + row − col, col] = J[row, col].

    When the line search finds no descent from a residual below it, Newton has converged
    as far as floating point allows, even if its update, amplified by the condition
    number (∝ N⁴ for fourth differences), still exceeds xtol.
    """
    scale = _band_product(np.abs(ab), bw, u)
    return 16 * np.finfo(float).eps * float(scale.max(initial=0.0))


def _band_product(ab: np.ndarray, bw: int, u: np.ndarray) -> np.ndarray:
    """J u, J given by its 2 bw + 1 diagonals, ab[bw + row − col, col] = J[row, col]."""
    out = np.zeros_like(u)
    for d in range(2 * bw + 1):
        offset = d - bw  # row = column + offset
        if abs(offset) >= u.size:       # a band wider than the matrix (few unknowns)
            continue
        if offset >= 0:
            out[offset:] += ab[d, : u.size - offset] * u[: u.size - offset]
        else:
            out[:offset] += ab[d, -offset:] * u[-offset:]
    return out


def _curvature(ab: np.ndarray, bw: int, delta: np.ndarray, nodes: np.ndarray,
               shift: float) -> float:
    """d_ηᵀ (W + shift·I) d_η, W = ∂R_η/∂η the node block of the Jacobian (the Hessian of
    S + λ·Φ_d), d_η the node part of ``delta``; ``ab`` in the band storage of
    :meth:`_Problem.assemble`."""
    d = np.where(nodes, delta, 0.0)
    return float(d @ _band_product(ab[bw:], bw, d)) + shift * float(d @ d)


def _descent_step(problem, state, res, ab, bw, delta, min_alpha: float = 2.0**-12):
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
    scale, shift = float(np.abs(ab[2 * bw][nodes]).max(initial=0.0)), problem.shift
    while shift <= 1e3:
        if shift > 0.0:
            try:
                delta = problem.solve(ab, bw, -res, shift * scale, nodes)
            except LinAlgError:         # this shift makes the matrix singular: the next
                shift = max(10 * shift, 1e-8)
                continue
        descent, nu, alpha = slope(delta), problem.penalty, 1.0
        if rows.any() and _curvature(ab, bw, delta, nodes, shift * scale) <= 0.0:
            descent = 0.0       # into W's negative curvature: shift instead
        while descent < 0.0 and alpha >= min_alpha:
            trial = problem.moved(state, delta, alpha)
            if trial is not None and _penalty(problem, trial, rows, nu) \
                    <= cost + nu * infeasibility + 1e-4 * alpha * descent:
                problem.shift = shift / 10 if alpha == 1.0 and shift > 1e-10 else \
                    (0.0 if alpha == 1.0 else shift)
                return trial, alpha * float(np.abs(delta).max(initial=0.0))
            alpha /= 2
        shift = max(10 * shift, 1e-8)
    return state, None


def _penalty(problem, path: Path, rows: np.ndarray, nu: float) -> float:
    """φ = S + ν‖Φ_d‖₁ at ``path`` (S alone without constraints)."""
    cost = problem.merit(path)[0]
    if not rows.any():
        return cost
    res, _, _, finite = problem.assemble(path, False)
    return cost + nu * float(np.abs(res[rows]).sum()) if finite else np.inf


def _natural_step(problem, state, delta, ab, bw: int, size: float):
    """The full Newton step from a residual at its rounding level, where the residual's
    norm is noise and cannot judge it: taken when it passes Deuflhard's natural
    monotonicity test (the correction the same Newton matrix gives at the new point is
    smaller), else (state, None)."""
    from scipy.linalg import LinAlgError

    trial = problem.moved(state, delta, 1.0)
    if trial is None:
        return state, None
    trial_res, _, _, finite = problem.assemble(trial, False)
    try:
        simplified = problem.solve(ab, bw, -trial_res) if finite else None
    except LinAlgError:
        simplified = None
    if simplified is None or not float(np.abs(simplified).max(initial=0.0)) < size:
        return state, None
    return trial, size


def _line_search(problem, state, delta, res, min_alpha: float = 2.0**-12):
    """Backtrack α = 1, ½, … until ‖R‖₂ decreases (Armijo, c = 1e-4)."""
    base = float(np.dot(res, res))
    alpha = 1.0
    while alpha >= min_alpha:
        trial = problem.moved(state, delta, alpha)
        if trial is not None:
            trial_res, _, _, finite = problem.assemble(trial, False)
            if finite and float(np.dot(trial_res, trial_res)) <= (1 - 1e-4 * alpha) * base:
                return trial, alpha * float(np.abs(delta).max(initial=0.0))
        alpha /= 2
    return state, None
