"""Banded assembly of the whole-trajectory Newton system (DESIGN.md §4).

The residual at node j involves nodes j−r … j+r, so the Jacobian is block-banded: C
assembles it in LAPACK's band storage (ab[2 bw + row − col, col] = J[row, col]) and
its banded LU (:mod:`.band`) solves for the corrections, so one iteration costs O(N).
The unknowns are corrections η_j of the free nodes, applied as the node variation g → g·τ(η), and with constraints the
multipliers λ^k of every window (paper §3.2, eq. ``constrainedso``), interleaved per node.
"""
from __future__ import annotations

import numpy as np

from .band import (factor, lu_solve, positive_definite, product, reciprocal_condition,
                   rounding_level)
from .gauge import Gauge
from .lifted import LIFT_FROM, LiftedSystem
from .optimality import FIRST_SHIFT
from ..core.model_info import Kernel
from ..core.paths import Path


class Problem:
    """Newton's view of a path: residuals, banded Jacobian and updates, all in C.

    An update composes each group fibre exactly, τ(hξ') = τ(−η_k) τ(hξ) τ(η_{k+1}), in
    increment-minus-identity arithmetic: recomputing ξ from the configurations instead
    would round it to ε/h, which the fourth-order structure of a second-order residual
    amplifies into O(1) errors of the slowest modes at N = 10⁵.
    """

    #: Unknowns after the band's (a free horizon's T: :mod:`.bordered`)
    BORDER = 0

    def __init__(self, model, p, h, lifted: bool | None = None):
        self.model, self.p, self.h = model, p, h
        #: Whether Newton corrections come from the lifted system (:mod:`.lifted`): by
        #: default where the model has one and N ≥ LIFT_FROM.
        self.lifted = lifted
        self._lifted = None
        #: An optimal-control problem minimises its cost: Newton steps are then globalised
        #: on the cost itself, or with constraints on its ℓ1 exact penalty (see
        #: :func:`.globalisation.descent_step`).
        self.minimise = bool(model.info.controls)
        self.shift, self.penalty = 0.0, 0.0
        #: The shift and the trial points of the last step taken, and the log of the
        #: last Newton solve (:mod:`.newton`, :mod:`..core.log`)
        self.last_shift, self.last_trials, self.log = 0.0, 0, None
        #: The inertia correction's first shift (:func:`.optimality.next_shift`)
        self.first_shift = FIRST_SHIFT
        #: Whether the last step was a full, unshifted Newton step from an iterate whose
        #: Hessian was positive definite (:func:`.globalisation.descent_step`).
        self.convex = False
        #: The residual's rounding level at the last iteration (:func:`.newton.rounding_level`).
        self.level = None
        self._band = self._work = None   # reused: fresh pages are slow to touch at large N
        #: (shift key, pivots) of the LU in the work band, kept until the next assembly:
        #: the rounding floor and simplified corrections reuse it.
        self._factored = None
        self._last = None       # (path, assembly) of the last assembly with a Jacobian
        self._rows = None       # constraint_rows' mask
        self.gauge = None
        #: Whether the last solve held an unknown beyond the band that its system could
        #: not move (a free horizon at a path at rest: :mod:`.bordered`): its correction
        #: then estimates no error
        self.held = False

    def step(self, path: Path) -> float:
        """The step h of ``path`` (the problem's; a free horizon's follows the path)."""
        return self.h

    def inequality_rates(self, path: Path) -> np.ndarray | None:
        """∂c/∂T per window and inequality at fixed elements, where the horizon T is an
        unknown (:mod:`.bordered`); None here."""
        return None

    def merit(self, path: Path) -> tuple[float, float]:
        """The cost S = Σ L_d and the size of its rounding error."""
        terms = self.model.along_vector(Kernel.LAGRANGIAN, path.x, path.f, self.h, self.p)
        return float(terms.sum()), float(np.abs(terms).sum()) * 64 * np.finfo(float).eps

    def assemble(self, path: Path, with_jacobian: bool, weights: np.ndarray | None = None):
        """(R, J in band storage or None, its bandwidth, whether both are finite) at
        ``path``; with ``weights`` (an interior point's z/s per window and inequality)
        the lifted system, where it is used, holds the barrier's GᵀΣG too (the node
        band gets it from :meth:`.barrier.Inequalities.add_barrier`)."""
        m, n_nodes = self.model, path.x.shape[0]
        unknown = int(m.lib.symvi_bvp_unknowns(n_nodes))
        bw = int(m.lib.symvi_bvp_bandwidth())
        res, ab = np.zeros(unknown), None
        if with_jacobian:
            if self._band is None or self._band.shape != (3 * bw + 1, unknown):
                self._band = np.zeros((3 * bw + 1, unknown), order="F")
                self._work = np.zeros_like(self._band, order="F")
            ab = self._band
            self._factored = None
        code = m.lib.symvi_bvp_assemble(m.ptr(path.x), m.ptr(path.f), m.ptr(path.lam),
                                        m.ptr(path.nu), n_nodes, m.ptr(self.p), self.h, m.ptr(res),
                                        m.ptr(ab.T) if with_jacobian else m.ffi.NULL)
        if with_jacobian and m.info.gauges:
            if self.gauge is None:
                self.gauge = Gauge(m, n_nodes)
            self.gauge.update(path, self.p, self.h)
        if with_jacobian and self._uses_lifted(n_nodes):
            if self._lifted is None or self._lifted.n_nodes != n_nodes:
                self._lifted = LiftedSystem(m, n_nodes, self.gauge)
            code = code if self._lifted.assemble(path, self.p, self.h,
                                                 weights=weights) else 1
        if with_jacobian:
            self._last = (path, (res, ab, bw, code == 0))
        return res, ab, bw, code == 0

    def assembled(self, path: Path):
        """:meth:`assemble` with the Jacobian at ``path``, reusing the last one if it was
        at this very path."""
        if self._last is not None and self._last[0] is path:
            return self._last[1]
        return self.assemble(path, True)

    def solve(self, ab, bw: int, rhs: np.ndarray, shift: float = 0.0,
              shifted: np.ndarray | None = None, at: Path | None = None) -> np.ndarray:
        """Solve (J + shift·D) x = rhs by banded LU (:func:`.band.factor`), J in the band
        storage of :meth:`assemble` (left intact: the work copy is factorised), D the
        identity on the unknowns ``shifted`` (a mask; default all). Exactly dependent
        constraints are replaced by their gauge condition (:mod:`.gauge`), posed at the
        path ``at`` (default: where J was assembled)."""
        lam = None if at is None or self.gauge is None else at.lam[self.gauge.window]
        if self._lifted is not None:
            return self._lifted.solve(rhs, shift, shifted, lam)
        key = (shift, None if shifted is None or not shift else shifted.tobytes())
        if self._factored is None or self._factored[0] != key:
            self._newton_matrix(ab, bw, shift, shifted)
            self._factored = (key, factor(self.model, self._work, bw,
                                          "band LU of the Newton matrix"))
        if self.gauge is not None:
            rhs = self.gauge.replace_rhs(rhs, self.gauge.rows, lam)
        return lu_solve(self.model, self._work, bw, self._factored[1],
                        np.array(rhs, dtype=float))

    @property
    def lifted_system(self) -> LiftedSystem | None:
        """The lifted system of the last assembly with a Jacobian, where it is used."""
        return self._lifted

    def definite(self, ab, bw: int, shift: float) -> bool:
        """Whether J + shift·I is positive definite (a problem without constraints): from
        the lifted system's inertia where it is used, else by band Cholesky of J."""
        if self._lifted is not None:
            return self._lifted.minimum(shift)[0]
        return positive_definite(self.model, ab, bw, shift)

    def curvature_beyond_band(self, ab, bw: int, shift: float = 0.0) -> float:
        """What the inertia of the Newton matrix needs beyond the band's: nothing here
        (inf); a free horizon's Schur complement (:mod:`.bordered`)."""
        return np.inf

    def curvature(self, ab, bw: int, delta: np.ndarray, nodes: np.ndarray,
                  shift: float) -> float:
        """d_ηᵀ (W + shift·I) d_η, W = ∂R_η/∂η the node block of the Jacobian (the Hessian
        of S + λ·Φ_d), d_η the node part (mask ``nodes``) of ``delta``; ``ab`` in the
        band storage of :meth:`assemble`."""
        d = np.where(nodes, delta, 0.0)
        with np.errstate(over="ignore", invalid="ignore"):      # a wild step: inf or nan
            return float(d @ product(self.model, ab, bw, d)) + shift * float(d @ d)

    def rounding_level(self, ab, bw: int, path: Path) -> float:
        """The residual's rounding level at ``path`` (:func:`.band.rounding_level`)."""
        return rounding_level(self.model, ab, bw, self.magnitudes(path))

    def _uses_lifted(self, n_nodes: int) -> bool:
        if not self.model.info.lifted:
            return False
        return n_nodes - 1 >= LIFT_FROM if self.lifted is None else self.lifted

    def reciprocal_condition(self, ab, bw: int) -> float:
        """An estimate of 1/κ₁ of the matrix :meth:`solve` factorises without shift (the
        lifted system's where it is used, equilibrated as it is factorised): below ε
        rounding may dominate its solves."""
        if self._lifted is not None:
            return self._lifted.reciprocal_condition()
        self._factored = None       # the estimate overwrites the work band
        self._newton_matrix(ab, bw)
        return reciprocal_condition(self._work, bw)

    def _newton_matrix(self, ab, bw: int, shift: float = 0.0,
                       shifted: np.ndarray | None = None) -> None:
        """Fill the work band with the matrix :meth:`solve` factorises (J, its shift, the
        gauge rows)."""
        np.copyto(self._work, ab)
        if shift:
            self._work[2 * bw] += shift if shifted is None else shift * shifted
        if self.gauge is not None:
            self.gauge.replace_rows(self._work, bw, self.gauge.rows)

    def moved(self, path: Path, delta, alpha):
        m, trial = self.model, path.copy()
        if np.size(delta) != m.lib.symvi_bvp_unknowns(path.x.shape[0]):    # C reads it all
            raise ValueError(f"a correction of {np.size(delta)} numbers for "
                             f"{m.lib.symvi_bvp_unknowns(path.x.shape[0])} unknowns")
        failed = m.ffi.new("long *")
        code = m.lib.symvi_bvp_update(m.ptr(trial.x), m.ptr(trial.g), m.ptr(trial.f),
                                      m.ptr(trial.lam), m.ptr(trial.nu), m.ptr(delta), alpha,
                                      path.x.shape[0],
                                      m.ptr(self.p), self.h, failed)
        return trial if code == 0 else None

    def rounding_correction(self, ab, bw: int, path: Path,
                            residual: np.ndarray | None = None, seeds=range(1)) -> float:
        """‖Δ‖∞ of the Newton correction (with J as assembled, in ``ab``) that undoes
        moving every unknown of ``path`` — node, multiplier — by one unit in the last
        place of its magnitude (:meth:`magnitudes`), in random directions, the path's
        numbers updated as by a Newton step: the error no path in double precision can
        avoid, hence a floor under the error of the returned one. A
        converged path's last corrections can be small by luck where this floor is
        large: the heavy top with rotors at N = 10⁴, whose residual sees the rotor
        angles' rounding ε|θ| over h³, passed two corrections below 1.9e-7 in a row
        after 28 of up to 7e-5, and its multipliers were 1e-6 off. The largest over the
        random directions ``seeds`` (one is a sample of the noise: the active-set Newton of
        bounded problems accepted multipliers 4 tolerances off on one lucky direction,
        ``polish.py``), through the same factorisation. ``residual``: R at ``path`` when
        known (the Jacobian's)."""
        base = residual if residual is not None else self.assemble(path, False)[0]
        if not np.isfinite(base).all():
            return np.inf
        floor = 0.0
        for seed in seeds:
            rounded, _ = self.rounded(path, seed)
            if rounded is None:
                return np.inf
            other, _, _, finite = self.assemble(rounded, False)
            if not finite:
                return np.inf
            if self.gauge is None:
                delta = self.solve(ab, bw, base - other)
            else:   # the gauge rows' right-hand sides carry each path's own multipliers
                delta = self.solve(ab, bw, -other, at=rounded) \
                    - self.solve(ab, bw, -base, at=path)
            floor = max(floor, self.correction_norm(delta, path))
        return floor

    def correction_norm(self, delta: np.ndarray, path: Path) -> float:
        """‖Δ‖∞ of a correction in the block layout, the measure compared with the
        tolerance xtol·(1 + size)."""
        return float(np.abs(delta).max(initial=0.0))

    def rounded(self, path: Path, seed: int):
        """(``path`` with every unknown — node, multiplier — moved by one unit in the last
        place of its magnitude in the random direction ``seed``, or None outside the
        chart; the generator, to draw further directions for unknowns beyond the band):
        the rounding floors' sample."""
        rng = np.random.default_rng(seed)
        units = np.finfo(float).eps * self.magnitudes(path)
        return self.moved(path, rng.choice((-1.0, 1.0), units.size) * units, 1.0), rng

    def perturbed(self, path: Path) -> Path:
        """``path`` with every free node moved by a fixed pseudo-random variation of size
        1e-2 (its ends kept): a second path between the same ends."""
        m, blocks = self.model, self._blocks(path)
        delta = 1e-2 * np.random.default_rng(0).uniform(-1.0, 1.0, (len(blocks), m.n
                                                                     + m.constraints))
        delta[(blocks < m.order) | (blocks > path.x.shape[0] - 1 - m.order)] = 0.0
        moved = self.moved(path, np.concatenate([delta.reshape(-1),
                                                 np.zeros(m.end_count + self.BORDER)]), 1.0)
        if moved is None:
            raise ValueError("cannot vary the initial path to check the declared symmetries")
        return moved

    def size(self, path: Path) -> float:
        """Scale of the unknowns for the relative step tolerance."""
        floor = 1.0 if self.model.matrix_dims else 0.0
        return max(floor, float(np.abs(path.x).max(initial=0.0)),
                   float(np.abs(path.lam).max(initial=0.0)),
                   float(np.abs(path.nu[:self.model.end_count]).max(initial=0.0)))

    def _blocks(self, path: Path) -> np.ndarray:
        """The nodes of the C assembler's blocks: each holds a node correction η_t (n
        unknowns, its residual rows) and, with constraints, the multipliers of window
        t − 1 (s unknowns, the rows of its constraints Φ_d): nodes r … N − r without
        constraints, 1 … N − r + 1 with them (a block per window). With an unknown end, to
        the last node; the end conditions' multipliers ν follow the blocks."""
        r, s = self.model.order, self.model.constraints
        t0, t1 = (1, r - 1) if s else (r, r)
        return np.arange(t0, path.x.shape[0] - (0 if self.model.end_free else t1))

    def constraint_rows(self, path: Path) -> np.ndarray:
        """Mask of the multiplier unknowns (= constraint rows) in the block layout (kept
        per number of nodes: read-only)."""
        n, s, ends = self.model.n, self.model.constraints, self.model.end_count
        count = len(self._blocks(path))
        if self._rows is None or len(self._rows) != count * (n + s) + ends:
            self._rows = np.concatenate([np.tile(np.concatenate(
                [np.zeros(n, bool), np.ones(s, bool)]), count), np.ones(ends, bool)])
            self._rows.flags.writeable = False
        return self._rows

    def multipliers(self, path: Path) -> np.ndarray:
        """The multipliers λ in the block layout, then ν (their rows of
        :meth:`constraint_rows`; a free end's last block, past the last window, 0)."""
        s, blocks = self.model.constraints, self._blocks(path)
        lam = np.zeros((len(blocks), s))
        windows = blocks - 1 < path.lam.shape[0]
        if s:
            lam[windows] = path.lam[blocks[windows] - 1, :s]
        return np.concatenate([lam.reshape(-1), path.nu[:self.model.end_count]])

    def magnitudes(self, path: Path) -> np.ndarray:
        """Magnitude of every unknown, in the block layout of the C assembler: a node
        correction is as precise as the fibres meeting there (a group fibre is held as
        its increment hξ, a pair fibre is the node itself), a multiplier as itself."""
        m, s = self.model, self.model.constraints
        blocks = self._blocks(path)
        scaled = m.step_scaled
        # blocks run from node T0 ≥ 1 to N − T1: the elements before each node exist, so
        # slices (no fancy-index copies) select them; the last node of a free end or of a
        # first-order constrained model has no element after it
        first, last = int(blocks[0]), int(blocks[-1])
        eta = np.abs(path.f[first - 1:last])
        if scaled.any():
            after = np.abs(path.f[first:last + 1])
            after = np.concatenate([after, eta[len(after):]])
            eta[:, scaled] = self.h * np.maximum(eta[:, scaled], after[:, scaled])
        lam = np.abs(path.lam[first - 1:last, :s]) if s else np.zeros((len(blocks), 0))
        lam = np.concatenate([lam, np.zeros((len(blocks) - len(lam), s))])
        return np.concatenate([np.concatenate([eta, lam], axis=1).reshape(-1),
                               np.abs(path.nu[:m.end_count])])
