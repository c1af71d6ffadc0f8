"""Check ``structure``: the discrete flow preserves the symplectic or Poisson structure.

Paper §4.3 (Theorem ``propositiongroupoids1``) and Appendix B: the discrete Hamiltonian
evolution operator F⁺L_d∘(F⁻L_d)⁻¹ preserves the linear Poisson structure of A*G (first
order, Marrero, Martín de Diego & Martínez) or of A*(P^αG) (second order). This check
verifies it numerically for the *step map* symvi actually derives — the one the generated
code iterates — not for the Legendre transforms alone: at random sample points it

1. solves the step residual R(s, f_new) = 0 (kernel ``step``) for the last element by
   Newton from the kernel ``predict``;
2. differentiates the step map Φ: s ↦ s' (s = the 2r−1 elements of the state, s' the
   state one element later) by the implicit function theorem, ∂f_new/∂s =
   −(∂R/∂f_new)⁻¹ ∂R/∂s, with ∂R/∂z exact (forward-mode differentiation of the symbolic
   kernel, chain rule through its named base points) and the new base point
   x₁ = β(x₀, f₀) differentiated through the kernel ``target``;
3. builds Hamiltonian coordinates y = Λ(s) from F⁻L_d (kernel ``momentum_minus``; for an
   order r ≥ 3 the reduced T*(H^r) of the first r nodes, :meth:`StepMap.legendre`), pulls
   the Poisson tensor Π(y) back to the state, Π_s = DΛ⁻¹ Π DΛ⁻ᵀ, and checks that Φ is a
   Poisson map, DΦ Π_s(s) DΦᵀ = Π_s(s') (:func:`poisson_defect`) — equivalently
   N Π(y) Nᵀ = Π(y') for N = DΛ(s')·DΦ·DΛ(s)⁻¹, and NᵀJN = J where Π is symplectic.

A residual that is not the variational one (a hand-written force term, an explicit
Euler–Poincaré step, a non-symmetric quadrature) gives a step map that still runs and may
even look accurate, but moves y off the Poisson structure; this is what the check catches.
It does not catch a residual whose Euler–Poincaré signs are swapped (ERRATA.md item 7):
that residual is F⁻L_d(g_k) = F⁺L_d(g_{k+1}), the *inverse* of the correct map, which
is Poisson too — the check ``consistency`` catches it (its O(h) term has the wrong sign).

The coordinates y and the structure Π for each kind of groupoid and order are in
:mod:`symvi.checks.stepmap`, which implements steps 1–3 (:class:`StepMap`).

Tolerance: the defect D = DΦ Π_s DΦᵀ − Π_s' is measured normwise, ‖D‖ relative to
‖DΦ‖²‖Π_s‖ + ‖Π_s'‖ (Frobenius), in state coordinates — nodes and ξ, O(1) at the sample
points, whereas the Hamiltonian coordinates mix scales (the momenta of a second-order
model are O(h⁻³) times the positions at h = 0.1, and an entry-by-entry comparison there
sees the rounding of the large entries in the small ones). Every bundled model gives
1e-17…1e-16 at h = 0.1 (rounding only). The broken maps tried give 1e-3…1e-2 at first
order (a non-variational force term h²V′(q₀), an explicit Euler–Poincaré step, the
structure with the other relative sign) and ~1e-6 at second order (a force term h⁴V′(q₀)
at one node of the fourth difference: the defect is O(h⁴V″)). :data:`TOLERANCE` = 1e-9
leaves 7 orders for rounding amplified by an ill-conditioned ∂R/∂f_new and 3 below the
weakest defect seen.

Order r ≥ 3 (issue 25): a non-variational term moves the step only by its size times
h^{2r−1} (the residual's leading coefficient is O(h^{1−2r})), and ‖DΦ‖ grows like the
binomial coefficients of the 2r-th difference, so the defect of a consistent force term
h·f(x₀) is 1e-9 (r = 3), 1e-12 (r = 4) and below rounding (r = 6) at h = 0.1. These
orders are therefore sampled at :data:`HIGH_ORDER_STEPS` (h = 0.5 first, then 0.1, 0.01
if no step can be solved) against :data:`HIGH_ORDER_TOLERANCE` = 1e-11: correct models
of orders 3–6 (pair, SO(3), SE(3), products, a stiff pair model) give 1e-17…4e-15 at
h = 0.5 (≤ 6e-14 at h = 0.1), the force term h·f(x₀) 1e-5…2e-5 (r = 3), 3e-7…1e-6
(r = 4), 7e-9…1e-8 (r = 5), 1e-10…4e-10 (r = 6).

Skipped: constrained (optimal-control) models — they are solved as whole trajectories
with multipliers and have no step map; groupoid kinds other than pair, Lie group, action
groupoid and their products.
"""
from __future__ import annotations

