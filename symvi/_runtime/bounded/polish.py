"""Active-set Newton on the interior point's identified active set (issue 21).

Near the end of an interior-point solve the barrier's reduced matrix W + GᵀΣG carries
Σ = z/s ≈ 10¹² on the active rows beside W's curvature, and its solves are rounding in
the directions along the active constraints: the planar flyer at N = 400 and 1000
hovered at KKT corrections of 10⁻⁸–10⁻⁵ (tolerance 3·10⁻⁹) and ended ILL_CONDITIONED. The
same optimum solves the KKT system of the equality-constrained problem in which the
active rows 𝒜 (z > s) are equalities and the others are dropped (z = 0),

    [ J    G_𝒜ᵀ ] [Δ ]     [ ∇ℒ  ]
    [ G_𝒜   0   ] [Δz] = − [ c_𝒜 ],

J the equality solver's Newton matrix (W with the multipliers z in the augmented window
Lagrangian, A, the pinned rows) and ∇ℒ its residual. This saddle-point matrix is
well conditioned where the active constraints are independent and the Hessian is
positive definite on their tangent space (the second-order sufficient conditions
:meth:`.interior.InteriorPoint.minimum` tests), so Newton converges quadratically from
the interior point's iterate: the flyer at N = 1000 from corrections 1.7e-8 (nodes) and
4.2e-6 (z) to 5.6e-14 and 7.0e-11 in three steps. It is not the banded system of the
iteration — its unknowns add a multiplier per window and inequality — so it is
assembled sparse and factorised by SuperLU (SciPy), and used only to finish.

The result is accepted only where it is a KKT point of the inequality-constrained
problem within the tolerance: two Newton corrections in a row within xtol·(1 + size),
the last with its rounding floor (the largest change of that correction when every
unknown moves by one unit in the last place, over three random directions), every
active multiplier z ≥ 0 and every dropped inequality c ≤ that tolerance times
min(1, ‖∇c‖). Anything else — a wrong active set, dependent active constraints,
corrections that wander with rounding — returns None and leaves the interior point's
verdict. At a vertex — more active rows than the nodes they fix, dependent, the KKT matrix
exactly singular (the double integrator's minimum time at even N, every window on its
bound) — the active row of least multiplier is dropped once: it holds as an equality
anyway, and the multipliers returned are then one point of a family, all within the
tolerance of KKT (the path and horizon are unique: the same to 1e-16 from every start).
(Those three safeguards answer false successes found by a hunt: a keep-out
disc of radius 0.01 dropped while violated by 3e-9, its node 60 tolerances from the
optimum; and the cart-pole's multipliers of two adjacent track windows 4 tolerances
from the KKT point, accepted on one lucky correction and one lucky floor.)
"""
from __future__ import annotations

import numpy as np

from ..core.memory import AddressSpaceCap
from ..core.paths import Path
from .barrier import BOUND_TOLERANCE
from ..bvp.newton import NOISE

# The most Newton steps per active set and the most active sets tried are the solve's
# options (``polish_steps``, ``polish_rounds``: :class:`.options.SolveOptions`, read from
# the interior point's). Between active sets, as in a primal active-set method, the
# inequalities whose multipliers are negative leave (else the dropped ones found violated
# join), and Newton starts from the last converged point; where Newton does not converge
# on that set, the single most extreme change is tried instead (the cart-pole swing-up at
# N = 700: of three track windows active at the interior point's iterate one leaves, and
# dropping two at once diverged; a warm start of the torque-limited slew at τ_max = 11 →
# 11.2 at N = 1000: a dozen windows leave).

#: The least z/s of the dropped rows added once where Newton on the active set z > s
#: fails and W is zero: rows the barrier has not decided (degenerate: z/s stays O(1) as
#: μ → 0, where an inactive row's falls as μ).
UNDECIDED = 0.1
#: Rounds of joining them, each with a threshold ten times lower (at N = 1600 the last
#: windows from the vertex had z/s = 0.37 and 0.014 at μ = 1e-12)
UNDECIDED_ROUNDS = 3

#: Newton on an active set stops where a correction fails to halve while above this
#: many tolerances: near the tolerance, rounding makes corrections wander (the slew at
#: xtol = 1e-12: 1.5e-12, 2.5e-12, 7.4e-13 about a tolerance of 2e-12, then converged).
WANDERING = 1e3

#: Random directions of the rounding floor (:func:`_floor`).
SAMPLES = 3


class Dependent(Exception):
    """The active-set KKT matrix is exactly singular: dependent active constraints."""


