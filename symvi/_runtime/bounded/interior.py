"""Primal–dual interior-point whole-trajectory Newton for optimal control with
inequalities (issue 21).

Newton's method on the perturbed KKT system of min S = Σ L_d subject to Φ_d = 0 and
c ≤ 0 on every window (:mod:`.barrier`), with the slack and multiplier steps eliminated
per window so that each iteration solves the equality solver's band. The barrier
parameter falls once the barrier problem is solved to its own accuracy, and only while
its bias exceeds the tolerance: to Mehrotra's σ·sᵀz/m, σ = (μ_aff/μ)³ from the
affine-scaling correction the SUCCESS rule computes anyway (:meth:`InteriorPoint.probed`),
at most the monotone rule's κμ (:func:`.barrier.next_barrier`; ``mu_strategy``). With it
the iterations at N = 100, 1000 and 10⁴: the minimum-time slew 30, 50, 49 (monotone 49,
84, 92), the cart-pole swing-up 58 and 51 at N = 100 and 1000 (64, 64). Steps keep
s, z > 0 by the fraction-to-the-boundary rule and are globalised by the filter line search of :mod:`.filter_steps` (or, where it finds no step or
``options.line_search`` asks it, as :mod:`.interior_steps` describes). Once the node
corrections are small the active-set Newton of :mod:`.polish` is tried from the
iterate (:meth:`InteriorPoint._identified`).

μ is measured per unit time: the barrier term of a window is μh log s, as the cost's
is h L̃, so one schedule fits every N.

SUCCESS needs the full Newton correction of the unperturbed KKT system (μ = 0, the
true optimality conditions with s_j z_j = 0) at the returned path — in the node
corrections and the multipliers λ and z — plus its rounding floor
(:meth:`InteriorPoint.rounding_floor`) within xtol·(1 + size), and a minimum (the
Hessian of the Lagrangian positive definite on the tangent space of the equalities and
the active bounds: :meth:`InteriorPoint.minimum`). Where that system is non-singular
(strict complementarity, independent active constraints, second-order sufficiency) the
correction is the first-order estimate of the distance to the KKT point, the same bound
the equality solver's rule uses. Where the iteration stalls, runs out of iterations or
rounding stops its corrections above the tolerance, the active-set Newton of
:mod:`.polish` tries to finish from the most accurate path met, under the same rule;
failing that the solve is ILL_CONDITIONED (returning that path), STALLED or
MAX_ITERATIONS.
"""
from __future__ import annotations

import math

import numpy as np

from ..bvp.band import cholesky_pivot
from ..bvp.diagnosis import diagnose
from .barrier import BOUND_TOLERANCE, Inequalities, boundary_step, next_barrier
from .vertex import fixes_every_unknown
from .filter_steps import filter_step
from ..core.log import IterationLog
from .interior_steps import step
from ..core.model_info import Kernel
from ..bvp.optimality import (FIRST_SHIFT, MAX_SHIFT, NEAR_FIRST_SHIFT, Curvature,
                              next_shift, second_order)
from ..core.options import SolveOptions
from ..core.paths import Path
from .polish import SAMPLES, polish
from ..core.results import BVPResult, Status

# The barrier parameter's start and floor (mu_start, mu_floor·xtol), the test of a solved
# barrier problem (kappa_epsilon, :meth:`InteriorPoint.barrier_error`), of stagnation and
# of an identified active set (identify) are the solve's options
# (:class:`.options.SolveOptions`). SUCCESS asks the whole KKT correction (nodes, λ
# and z) within the tolerance.

#: Penalties ρ (times W's scale over |∇c_j|²) on the active inequalities in the final
#: second-order test, and the cap on Σ in the iteration's inertia test (×10⁶). No more
#: than 10² of W's scale: the Cholesky factorisation's rounding grows as ε·ρ·‖W‖, and at
#: 10⁶ it hid a negative reduced eigenvalue (a hunt's false SUCCESS: the cart-pole at
#: N = 150 from the chord guess, a saddle of cost 32.3576 with reduced eigenvalue −0.197
#: accepted; capped, the solve goes on to the minimum 32.3515, smallest eigenvalue +4.4).
PENALTIES, CAP = (0.0, 1.0, 1e2), 1e6
#: An interior-point estimate the active-set Newton did not confirm counts only this many
#: times within the tolerance (:meth:`InteriorPoint._confirmed`): a hunt met one at 0.95
#: of the tolerance whose path was 1.0 of it off (the horizon of a double integrator
#: with moving ends at xtol = 1e-2).
UNCONFIRMED = 2.0
#: The largest relative tolerance whose stalled corrections can be rounding's
#: (:meth:`InteriorPoint._stagnant`): stalls are judged against 10⁴ times the smaller of
#: it and the tolerance asked.
ROUNDING = 1e-8


