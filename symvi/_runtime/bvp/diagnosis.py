"""Why a whole-trajectory solve with constraints failed, where the constraints themselves
are the cause (issue 22, item 5).

An underactuated optimal-control problem carries the constraints Φ^A_d = 0 of the
directions A no control acts on (paper §3.3.2). Newton's method fails on them in two
ways that a user cannot tell from a stalled line search:

- **Dependent constraints.** A symmetry Z of L with no actuated component makes
  Σ_k Z(x_k)·Φ^k_d telescope to boundary terms (Noether's theorem; exactly with
  ``equations="variational"``, to O(h⁴) with the paper's rule): the rows of A = ∂Φ_d/∂η
  are dependent, the multipliers are not determined, and the Newton matrix is singular
  at every N. The remedy is to declare Z, which fixes the multipliers' freedom
  (:mod:`.gauge`).
- **Constraints that cannot be met.** Where such a combination uᵀΦ_d has no gradient
  (uᵀA = 0) but a value that is not zero, no Newton step changes it: the linearised
  constraints have no solution. Where its gradient is merely small, meeting it to first
  order takes a correction far larger than the path — the end conditions ask for motion
  along directions no control produces (a torque-only body asked to translate).

Both are read from the singular value decomposition of A at the path the solve
returned: dense, so only up to :data:`DENSE_LIMIT` unknowns (at N ≈ 1000 for three
fibre directions), which covers the few steps one tries first.

A combination without gradient may be the path's and not the problem's (issue 53): a
nonholonomic constraint ẏ cos θ − ẋ sin θ = 0 has no gradient toward a sideways
displacement where the path is at rest with θ constant, as on the straight line between
two parked poses of a unicycle — yet parking sideways is feasible, by driving while
turning. So an inconsistent dependency among such constraints (not an optimal-control problem's
unactuated directions) is looked for again at the path with its free nodes varied
(:meth:`~.assembly.Problem.perturbed`): where it is gone there, the message blames the
path (give a guess that moves along the allowed directions), not the end conditions;
where it stays (a cart on a rail asked off it: Σ_k (y_{k+1} − y_k) = y_N − y_0 at every
path), the end conditions ask for motion the constraints forbid. The unactuated
directions' dependencies are not varied: they are the problem's (Noether's telescoping
sum, exact with the variational equations), but with the paper's rule only to O(h⁴), so
that at a varied path they are merely ill-conditioned (the torque-only body asked to
translate: a reach of 15 where the straight path has none).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .optimality import _sparse
from ..core.paths import Path, fibres

#: Most node unknowns for which the dense SVD of A is computed (O(rows · columns²)).
DENSE_LIMIT = 3000
#: A singular value of A within this factor of its largest is rounding: a dependency.
DEPENDENT = 1e-9
#: uᵀΦ_d of a dependency within this factor of A's scale times the path's size is
#: rounding (ε·‖A‖·|path| is the noise in Φ_d itself, 10⁸ on top for the sum's terms).
NOISE = 1e8 * np.finfo(float).eps
#: A first-order correction of the constraints this many times the path's size (in
#: the directions of A's smallest singular values) counts as one they cannot make.
UNATTAINABLE = 10.0


@dataclass(frozen=True)
class ConstraintDiagnosis:
    """What A = ∂Φ_d/∂η says at a failed path (module docstring)."""

    #: Number of exact dependencies among the constraint rows (rank deficiency of A).
    dependent: int
    #: Largest |uᵀΦ_d| over the dependencies u: zero (to rounding) if consistent.
    inconsistency: float
    #: The first-order correction the constraints need along A's weakest directions,
    #: over the path's size (∞ for an inconsistent dependency).
    reach: float
    #: The constraints (unactuated directions) that the weakest combinations involve.
    involved: tuple[str, ...]
    #: The boundary data's motion along those directions: (name, start-to-end mean
    #: velocity, velocity at the start, velocity at the end), its components not all 0.
    motion: tuple[tuple[str, float, float, float], ...]
    #: Whether the inconsistent dependency is this path's only (gone at the path varied:
    #: True), the problem's (False), or was not looked for again (None).
    degenerate: bool | None = None

    @property
    def unattainable(self) -> bool:
        return self.reach > UNATTAINABLE

    def describe(self, N: int, h: float) -> str:
        """The finding and its remedy, for a failed result's message."""
        if self.involved and all(n.startswith("end condition ") for n in self.involved):
            return self._end_conditions()
        plural = "s" if len(self.involved) > 1 else ""
        subject = self._subject
        if self.degenerate:
            return (f"; at this path {subject} {'have' if plural else 'has'} no gradient "
                    f"along a combination whose value ({self.inconsistency:.3g}) the end "
                    f"conditions ask to change, but {'they have' if plural else 'it has'} "
                    f"one once the path's free nodes are varied by 1e-2: the path, not the "
                    f"problem, is degenerate — a nonholonomic constraint has no gradient "
                    f"toward the motion it forbids where the path is at rest or moves "
                    f"straight across it, as a straight line between the ends does. Give "
                    f"solve_bvp a guess that already moves along the allowed directions "
                    f"(for a wheeled vehicle moved sideways: driving while turning, forward "
                    f"then back)")
        if self.unattainable:
            varied = ", nor at the path varied" if self.degenerate is False else ""
            how = (f"cannot be met to first order: {'a combination of them has' if plural else 'it has'} "
                   f"no gradient at this path but the value {self.inconsistency:.3g}"
                   f"{varied}" if np.isinf(self.reach) else
                   f"can be met to first order only by a correction {self.reach:.3g} times "
                   f"the path's size")
            remedy = ("Change the end conditions or actuate these directions"
                      if self.controlled else "Change the end conditions: no path that "
                      "keeps these constraints joins them")
            return (f"; {subject} {how} — the end conditions ask for motion that "
                    f"{self._produced}{self._motion(N * h)}. {remedy}")
        return (f"; {subject} {'are' if plural else 'is'} dependent ({self.dependent} "
                f"combination{'s' if self.dependent > 1 else ''} of them without gradient "
                f"at this path): no path between these ends changes those combinations, "
                f"the boundary data fix them, their multipliers are not determined and the "
                f"Newton matrix is singular at every N. A symmetry of L that no control "
                f"acts on does this (Noether: Σ_k Z(x_k)·Φ_d^k telescopes to the ends). "
                f"Where Z is a section of the algebroid (constant on a Lie group, a "
                f"function of the base point on an action groupoid), declare it — "
                f"optimal_control(..., symmetries=[Symmetry(name, section)], "
                f"equations=\"variational\") — and the solver fixes the multipliers' "
                f"freedom; otherwise leave the directions no control reaches out of the "
                f"model")

    def _end_conditions(self) -> str:
        """The finding when only end conditions ψ are involved."""
        names = ", ".join(n.removeprefix("end condition ") for n in self.involved)
        if self.unattainable:
            why = (f"a combination of them has no gradient here but the value "
                   f"{self.inconsistency:.3g}" if np.isinf(self.reach) else
                   f"a correction {self.reach:.3g} times the path's size would be needed")
            return (f"; the end conditions {names} cannot be met to first order from this "
                    f"path ({why}): give solve_bvp a guess of the last nodes (`end=`) where "
                    f"ψ has a gradient, or check that ψ = 0 has a solution")
        return (f"; the end conditions {names} are dependent ({self.dependent} combination"
                f"{'s' if self.dependent > 1 else ''} without gradient): remove the "
                f"redundant ones")

    @property
    def _subject(self) -> str:
        """What is involved, as a message's subject: "the constraints of the unactuated
        directions v1, v2", "constraint 2", "constraints 1, 3"."""
        plural = "s" if len(self.involved) > 1 else ""
        if self.controlled:
            return (f"the constraint{plural} of the unactuated direction{plural} "
                    f"{', '.join(self.involved)}")
        numbers = [n.removeprefix("constraint ") for n in self.involved]
        return f"constraint{plural} {', '.join(numbers)}"

    @property
    def controlled(self) -> bool:
        """Whether the constraints involved are unactuated directions of optimal control."""
        return not any(n.startswith(("constraint ", "end condition ")) for n in self.involved)

    @property
    def _produced(self) -> str:
        return "no control produces" if self.controlled else "the constraints forbid"

    def _motion(self, T: float) -> str:
        if not self.motion:
            return ""
        parts = "; ".join(f"{name}: mean {mean:.3g} over T = {T:.3g}, {a:.3g} at the start, "
                          f"{b:.3g} at the end" for name, mean, a, b in self.motion)
        return f" (the boundary data's velocities along them — {parts})"