def polish(ip, path: Path, tolerance: float, active: np.ndarray | None = None):
    """(path, slacks, message, Newton steps) of the active-set Newton from the interior
    point ``ip``'s ``path`` (module docstring), starting with the inequalities ``active``
    (default: where z > s), or None where it does not end at a KKT point within
    ``tolerance``. ``ip``'s state is left as it was."""
    if ip.problem.gauge is not None:
        return None     # replaced rows of exactly dependent constraints: not this system
    active = (ip.z(path) > ip.s) if active is None else active
    total, single, weakest, undecided = 0, None, True, 0
    for _ in range(ip.options.polish_rounds):
        try:
            converged = _newton(ip, path, active, tolerance)
            dependent = False
        except Dependent:
            converged, dependent = None, True
        joined = None if converged is not None or single is not None \
            or undecided == UNDECIDED_ROUNDS else _undecided(ip, path, active, undecided)
        undecided += converged is None and single is None
        if joined is not None:
            single = joined
        elif dependent and single is None and weakest:
            # a vertex: the double integrator's minimum time at even N, every window on
            # its bound and one row too many — without the row of least multiplier,
            # which then holds as an equality anyway
            single = active.copy()
            z = np.where(active, ip.z(path), np.inf)
            single[np.unravel_index(int(np.argmin(z)), active.shape)] = False
            weakest = False
        if converged is None:
            if single is None:
                return None
            active, single = single, None
            continue
        path, steps, correction, floor = converged
        total += steps
        ineq = ip.inequalities
        if not ineq.evaluate(path, ip.problem.p, ip.problem.step(path), with_jacobian=True):
            return None
        z, c = ip.z(path), ineq.values
        leaving = active & (z < 0.0)
        # a dropped row violated by c lies about c/‖∇c‖ from the nodes that meet it: it
        # joins where that exceeds the tolerance, or c the bounds' own (a disc of radius
        # 0.01, ‖∇c‖ ≈ 0.02, once stayed dropped at c = 3e-9 < tolerance, its node 60
        # tolerances from the optimum, where its multiplier is 4.5e-5)
        norms = np.sqrt(ip.squared_gradients())
        joining = ~active & ((c > tolerance * np.minimum(1.0, norms))
                             | (ineq.relative() - ineq.rounding(path) > BOUND_TOLERANCE))
        if not (leaving.any() or joining.any()):
            return _accepted(ip, path, active, tolerance, total, correction, floor)
        extreme = np.where(active, z, np.inf) if leaving.any() else np.where(active, -np.inf, -c)
        single = active.copy()
        single[np.unravel_index(int(np.argmin(extreme)), active.shape)] ^= True
        active = active & ~leaving if leaving.any() else active | joining
        if (active == single).all():
            single = None
    return None


def _undecided(ip, path: Path, active: np.ndarray, round_: int) -> np.ndarray | None:
    """Without curvature of its own (pure minimum time, W = 0) the directions no active
    row fixes are free, and Newton wanders or the matrix is singular (at N = 10⁴, T 2 →
    5.4 → 1.3 → 20 with the switching windows' rows dropped): ``active`` with the rows
    the barrier leaves undecided (z/s ≥ :data:`UNDECIDED` / 10^``round_``), or None where
    W has curvature or there are none."""
    if ip.curved:
        return None
    ratio = ip.z(path) / ip.s
    undecided = ~active & (ratio >= UNDECIDED / 10.0 ** round_)
    for i, j in ip.model.info.intervals:    # of a bound's two sides, the likelier alone
        lower = ratio[:, i] < ratio[:, j]
        undecided[:, i] &= ~active[:, j] & ~lower
        undecided[:, j] &= ~active[:, i] & lower
    return active | undecided if undecided.any() else None


def sparse_lu(K):
    """SuperLU's factorisation of the square sparse matrix K, or None where K is
    singular: exactly (SuperLU's RuntimeError) or structurally, by an empty row or column,
    on which SuperLU reads an uninitialised pivot and crashes (xiaoyeli/superlu#33: the
    pure minimum-time double integrator at N = 10⁵ ended the process with a segmentation
    fault; SciPy's structural rank, which would catch every structural singularity, took
    minutes on the flyer's matrices, so the caller keeps other singular ones away); None
    too where its fill outgrows the memory available (:class:`.memory.AddressSpaceCap`),
    which would have the process killed."""
    from scipy.sparse import csc_matrix
    from scipy.sparse.linalg import splu

    K = csc_matrix(K, copy=True)
    K.eliminate_zeros()
    empty_column = (np.diff(K.indptr) == 0).any()
    empty_row = (np.bincount(K.indices, minlength=K.shape[0]) == 0).any()
    if empty_column or empty_row:
        return None
    try:
        with AddressSpaceCap():
            return splu(K)
    except RuntimeError:        # exactly singular
        return None
    except MemoryError:         # its fill past the memory available: no step from here
        return None