import numpy as np

from ..groupoids.base import Groupoid, subscript
from .report import CheckResult
from .stepmap import (STEP, Defect, StepMap, canonical_poisson, linear_poisson,
                      poisson_defect, symplectic_defect)

__all__ = ["NAME", "TOLERANCE", "HIGH_ORDER_STEPS", "HIGH_ORDER_TOLERANCE", "STEP", "SAMPLES",
           "Defect", "StepMap", "canonical_poisson", "linear_poisson", "poisson_defect",
           "symplectic_defect", "structure_name", "sample_defects", "run"]

NAME = "structure"
#: Of the Lagrangian's step map: skipped in pure minimum time (:mod:`.runner`).
OF_THE_LAGRANGIAN = True
#: Largest relative defect accepted (see the module docstring).
TOLERANCE = 1e-9
#: Orders r ≥ 3: the steps tried, and the largest relative defect accepted (docstring).
HIGH_ORDER_STEPS = (0.5, STEP, STEP / 10)
HIGH_ORDER_TOLERANCE = 1e-11
#: Number of sample points.
SAMPLES = 3


def structure_name(groupoid: Groupoid, order: int) -> str:
    """The structure the step map of ``order`` on ``groupoid`` preserves, for messages."""
    return groupoid.preserved_structure(order)


def state_text(order: int) -> str:
    """The state (x₀, f₀, …, f_{2r−2}) of the step map of ``order``."""
    if order <= 2:
        return "(x₀, f₀)" if order == 1 else "(x₀, f₀, f₁, f₂)"
    return f"(x₀, f₀, …, f{subscript(2 * order - 2)})"


def sample_defects(step: StepMap, rng: np.random.Generator, samples: int = SAMPLES
                   ) -> tuple[list[tuple[np.ndarray, Defect]], int]:
    """Defects at ``samples`` random states where the step can be solved, and the number
    of states tried (at most 4·samples)."""
    found, attempts = [], 0
    while len(found) < samples and attempts < 4 * samples:
        attempts += 1
        s = step.sample(rng)
        with np.errstate(all="ignore"):
            try:
                d = step.defect(s)
            except np.linalg.LinAlgError:
                d = None
        if d is not None and np.isfinite(d.relative):
            found.append((s, d))
    return found, attempts


def run(ctx) -> CheckResult:
    """The check ``structure`` on ``ctx.model`` (see the module docstring)."""
    g = ctx.model.groupoid
    dm = ctx.discrete
    if dm.constraints:
        return CheckResult.skipped(
            NAME, "constrained (optimal-control) model: it is solved as a whole trajectory "
                  "with multipliers and has no step map whose Jacobian could be checked")
    if not g.structure_check:
        return CheckResult.skipped(
            NAME, f"{g!r} has no Poisson structure implemented here (pair, Lie group, "
                  f"action groupoid and their products only)")
    derived = ctx.derived
    rng = np.random.default_rng(ctx.seed)
    tried = 0
    steps, tolerance = ((STEP, STEP / 10), TOLERANCE) if dm.order <= 2 else \
        (HIGH_ORDER_STEPS, HIGH_ORDER_TOLERANCE)
    for h in steps:
        # A stiff model may have no step from the predictor at h = 0.1: try a tenth.
        step = StepMap(derived, g, h)
        defects, attempts = sample_defects(step, rng)
        tried += attempts
        if defects:
            break
    else:
        return CheckResult.failed(
            NAME, f"the step could not be solved at any of {tried} sample points (Newton "
                  f"from the predictor did not converge, h = "
                  f"{', '.join(f'{h:g}' for h in steps[:-1])} and {steps[-1]:g})")
    names, what = step.state_names(), structure_name(g, dm.order)
    state = state_text(dm.order)
    failures = [f"at the sample point s = {state} = "
                f"{np.array2string(s, precision=6, separator=', ')} (h = {h:g}): "
                f"{d.describe(names)}" for s, d in defects if d.relative > tolerance]
    worst = max(d.relative for _, d in defects)
    data = dict(structure=what, h=h, tolerance=tolerance,
                defects=[d.relative for _, d in defects],
                defect_norms=[d.norm for _, d in defects], max_defect=worst)
    if failures:
        return CheckResult.failed(
            NAME, f"the step map does not preserve the {what}: relative defect "
                  f"{worst:.2e} > {tolerance:.0e} at {len(failures)} of {len(defects)} "
                  f"sample points", failures, **data)
    return CheckResult.passed(
        NAME, f"the step map preserves the {what} at {len(defects)} sample points "
              f"(h = {h:g}, relative defect ≤ {worst:.1e})", **data)