def diagnose(problem, path: Path, vary: bool = True) -> ConstraintDiagnosis | None:
    """The :class:`ConstraintDiagnosis` of ``path``, or None where it finds nothing (no
    dependency, no unattainable correction), the model has no constraints or declared
    gauges, or A is too large to decompose densely. With ``vary``, an inconsistent
    dependency is looked for again at the path varied (module docstring)."""
    model = problem.model
    rows = problem.constraint_rows(path) if model.constraints or model.end_count else None
    if rows is None or model.info.gauges or (~rows).sum() > DENSE_LIMIT:
        return None
    res, ab, bw, finite = problem.assembled(path)
    if not finite:
        return None
    J = _sparse(ab, bw)
    # the band's rows (a free horizon's T follows them: .bordered)
    rows, res = rows[:ab.shape[1]], res[:ab.shape[1]]
    A = J[rows][:, ~rows].toarray()
    # rows without node entries and a 1 on the diagonal pin the multipliers of a free
    # end's missing window; an end condition without gradient stays (a finding)
    kept = (np.abs(A).sum(axis=1) > 0) | (J.diagonal()[rows] != 1.0)
    U, s, _ = np.linalg.svd(A[kept], full_matrices=False)
    if not s.size:
        return None
    values = U.T @ res[rows][kept]
    # the nodes' scale, not the multipliers' (which a failing solve drives up)
    size = 1.0 + max(float(np.abs(path.x).max(initial=0.0)),
                     float(np.abs(path.g).max(initial=0.0)))
    scale = s[0] if s[0] > 0 else 1.0       # A = 0: every combination is without gradient
    dependent = s <= DEPENDENT * scale
    consistent = np.abs(values) <= NOISE * scale * size
    with np.errstate(divide="ignore"):
        reach = np.where(dependent, np.where(consistent, 0.0, np.inf),
                         np.abs(values) / np.where(dependent, 1.0, s)) / size
    weakest = dependent | (reach > UNATTAINABLE)
    if not weakest.any():
        return None
    inconsistency = float(np.abs(values[dependent & ~consistent]).max(initial=0.0))
    weight = np.zeros(kept.size)
    weight[kept] = (U[:, weakest] ** 2).sum(axis=1)
    names, involved = _involved(model, weight)
    found = ConstraintDiagnosis(int(dependent.sum()), inconsistency, float(reach.max()),
                                names, _motion(problem, path, involved, size))
    if vary and inconsistency > 0 and not model.end_count and not found.controlled:
        try:
            varied = diagnose(problem, problem.perturbed(path), vary=False)
        except ValueError:          # the varied path leaves a retraction's chart
            return found
        return replace(found, degenerate=varied is None or varied.inconsistency == 0
                       or varied.dependent < found.dependent)
    return found