def both_sides(model, active: np.ndarray) -> bool:
    """Whether ``active`` holds both sides of a bound in some window (``ModelInfo.
    intervals``): their gradients are opposite, the KKT matrix singular — and SuperLU
    crashed on one such (a hunt: |u| ≤ 0.01 at N = 12, rank 22 of 27) rather than
    raising."""
    return any((active[:, i] & active[:, j]).any() for i, j in model.info.intervals)


def _newton(ip, path: Path, active: np.ndarray, tolerance: float):
    """(path, steps, correction, floor) where Newton on the KKT system of the active set
    ``active`` (as equalities, the other multipliers 0) from ``path`` converged within
    ``tolerance`` with its rounding floor; else None."""
    problem = ip.problem
    path = path.copy()
    path.lam[:, ip.s_count:] = np.where(active, ip.z(path), 0.0)
    within = False      # whether the last correction was within the tolerance
    previous = np.inf
    for step in range(ip.options.polish_steps):
        ip.active_set_steps += 1
        newton = _correction(ip, path, active)
        if newton is None:
            return None
        delta, dz, solve = newton
        correction = max(problem.correction_norm(delta, path),
                         float(np.abs(dz).max(initial=0.0)))
        # two in a row: where rounding dominates, the corrections wander rather than
        # fall, and one of them within the tolerance is luck (the cart-pole at N = 700:
        # corrections between 1.4e-7 and 9.3e-7 about a tolerance of 1.6e-7)
        # the active rows hold at path too (barrier.BOUND_TOLERANCE), whatever the
        # tolerance; a dropped one that does not joins in polish()
        if within and correction <= tolerance and ip.bounds_hold(path, active):
            floor = _floor(ip, path, active, delta, dz, solve)
            # and shrinking, or rounding's noise: a correction that did not shrink
            # estimates no error (a hunt: a free horizon's T = 0.032 for T* = 2.06 at
            # xtol = 1e-2, two corrections of 7.9e-3 in a row)
            shrinking = correction <= previous / 2 or correction <= NOISE * floor
            if shrinking and correction + floor <= tolerance:
                return path, step, correction, floor
        if correction > max(previous / 2, WANDERING * tolerance):
            # not converging, far above rounding's level: not this active set's
            # neighbourhood (a wrong set wandered over all its steps, each counted
            # among the iterations)
            return None
        within, previous = correction <= tolerance, correction
        moved = problem.moved(path, delta, 1.0)
        if moved is None:
            return None
        moved.lam[:, ip.s_count:][active] += dz
        path = moved
    return None


def _correction(ip, path: Path, active: np.ndarray):
    """(Δ in the block layout, Δz of the active rows, solve) of the active-set Newton step
    at ``path`` — ``solve(rhs)`` applies the factorised matrix's inverse, refined once —
    or None where something is not finite; :class:`Dependent` where the matrix is
    exactly singular."""
    from scipy.sparse import bmat, csr_matrix, dia_matrix, hstack

    problem, ineq = ip.problem, ip.inequalities
    if both_sides(ip.model, active):
        raise Dependent
    res, ab, bw, finite = problem.assemble(path, True)
    if not (finite and ineq.evaluate(path, problem.p, problem.step(path), with_jacobian=True)):
        return None
    size = ab.shape[1]
    J = dia_matrix((ab[bw:], bw - np.arange(2 * bw + 1)), shape=(size, size))
    G = block_jacobian(ip, active)
    rows = G.shape[0]
    K = bmat([[J, G.T], [G, csr_matrix((rows, rows))]], format="csc")
    # more active rows than nodes: singular (pure minimum time without T's column), which
    # SuperLU met with a segmentation fault at N = 50
    lu = sparse_lu(K) if rows <= size else None
    apply = None if lu is None else lu.solve
    rates = problem.inequality_rates(path)
    if rates is not None:       # a free horizon: W's border, and ∂c/∂T of the active rows
        b, d = problem.raw
        J = bmat([[J, csr_matrix(b[:, None])], [csr_matrix(b[None, :]), csr_matrix([[d]])]])
        G = hstack([G, csr_matrix(rates[active][:, None])])
        K = bmat([[J, G.T], [G, csr_matrix((rows, rows))]], format="csc")
        apply = _bordered(apply, np.concatenate([b, rates[active]]), d, size)
        size += 1
    if apply is None and rates is not None:
        # the horizon's row and column factorised with the rest, where the matrix without
        # them is singular (pure minimum time: its active rows fix the nodes only with T)
        lu = sparse_lu(K)
        apply = None if lu is None else lu.solve
    if apply is None:           # singular: dependent active constraints
        raise Dependent

    def solve(rhs: np.ndarray) -> np.ndarray:
        x = apply(rhs)
        return x + apply(rhs - K @ x)       # one refinement: SuperLU pivots by threshold

    x = solve(-np.concatenate([res, ineq.values[active]]))
    if not np.isfinite(x).all():
        return None
    return x[:size], x[size:], solve