class InteriorPoint:
    """The interior-point iteration on one :class:`.assembly.Problem` and path, under the
    solve's :class:`.options.SolveOptions` (the active-set Newton of :mod:`.polish`
    reads them here too).

    ``near``: the start is near a solution (the optimum without bounds, or that moved
    toward them), and the iteration is issue 21's: μ falls as soon as the barrier
    problem's node correction is within κ_ε μ (1 + size), steps by Armijo on the ℓ1
    merit (:mod:`.interior_steps`), the active-set Newton only where it stalls. From
    such starts that one is the more robust: with the filter and the residual test of
    :meth:`barrier_error`, 4 of 10 perturbed starts of the cart-pole swing-up at
    N = 1000 ran out of iterations at μ = 0.1, where inertia-corrected steps alternated
    without converging; with it all 10 succeed."""

    def __init__(self, problem, path: Path, options: SolveOptions, near: bool = False):
        self.problem, self.model, self.xtol = problem, problem.model, options.xtol
        self.options, self.near = options, near
        #: The inertia correction's first shift (:func:`.optimality.next_shift`)
        self.first_shift = NEAR_FIRST_SHIFT if near else FIRST_SHIFT
        m = self.model
        self.s_count = m.constraints
        self.inequalities = Inequalities(m, path.x.shape[0])
        self.blocks = problem._blocks(path)
        self.width = m.n + m.constraints
        self.rows = problem.constraint_rows(path)
        self.nodes = ~self.rows
        self.mu, self.floor = options.mu_start, options.mu_floor * options.xtol
        self.corrections: list[float] = []     # the KKT corrections, one per iteration
        self.best = (np.inf, path, None)        # (correction, path, slacks) of the best
        self.verified = None        # a path :meth:`minimum` has verified (:meth:`finish`)
        self._unconfirmed = None    # the last path the active-set Newton did not finish
        #: The active sets :meth:`_identified` tried, with the node correction of the try
        self._tried: dict[bytes, float] = {}
        self._last_key = b""        # the active set at the last iteration's test
        self._gram = [None]         # AᵀA of the last inertia test (optimality._gram)
        self.node_correction = np.inf       # the last iteration's, for :meth:`_identified`
        #: Newton steps of the active-set Newton (:mod:`.polish`) from this interior point,
        #: failed attempts included: the result counts them among its iterations
        self.active_set_steps = 0
        self.filter, self.filter_mu = None, None     # the filter line search's (filter_steps)
        self.failure = ""           # why a failed iteration stopped, without the diagnosis
        self.log = IterationLog("interior point " + ("near a solution" if near else
                                                     "from the guess"),
                                options.verbose)
        #: The barrier's unit of time: the barrier term of a window is μ·unit·log s (the
        #: step h; with a free horizon, the first one, so that the barrier problem does
        #: not change with T)
        self.unit = problem.step(path)
        #: ∂c/∂T at the last system's path where the horizon is an unknown, else None
        self.rates = None
        self.inequalities.evaluate(path, problem.p, self.unit, with_jacobian=True)
        c = self.inequalities.values
        self.s = np.maximum(-c, 1e-2 * (1.0 + np.abs(c)))
        path.lam[:, self.s_count:] = self.mu * self.unit / self.s
        self.curved = True          # whether W has curvature (:meth:`curvature_scale`)
        #: The curvature scale where W has none (pure minimum time, whose Lagrangian is
        #: zero): the barrier's GᵀΣG at μ = 1 at the start, fixed for the solve
        self.barrier_scale = float((self.unit * self.squared_gradients() / self.s ** 2).max())

    @property
    def history(self) -> dict[str, list]:
        """The iteration log's columns so far (:mod:`.log`)."""
        return self.log.rows

    def curvature_scale(self, ab, bw: int) -> float:
        """The scale of inertia-correcting shifts and of the penalties on active rows: W's
        largest diagonal entry on the nodes (not Σ's, 10¹⁰ larger near the end), or
        :attr:`barrier_scale` where W is zero."""
        scale = float(np.abs(ab[2 * bw][self.nodes[:ab.shape[1]]]).max(initial=0.0))
        self.curved = scale > 0.0
        return scale if self.curved else self.barrier_scale

    def z(self, path: Path) -> np.ndarray:
        return path.lam[:, self.s_count:]

    # -- the linear algebra of one iteration ---------------------------------------------
    def system(self, path: Path):
        """Assemble the reduced system at ``path``: (res, ab, bw, and the stencil
        residual's norms on the node and constraint rows), or None where something is
        not finite."""
        res, ab, bw, finite = self.problem.assemble(path, True, self.z(path) / self.s)
        dual = float(np.abs(res[self.nodes]).max(initial=0.0))
        eq = float(np.abs(res[self.rows]).max(initial=0.0))
        self.stencil = res.copy()
        self.scale = self.curvature_scale(ab, bw)
        self.hessian = np.array(ab, order="F")      # W, before the barrier adds GᵀΣG
        self.rates = self.problem.inequality_rates(path)
        finite = finite and self.reduce(path, self.s, res, self.rates, ab)
        if finite and self.rates is not None:
            # the horizon's column of the same elimination: GᵀΣg_T and g_TᵀΣg_T
            sigma = self.z(path) / self.s
            self.problem.add_to_border(
                self.inequalities.transposed(sigma * self.rates, self.blocks, self.width),
                float((sigma * self.rates ** 2).sum()))
            # the shifts of the inertia correction on σ in its own units: the swing-up of
            # a torque-limited pendulum (pure minimum time, N = 400) found none up to
            # 10³ × W's scale, its Schur complement −6.7e3 with a corner of 1.3e2
            self.problem.corner_weight = max(1.0, abs(self.problem.border[1]) / self.scale)
        return (res, ab, bw, dual, eq) if finite else None

    def reduce(self, path: Path, s: np.ndarray, res: np.ndarray, rates: np.ndarray | None,
               ab=None) -> bool:
        """Add the eliminated slack and multiplier steps at ``path`` (slacks ``s``) to
        the residual ``res`` (and the band ``ab``, unless None) assembled there: Gᵀ(zc +
        μ)/s, and g_σᵀ(zc + μ)/s on the horizon's row where T is an unknown (``rates``,
        g_σ = ∂c/∂σ at ``path``: :meth:`.bordered.HorizonProblem.inequality_rates`);
        whether everything is finite."""
        z, mu = self.z(path), self.mu * self.unit
        if not self.inequalities.add_barrier(path, self.problem.p, self.problem.step(path),
                                             z, s, mu, res, ab):
            return False
        if rates is not None:
            res[-1] += float((rates * (z * self.inequalities.values + mu) / s).sum())
        return bool(np.isfinite(res[-1]))

    def steps(self, delta: np.ndarray, path: Path, mu: float, c: np.ndarray | None = None):
        """(Δs, Δz, GΔη) of the eliminated rows for the reduced correction ``delta``; c
        the inequalities at ``path`` (default: the last evaluated)."""
        Gd = self.inequalities.linearised(delta, self.blocks, self.width)
        if self.rates is not None:
            Gd = Gd + self.rates * delta[-1]
        c = self.inequalities.values if c is None else c
        z, s = self.z(path), self.s
        return -(c + s) - Gd, (mu + z * c + z * Gd) / s, Gd

    def barrier_rhs(self, mu: float) -> np.ndarray:
        """Gᵀ(μ/s) in the block layout: what the barrier adds to the reduced residual
        (and g_Tᵀ(μ/s) on the horizon's row, where T is an unknown)."""
        nodes = self.inequalities.transposed(mu / self.s, self.blocks, self.width)
        if self.rates is None:
            return nodes
        return np.append(nodes, float((self.rates * mu / self.s).sum()))

    def kkt_correction(self, ab, bw: int, res: np.ndarray, path: Path) -> np.ndarray:
        """(Δη, Δλ, Δz) of the full Newton correction of the unperturbed KKT system
        (μ = 0, s_j z_j = 0) at ``path``, from the reduced system (``res``, ``ab``)
        assembled there at the current μ: its ∞-norm is the first-order estimate of the
        distance to the KKT point, barrier's bias included. Not Δs, which is Δη's noise
        amplified by G (:meth:`_barrier_error`)."""
        delta = self.problem.solve(ab, bw, -(res - self.barrier_rhs(self.mu * self.unit)))
        return np.concatenate([delta, self.steps(delta, path, 0.0)[1].ravel()])

    # -- the iteration -------------------------------------------------------------------
    def solve(self, path: Path):
        """Iterate from ``path``, at most ``options.maxiter`` times: (path, iterations,
        status, message)."""
        from scipy.linalg import LinAlgError

        maxiter = self.options.maxiter
        for it in range(maxiter):
            try:
                path, status, message = self.iteration(path, it)
            except LinAlgError as exc:
                return path, it, Status.SINGULAR_JACOBIAN, (
                    f"singular Newton matrix at interior-point iteration {it} ({exc})"
                    f"{self._why_singular(path)}")
            self.log.report(it, f": {status.name}" if status is not None else "")
            if status in (Status.STALLED, Status.MAX_ITERATIONS):
                return self._failed(path, it + 1, status, message)
            if status is not None:
                return path, it + (status is not Status.SUCCESS), status, message
        return self._failed(path, maxiter, Status.MAX_ITERATIONS, (
            f"the interior-point method did not converge in {maxiter} iterations "
            f"(barrier parameter {self.mu:.1e}, {self._last_errors()})"))

    def _failed(self, path: Path, iterations: int, status: Status, message: str):
        """(path, iterations, status, message) of a stalled or exhausted iteration: SUCCESS
        where the active-set Newton (:mod:`.polish`) finishes from the most accurate path
        met — it accepts only a KKT point within the tolerance, wherever it starts —
        else the failure, with the infeasibility where it stopped decreasing."""
        _, best, slacks = self.best
        if best is not None and slacks is not None:
            s, self.s = self.s, slacks
            finished = self.finish(best, self.xtol * (1.0 + self.problem.size(best)))
            if finished is not None:
                how = "stalled" if status == Status.STALLED else "ran out of iterations"
                return finished[0], iterations, Status.SUCCESS, (
                    f" (where it {how}, its most accurate iterate was finished){finished[1]}")
            self.s = s
        self.failure = message
        return path, iterations, *self._with_infeasibility(path, status, message)

    def finish(self, path: Path, tolerance: float, active: np.ndarray | None = None):
        """(path, message, Newton steps) of the active-set Newton (:mod:`.polish`) from
        ``path`` where it ends at a verified minimum (:meth:`minimum`), its slacks then
        set; else None, the slacks unchanged. Not a saddle: a KKT point of another
        active set can be one (the cart-pole swing-up at N = 700), and the interior
        point's own failure, with its retries, says more."""
        polished = polish(self, path, tolerance, active)
        if polished is None:
            return None
        end, slacks, message, steps = polished
        kept, self.s = self.s, slacks
        status, message = self.minimum(end, message)
        if status != Status.SUCCESS:
            self.s = kept
            return None
        self.verified = end
        return end, message, steps

    def _with_infeasibility(self, path: Path, status: Status, message: str) -> tuple[Status, str]:
        """A stalled or exhausted solve whose primal infeasibility stopped decreasing
        (less than 10 % over the last ten iterations) above 10⁻³ of the inequalities'
        scale: the message names the worst violated inequality and its window. The
        status stays: such a stall is not proof that the bounds admit no solution (the
        planar flyer with a forward-only thruster stalls at 1.1 although it is feasible;
        a stall of the slew whose torque limit admits none looks the same), and no
        restoration phase yet tells the two apart."""
        primal = self.history["primal"]
        if status not in (Status.STALLED, Status.MAX_ITERATIONS) or len(primal) < 10 \
                or primal[-1] < 0.9 * primal[-10]:
            return status, message
        p, h = self.problem.p, self.problem.step(path)
        self.inequalities.evaluate(path, p, h)
        c = self.inequalities.values
        if primal[-1] <= 1e-3 * (1.0 + float(np.abs(c).max(initial=0.0))):
            return status, message
        w, k = np.unravel_index(int(np.argmax(c)), c.shape)
        worst = (f"the worst inequality, {self.inequalities.names[k]!r}, is violated by "
                 f"{c[w, k]:.3g} at window {w} (t = {(w + 1) * h:.4g})" if c[w, k] > 0 else
                 f"the constraints Φ_d are violated by up to {primal[-1]:.3g}")
        return status, (
            f"{message}; the infeasibility stopped decreasing at {primal[-1]:.3g}: {worst}. "
            f"The bounds may admit no solution (loosen them or lengthen the horizon), or "
            f"the method failed from this start (try another guess)")

    def iteration(self, path: Path, it: int):
        h = self.unit
        # before the assembly: the active-set Newton assembles in the same buffers
        finished = self._identified(path, self.xtol * (1.0 + self.problem.size(path)))
        if finished is not None:
            return finished[0], Status.SUCCESS, finished[1]
        system = self.system(path)
        if system is None:
            return path, Status.NON_FINITE, (
                f"non-finite residual, Jacobian or inequality at interior-point iteration {it}")
        res, ab, bw, dual, eq = system
        self._record(path, dual, eq)
        tolerance = self.xtol * (1.0 + self.problem.size(path))
        while True:
            delta = self.problem.solve(ab, bw, -res)
            ds, dz, Gd = self.steps(delta, path, self.mu * h)
            error = self._barrier_error(delta, dz, path)
            kkt = self.kkt_correction(ab, bw, res, path)
            correction = self.kkt_norm(kkt, path)
            self.corrections.append(max(error, correction))
            self.log.correction(self.corrections[-1])
            if max(error, correction) < self.best[0]:
                self.best = (max(error, correction), path, self.s.copy())
            # and every bound holding at path, whatever xtol (barrier.BOUND_TOLERANCE):
            # where one does not, the iteration goes on, its steps cutting c + s
            unconfirmed = False
            if max(error, correction) <= tolerance and self.bounds_hold(path):
                floor = self.rounding_floor(path, kkt)
                if max(error, correction) + floor > tolerance:
                    # small by luck against the noise: judged as that sum, and on (from
                    # the system at path again: the floor assembled another in its place)
                    self.corrections[-1] += floor
                    if self.best[1] is path:
                        self.best = (self.corrections[-1], path, self.best[2])
                    res, ab, bw, _, _ = self.system(path)
                    break
                confirmed = self._confirmed(path, tolerance, correction, floor)
                if confirmed is not None:
                    return confirmed
                # unconfirmed, the estimate stands only below μ = xtol: μ falls (from
                # the system at path again: the active-set Newton assembled in its place)
                unconfirmed = True
                res, ab, bw, _, _ = self.system(path)
            # μ falls once its barrier problem is solved, and only while its bias (the
            # μ = 0 correction beyond the barrier problem's own) exceeds the tolerance:
            # a smaller μ only adds rounding (Σ = z/s grows as 1/μ on active rows)
            biased = correction - error > tolerance / 2 or unconfirmed
            self.node_correction = float(np.abs(delta[self.nodes]).max(initial=0.0))
            solved = self._barrier_solved(res, bw, path, error, tolerance)
            if not solved or self.mu <= self.floor or not biased:
                break
            # the barrier problem is solved: the same matrix serves the next μ
            mu = next_barrier(self.mu, self.floor)
            if self.options.mu_strategy == "probing":
                mu = max(self.floor, min(mu, self.probed(kkt, path)))
            res = res - self.barrier_rhs((self.mu - mu) * h)
            self.mu, self.corrections = mu, []      # stagnation is judged per barrier stage
        stagnant = self._stagnant(tolerance)
        if stagnant is not None:
            # the most accurate path met, with its own correction as its error estimate
            best, path, self.s = self.best
            finished = self.finish(path, tolerance)
            if finished is not None:
                return finished[0], Status.SUCCESS, finished[1]
            return path, Status.ILL_CONDITIONED, (
                f"the Newton correction of the KKT system stopped decreasing, between "
                f"{min(self.corrections):.1e} and {stagnant:.1e}, above the tolerance "
                f"xtol·(1 + size) = {tolerance:.1e} (barrier parameter {self.mu:.1e}): "
                f"rounding amplified by the barrier system's conditioning (Σ = z/s grows as "
                f"the bounds become active) limits the attainable accuracy; the path "
                f"returned is the most accurate met, its correction {best:.1e}. Accept it "
                f"with a larger xtol, or use fewer steps")
        search = filter_step if self.options.line_search == "filter" and not self.near \
            else step
        moved = search(self, path, res, ab, bw, delta, ds, dz, Gd, error)
        if moved is None:
            return path, Status.STALLED, (
                f"the interior-point line search stalled at iteration {it} (barrier "
                f"parameter {self.mu:.1e}, {self._last_errors()})")
        return moved, None, ""

    def _confirmed(self, path: Path, tolerance: float, correction: float, floor: float):
        """(path, SUCCESS, message) once the μ = 0 KKT correction at an interior ``path``
        is within the tolerance, or None to iterate on. That correction linearises
        s∘z = 0 across the whole active set at once, and where μ is still large it is
        not the distance to the KKT point: the torque-limited slew at N = 1000 with
        xtol = 1e-2 stopped at μ = 0.4 with a correction of 2.0e-2 and was 0.12 from the
        optimum (3–5× its estimate for xtol 1e-2 … 1e-3). So the active-set Newton of
        :mod:`.polish` finishes from it — two corrections in a row within the tolerance,
        quadratic convergence shown. Where it cannot (gauged constraints; a degenerate
        active set: the double integrator's minimum time from States, two windows at the
        switch 2e-8 inside their bounds with multipliers near 0), the interior point's own
        estimate stands once μ is below xtol and it is within half the tolerance
        (:data:`UNCONFIRMED`): the iterate is then within O(μ) of the KKT point, and the
        linearisation's error second order in that. Else it goes on."""
        # once per path: at the next μ the same iterate needs only the μ test
        finished = None if path is self._unconfirmed else self.finish(path, tolerance)
        if finished is not None:
            return finished[0], Status.SUCCESS, f" (finished from its last iterate){finished[1]}"
        self._unconfirmed = path
        if self.mu > self.xtol or UNCONFIRMED * (correction + floor) > tolerance:
            return None
        return path, Status.SUCCESS, (
            f"; Newton correction of the KKT system (μ = 0) {correction:.1e}, rounding "
            f"floor {floor:.1e}, within xtol·(1 + size) = {tolerance:.1e} (barrier "
            f"parameter {self.mu:.1e}), {self._last_errors()}")

    def _barrier_solved(self, res: np.ndarray, bw: int, path: Path, error: float,
                        tolerance: float) -> bool:
        """Whether the barrier problem counts as solved, so that μ may fall: its
        correction within the tolerance, or :meth:`barrier_error` within κ_ε μ (from a
        start near a solution: the node correction within κ_ε μ (1 + size))."""
        kappa = self.options.kappa_epsilon
        if self.near:
            return self.node_correction <= kappa * self.mu * (1.0 + self.problem.size(path))
        return error <= tolerance or self.barrier_error(res, bw, path) <= kappa * self.mu

    def probed(self, kkt: np.ndarray, path: Path) -> float:
        """Mehrotra's barrier parameter (per unit time) from the affine-scaling
        correction ``kkt`` (:meth:`kkt_correction`: Δη, Δλ, Δz at μ = 0): σ·μ̄ with μ̄ =
        sᵀz/(m·unit), σ = (μ_aff/μ̄)³, μ_aff the complementarity after the longest steps
        to the boundary along it (Nocedal & Wright, Algorithm 14.3)."""
        z, s = self.z(path), self.s
        ds = self.steps(kkt[:kkt.size - z.size], path, 0.0)[0]
        dz = kkt[kkt.size - z.size:].reshape(z.shape)
        alpha, alpha_z = boundary_step(s, ds, 1.0), boundary_step(z, dz, 1.0)
        mean = float((s * z).mean()) / self.unit
        affine = float(((s + alpha * ds) * (z + alpha_z * dz)).mean()) / self.unit
        return (affine / mean) ** 3 * mean if mean > 0 else 0.0

    def barrier_error(self, res: np.ndarray, bw: int, path: Path) -> float:
        """E_μ of Wächter & Biegler 2006 (eq. 5) per unit time — the barrier problem's
        dual and equality residuals over h, the slacked inequalities' residual c + s, and
        the complementarity's distance s∘z/h − μ —: its barrier problem counts as solved
        where E_μ ≤ κ_ε μ. Residuals, not the Newton correction the SUCCESS rule reads:
        that one, relative to the path's size (its multipliers' included), called the
        first barrier problems solved at once — the cart-pole swing-up from its guess at
        N = 1000 went from μ = 100 to 0.032 in two iterations with a dual residual of 60,
        and crept at steps α ≈ 0.05 cut by the fraction to the boundary for 90
        iterations. The residuals are measured above their rounding level
        (:func:`.band.rounding_level` of W, assembled at ``path``): at N = 1000 the
        cart-pole's barrier problem converged in its nodes with a node residual of 0.05,
        its rounding, and μ = 0.1 never fell."""
        h = self.unit
        c, z = self.inequalities.values, self.z(path)
        level = self.problem.rounding_level(self.hessian, bw, path)
        dual = max(0.0, float(np.abs(res).max(initial=0.0)) - level)
        return max(dual / h,
                   float(np.abs(c + self.s).max(initial=0.0)),
                   float(np.abs(self.s * z / h - self.mu).max(initial=0.0)))

    def _identified(self, path: Path, tolerance: float):
        """(path, message) where the active-set Newton (:mod:`.polish`) finishes from
        ``path``, tried for an active set (z > s) as soon as the last node correction is
        within ``options.identify`` of the nodes' size (1 + max |x|), and for the same set
        again only from ten times closer; else None. The interior point
        finds the active set long before its multipliers converge: those of nearly
        dependent active rows (the cart-pole's track limit touched at adjacent windows)
        are fixed by the barrier problem only weakly, and the cart-pole catch at N = 1000
        went on for 280 iterations at μ = 3.2e-3 with its nodes converged to 1e-7 and a
        KKT correction stuck at 0.3 in the multipliers; the active-set Newton finished it
        in 3 steps."""
        nodes = self.node_correction
        if self.near or \
                nodes > self.options.identify * (1.0 + float(np.abs(path.x).max(initial=0.0))):
            return None
        identified = self.z(path) > self.s
        if not (self.curved or identified.any()):
            return None     # no curvature and nothing active: no vertex identified yet
        key = identified.tobytes()
        stable, self._last_key = key == self._last_key, key
        if not stable:
            return None         # the set changed at the last iteration: not identified
        if nodes > 0.1 * self._tried.get(key, np.inf):
            return None         # tried from no farther: again only from ten times closer
        self._tried[key] = nodes
        finished = self.finish(path, tolerance)
        if finished is None:
            return None
        return finished[0], f" (its active set identified and finished){finished[1]}"

    def bounds_hold(self, path: Path, among: np.ndarray | None = None) -> bool:
        """Whether every inequality (of the rows ``among``, default all) holds at
        ``path``, last evaluated, to :data:`.barrier.BOUND_TOLERANCE` of its scale beyond
        its rounding (:meth:`.barrier.Inequalities.holds`): the condition of every
        SUCCESS."""
        return self.inequalities.holds(path, among)

    def rounding_floor(self, path: Path, kkt: np.ndarray) -> float:
        """The largest ‖·‖∞ of the change in the μ = 0 KKT correction ``kkt``
        (:meth:`kkt_correction` at ``path``) when
        every unknown — node, λ, z and slack — moves by one unit in the last place of its
        magnitude, over :data:`.polish.SAMPLES` random directions: the noise under that
        correction, as the equality solver's floor
        (:meth:`.assembly.Problem.rounding_correction`). A correction within the tolerance
        by luck is caught by it: the planar flyer at N = 200 met its tolerance 3.0e-9 with
        a correction of 2.4e-9 over a floor of 3.0e-9. More than one direction: one is a
        sample of the noise, and on nearly dependent active rows eight gave 7e-9 to
        5.1e-7 (the active-set Newton's, :func:`.polish._floor`). The system of the last
        moved path takes the place of the one at ``path``."""
        eps = np.finfo(float).eps
        z, s, floor = self.z(path), self.s, 0.0
        for seed in range(SAMPLES):
            rounded, rng = self.problem.rounded(path, seed)
            if rounded is None:
                return np.inf
            rounded.lam[:, self.s_count:] = z * (1.0 + eps * rng.choice((-1.0, 1.0), z.shape))
            self.s = s * (1.0 + eps * rng.choice((-1.0, 1.0), s.shape))
            try:
                system = self.system(rounded)
                other = None if system is None else \
                    self.kkt_correction(system[1], system[2], system[0], rounded)
            finally:
                self.s = s
            if other is None:
                return np.inf
            floor = max(floor, self.kkt_norm(other - kkt, path))
        return floor

    def _stagnant(self, tolerance: float) -> float | None:
        """The attainable accuracy where the KKT corrections of one barrier stage have
        stopped decreasing near a feasible solution — the best of the last
        ``options.stagnation`` is not half the best of the ones before, all within 10⁴ of
        the tolerance, the primal infeasibility below 1e-8 — else None (the
        near-bang–bang slew at N = 1000 hovered between 9e-9 and 4e-8 for 80 iterations,
        asked 2e-9)."""
        c, n = self.corrections, self.options.stagnation
        if len(c) < 2 * n or self.history["primal"][-1] > 1e-8:
            return None     # not near a solution: not rounding's doing
        recent, before = min(c[-n:]), min(c[-2 * n:-n])
        attainable = max(c[-n:])
        # and far below the path's size: at xtol = 1e-2 the planar flyer's corrections
        # hovered at 0.7 in a basin it had not left, and 1e4 × the tolerance called that
        # rounding (ILL_CONDITIONED 3.0 from the optimum, which xtol = 1e-4 found)
        size = tolerance / self.xtol
        if recent > 0.5 * before and attainable <= 1e4 * min(tolerance, ROUNDING * size):
            return attainable
        return None

    def _barrier_error(self, delta, dz, path: Path) -> float:
        """The barrier problem's remaining error: its full Newton correction in the node
        corrections, λ and z, measured as the tolerance reads it
        (:meth:`.assembly.Problem.correction_norm` of Δ, and ‖Δz‖∞). Not in the slacks:
        Δs = −(c + s) − GΔη carries Δη's noise amplified by G (∂u/∂η ∝ 1/h² for
        controls), and s is c's function anyway."""
        return max(self.problem.correction_norm(delta, path),
                   float(np.abs(dz).max(initial=0.0)))

    def kkt_norm(self, kkt: np.ndarray, path: Path) -> float:
        """:meth:`_barrier_error`'s measure of a :meth:`kkt_correction` (Δη, Δλ, Δz)."""
        n = kkt.size - self.z(path).size
        return self._barrier_error(kkt[:n], kkt[n:], path)

    def _record(self, path: Path, dual: float, eq: float) -> None:
        c, z = self.inequalities.values, self.z(path)
        self.log.measured(mu=self.mu, objective=self.problem.merit(path)[0],
                          primal=max(eq, float(np.abs(c + self.s).max(initial=0.0))),
                          dual=dual, complementarity=float((self.s * z).max(initial=0.0)),
                          T=math.nan if path.T is None else path.T)

    def _last_errors(self) -> str:
        hist = self.history
        return (f"primal infeasibility {hist['primal'][-1]:.1e}, dual infeasibility "
                f"{hist['dual'][-1]:.1e}, complementarity {hist['complementarity'][-1]:.1e}")

    def minimum(self, path: Path, message: str) -> tuple[Status, str]:
        """The second-order test at the converged path: the Hessian W of the Lagrangian
        S + λ·Φ_d + z·c positive definite on the tangent space of the equalities and
        the active inequalities (second-order sufficient conditions). W + ρG_AᵀG_A, G_A
        the active inequalities' gradients, goes to :func:`.optimality.second_order`
        for growing ρ (Debreu's lemma, as for the equality rows). Not the reduced matrix
        W + GᵀΣG of the iteration: near the end Σ exceeds W by 10¹³ on active rows and
        its Cholesky factorisation is rounding. Where that fails, a vertex — the
        equalities and active rows fixing every unknown (:mod:`.vertex`) — is a strict
        minimum whatever W. SUCCESS, or SADDLE."""
        _, ab, bw, finite = self.problem.assemble(path, True)
        active = (self.z(path) > self.s).astype(float)
        scale = self.curvature_scale(ab, bw)
        verdict, rates = None, self.problem.inequality_rates(path)
        for rho in PENALTIES if finite else ():
            verdict = self.curvature(path, ab, bw, active * rho * scale / self.squared_gradients(),
                                     rates)
            if verdict.minimum:
                return Status.SUCCESS, message
        # the penalty tests above evaluated c and G at path (add_barrier)
        positive = self.z(path)[active > 0] > self.xtol * (1.0 + self.problem.size(path))
        if finite and positive.all() and fixes_every_unknown(self, ab, bw, active > 0, rates):
            return Status.SUCCESS, f"{message}; a vertex: the active inequalities fix every unknown"
        pivot = "" if verdict is None else f" (Cholesky pivot {verdict.pivot:.1e})"
        if not self.curved:
            # a hunt: the double integrator at xtol = 1e-2, T = 2.008 for T* = 2, was
            # told to start from another guess
            return Status.SADDLE, (
                f"converged to a KKT point{message}, but not to a verified minimum: the "
                f"cost has no curvature in the path (pure minimum time), so a minimum is "
                f"verified at a vertex of the active inequalities, and at this tolerance "
                f"they do not yet fix every unknown — ask a smaller xtol")
        return Status.SADDLE, (
            f"converged to a KKT point{message}, but not to a verified minimum: the Hessian "
            f"of the Lagrangian is not positive definite on the tangent space of the "
            f"equalities and active inequalities{pivot} — a saddle or maximum; start from "
            f"another guess")

    def curvature(self, path: Path, hessian, bw: int, weight: np.ndarray,
                  rates: np.ndarray | None, shift: float = 0.0) -> Curvature:
        """The second-order test (:func:`.optimality.second_order`: positive definite
        on the equalities' tangent space, by Debreu's lemma) of W + Gᵀ diag(weight) G +
        shift·I on the node corrections, W the Hessian of the Lagrangian in ``hessian``
        (band storage, left intact) and G the inequalities' gradients at ``path``; with a
        free horizon, ``rates`` the inequalities' g_σ there (else None) and the border
        of the last assembly, at ``path``, W's."""
        if self.problem.lifted_system is not None and self.curved:
            return self._lifted_curvature(weight, rates, shift)
        problem, work = self.problem, np.array(hessian, order="F")
        weight = np.ascontiguousarray(weight)
        self.inequalities.add_barrier(path, problem.p, problem.step(path), weight,
                                      np.ones_like(weight), 0.0, np.zeros(work.shape[1]), work)
        band = work.shape[1]
        work[2 * bw] += shift * self.nodes[:band]
        verdict = second_order(work, bw, self.rows[:band],
                               lambda: cholesky_pivot(self.model, work, bw), self._gram)
        if not verdict.minimum or rates is None:
            return verdict
        # a free horizon: the bordered matrix's inertia is the band's and the sign of its
        # Schur complement (Haynsworth), the border W's plus the weighted inequalities'
        b, d = problem.raw
        column = b + self.inequalities.transposed(weight * rates, self.blocks, self.width)
        schur = problem.schur_with(work, bw, column, d + float((weight * rates ** 2).sum())
                                   + shift * problem.corner_weight)
        return verdict if schur > 0 else Curvature(False, verdict.rho, schur)

    def _lifted_curvature(self, weight: np.ndarray, rates: np.ndarray | None,
                          shift: float) -> Curvature:
        """:meth:`curvature` from the lifted system's inertia (:meth:`.lifted.
        LiftedSystem.minimum`), its barrier weighed by ``weight``; with a free horizon,
        and the Schur complement of the border through the lifted system's solve. Where
        the lifted system solves the steps (N ≥ 2000) W's band Cholesky cannot tell W's
        smallest eigenvalue (≈ hπ⁴) from its rounding (≈ ε·16/h³): the shift that test
        asked for at every iteration slowed the cart-pole swing-up's Newton at N = 10⁴
        to linear convergence (MAX_ITERATIONS; 51 iterations with this test)."""
        lifted = self.problem.lifted_system
        if not lifted.weigh(weight):
            return Curvature(False, 0.0, np.nan)
        minimum, excess = lifted.minimum(shift)
        if not minimum or rates is None:
            return Curvature(minimum, 0.0, float(excess))
        b, d = self.problem.raw
        column = b + self.inequalities.transposed(weight * rates, self.blocks, self.width)
        mask = self.nodes[:len(column)].astype(float)
        solved = lifted.solve(column, shift, mask)
        schur = d + float((weight * rates ** 2).sum()) + shift * self.problem.corner_weight \
            - float(column @ solved)
        return Curvature(schur > 0, 0.0, schur)

    def squared_gradients(self) -> np.ndarray:
        """|∇c_j|² per window and inequality: the penalties on the active ones are
        measured per row, since a bound on a control (∂u/∂η ∝ 1/h²) and one on a
        coordinate differ in scale by 1/h⁴ (a common scale hid the cart-pole's track
        limit: a false SADDLE at a verified minimum). The active-set Newton's test of
        dropped rows uses them too (:mod:`.polish`)."""
        return np.maximum((self.inequalities.jacobian ** 2).sum(axis=2), 1e-300)

    def _why_singular(self, path: Path) -> str:
        """Why the Newton matrix is singular where the constraints or end conditions are
        the cause (:func:`.bvp.diagnosis.diagnose`: dependent, or not to be met from
        ``path``), as the solve without inequalities says it: the KKT matrix has the rows
        of A = ∂(Φ_d, ψ)/∂η, and dependent rows (nine end conditions on the entries of
        an SE(2) configuration and ξ, whose group has three directions) make it
        singular whatever the barrier adds to W."""
        found = diagnose(self.problem, path)
        return "" if found is None else found.describe(path.x.shape[0] - 1,
                                                         self.problem.step(path))

    def inertia_shift(self, path: Path, bw: int, start: float) -> float:
        """The inertia correction of the step (Wächter & Biegler 2006, §3.1, with
        Debreu's test for the inertia LAPACK's band routines do not give): the smallest
        δ from start along :func:`.optimality.next_shift`'s ladder (relative to W's
        largest diagonal entry) for which W + GᵀΣ'G + δ·I is positive definite on the
        equalities' tangent space, so
        that the step descends on the barrier problem and no saddle attracts it; inf if
        none up to 1e3. Σ' = min(Σ, 10⁶ × scale / |∇c_j|²): where Σ = z/s exceeds W
        by 10¹⁰ near the end its Cholesky factorisation is rounding, and a capped Σ'
        only makes the test stricter (GᵀΣG − GᵀΣ'G is positive semidefinite). The
        cart-pole swing-up with force and track limits: without it 4 of 8 limit pairs
        ended in MAX_ITERATIONS and one at a saddle; with it all 8 succeed."""
        weight = np.minimum(self.z(path) / self.s, CAP * self.scale / self.squared_gradients())
        shift = start
        try:
            while shift <= MAX_SHIFT:
                if self.curvature(path, self.hessian, bw, weight, self.rates,
                                  shift * self.scale).minimum:
                    return shift
                shift = next_shift(shift, self.first_shift)
            return np.inf
        finally:        # the step's own weights back in the lifted system, for its solve
            if self.problem.lifted_system is not None:
                self.problem.lifted_system.weigh(self.z(path) / self.s)

    def _bounds_verified(self, path: Path, message: str) -> tuple[Status, str]:
        """(status, message) of a SUCCESS, checked once more at the returned ``path``:
        every inequality within :data:`.barrier.BOUND_TOLERANCE` of its scale, else
        ILL_CONDITIONED with the violation (the phases accept no such path; this is the
        last line against a false SUCCESS)."""
        finite = self.inequalities.evaluate(path, self.problem.p, self.problem.step(path))
        if finite and self.bounds_hold(path):
            return Status.SUCCESS, message
        where = self.inequalities.describe_violation(self.problem.step(path)) if finite else \
            "an inequality is not finite"
        return Status.ILL_CONDITIONED, (
            f"converged within the tolerance{message}, but at the path returned {where}, "
            f"more than {BOUND_TOLERANCE:.0e} of its scale beyond its rounding: not "
            f"accepted. Ask a smaller xtol")

    def result(self, path: Path, iterations: int, status: Status, message: str) -> BVPResult:
        """The :class:`BVPResult` of the solve, with the bound multipliers, the active
        set and the iteration history."""
        model, problem = self.model, self.problem
        h, p, s_count = problem.step(path), problem.p, self.s_count
        N = path.x.shape[0] - 1
        if status == Status.SUCCESS:
            status, message = self._bounds_verified(path, message)
        z = np.array(self.z(path))
        return BVPResult(
            t=h * np.arange(N + 1), iterations=iterations,
            residual_norms=np.array(self.history["dual"]),
            step_norms=np.array([a for a in self.log.history()["alpha"] if a > 0]),
            status=status, message=message,
            x=path.x if model.m else None, f=path.f,
            g=model.configurations(path.g) if model.matrix_dims else None,
            multipliers=np.array(path.lam[:, :s_count]) if s_count else None,
            controls=model.along_vector(Kernel.CONTROLS, path.x, path.f, h, p),
            cost=float(model.along_vector(Kernel.LAGRANGIAN, path.x, path.f, h, p).sum()),
            kind=model.info.kind, bound_multipliers=z, active=z > self.s,
            end_multipliers=path.nu[:model.end_count].copy() if model.end_count else None,
            inequalities=self.inequalities.names,
            history=self.log.history())