def _involved(model, weight: np.ndarray) -> tuple[tuple[str, ...], list[int]]:
    """(names, indices) of the constraint components — then the end conditions — that
    carry at least 5 % of the combinations' ``weight`` (per constraint row)."""
    s, ends = model.constraints, model.end_count
    per_window = weight[:weight.size - ends].reshape(-1, s).sum(axis=0) if s else np.zeros(0)
    totals = np.concatenate([per_window, weight[weight.size - ends:]])
    names = list(model.info.constraint_names or [f"constraint {a + 1}" for a in range(s)])
    names += [f"end condition {name!r}" for name in model.info.end_conditions]
    chosen = [a for a in range(totals.size) if totals[a] >= 0.05 * totals.sum()]
    return tuple(names[a] for a in chosen), [a for a in chosen if a < s]


def _motion(problem, path: Path, involved: list[int], size: float) -> tuple:
    """Per involved unactuated direction of a group factor: the mean velocity of the
    element from the first node to the last over T, and the boundary elements'
    velocities, where one is not zero next to the nodes' scale ``size``. Only for optimal
    control, whose constraints are the unactuated directions in order
    (:attr:`ControlSystem.unactuated`)."""
    model = problem.model
    directions = model.info.unactuated
    if not directions:
        return ()
    N = path.x.shape[0] - 1
    ends = [0, N]
    chord = fibres(model, path.x[ends], path.g[ends], problem.p, N * problem.h,
                   lambda _: "the start-to-end element")
    if not isinstance(chord, np.ndarray):
        return ()
    out = []
    for a in involved:
        A = directions[a]
        if not model.step_scaled[A]:    # a pair factor's fibre is a node, not a velocity
            continue
        values = (float(chord[0, A]), float(path.f[0, A]), float(path.f[-1, A]))
        if max(map(abs, values)) > 1e-12 * size:
            out.append((model.info.constraint_names[a], *values))
    return tuple(out)