def _bordered(inner_solve, column: np.ndarray, corner: float, at: int):
    """The solve of [[K₀, u], [uᵀ, d]] (u = ``column``, d = ``corner``) with the bordering
    unknown and row at index ``at`` (T, between the nodes and the multipliers), from
    K₀'s (``inner_solve``, None where K₀ is singular): its Schur complement
    d − uᵀK₀⁻¹u, so that SuperLU never factorises the dense row and column (a sparse
    ordering's worst case; that it saves memory on the minimum-time slew is not
    measured: the 24 GB fill at N = 10⁵ was pure minimum time's full matrix, which this
    cannot border); None where K₀ or the Schur complement is singular."""
    if inner_solve is None:
        return None
    w = inner_solve(column)
    schur = corner - float(column @ w)
    if not np.isfinite(schur) or schur == 0.0:
        return None

    def apply(rhs: np.ndarray) -> np.ndarray:
        y = inner_solve(np.concatenate([rhs[:at], rhs[at + 1:]]))
        last = (float(rhs[at]) - float(column @ y)) / schur
        x = y - w * last
        return np.concatenate([x[:at], [last], x[at:]])
    return apply


def block_jacobian(ip, active: np.ndarray):
    """G_𝒜 in the block layout of the reduced system: the active rows' gradients with
    respect to the free nodes' corrections (:attr:`.barrier.Inequalities.jacobian`)."""
    from scipy.sparse import csr_matrix

    model, ineq = ip.model, ip.inequalities
    n, r = model.n, model.order
    position = np.full(ineq.n_nodes, -1)
    position[ip.blocks] = np.arange(len(ip.blocks)) * ip.width
    position[:r] = -1                                       # fixed nodes do not move
    if not model.end_free:
        position[ineq.n_nodes - r:] = -1
    windows, which = np.nonzero(active)
    row_of = np.arange(len(windows))
    rows, cols, vals = [], [], []
    for j in range(r + 1):
        at = position[windows + j]
        free = at >= 0
        rows.append(np.repeat(row_of[free], n))
        cols.append((at[free][:, None] + np.arange(n)).ravel())
        vals.append(ineq.jacobian[windows[free], which[free], j * n:(j + 1) * n].ravel())
    size = len(ip.blocks) * ip.width + model.end_count
    return csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(len(windows), size))


def _floor(ip, path: Path, active: np.ndarray, delta: np.ndarray, dz: np.ndarray,
           solve) -> float:
    """The largest ‖·‖∞ of the change in the active-set correction when every node, λ and
    active z moves by one unit in the last place, over :data:`SAMPLES` random directions:
    the residual's noise through the same factorised matrix ``solve`` (as the equality
    solver's :meth:`.assembly.Problem.rounding_correction`). More than one direction: on
    nearly dependent active rows (the cart-pole's track limit at adjacent windows,
    N = 700) eight gave 7e-9 to 5.1e-7, and the first alone 1.1e-7."""
    problem, ineq, eps = ip.problem, ip.inequalities, np.finfo(float).eps
    floor = 0.0
    for seed in range(SAMPLES):
        rounded, rng = problem.rounded(path, seed)
        if rounded is None:
            return np.inf
        rounded.lam[:, ip.s_count:][active] *= 1.0 + eps * rng.choice((-1.0, 1.0), dz.size)
        res, _, _, finite = problem.assemble(rounded, False)
        if not (finite and ineq.evaluate(rounded, problem.p, problem.step(rounded))):
            return np.inf
        other = solve(-np.concatenate([res, ineq.values[active]]))
        floor = max(floor, problem.correction_norm(other[:delta.size] - delta, path),
                    float(np.abs(other[delta.size:] - dz).max(initial=0.0)))
    return floor


def _accepted(ip, path: Path, active: np.ndarray, tolerance: float, steps: int,
              correction: float, floor: float):
    """(path, slacks, message, steps) at ``path``, a KKT point of the bounded problem within
    ``tolerance`` (z ≥ 0 on the active rows, c ≤ tolerance·min(1, ‖∇c‖) on the others,
    the inequalities evaluated there)."""
    c, z = ip.inequalities.values, ip.z(path)
    # slacks consistent with the active set, for the result's `active` (z > s)
    slacks = np.where(active, np.minimum(np.maximum(-c, 0.0), 0.5 * z), np.maximum(-c, 0.0))
    primal = float(np.maximum(c, 0.0).max(initial=0.0))
    return path, slacks, (
        f"; finished by {steps} active-set Newton step{'s' if steps != 1 else ''} on the "
        f"{int(active.sum())} active inequalities: Newton correction of the KKT system "
        f"(μ = 0) {correction:.1e}, rounding floor {floor:.1e}, within xtol·(1 + size) = "
        f"{tolerance:.1e}, primal infeasibility {primal:.1e}"), steps
