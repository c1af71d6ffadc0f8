"""Check ``noether``: declared symmetries leave L_d invariant or quasi-invariant (paper §4.4,
Theorem ``teoremanoethergroupoids``).

For each :class:`~symvi.declaration.symmetry.Symmetry` Z of the model, the change of one window's L_d
when every node moves along Z, minus the potential difference, must vanish identically
(:func:`symvi.derivation.derive.invariance_defect`). It is evaluated at random points with the
window's base points computed exactly; on failure the defect is simplified symbolically to
name the offending terms. The conserved F_Z itself is compiled as the ``noether`` kernel
(``StepResult.noether``). For optimal-control models with variational equations the
symmetries without actuated components are checked on the first-order L_d of the
mechanical Lagrangian: the solver drops one constraint component per such symmetry
(:mod:`symvi.declaration.control`), which is right only when the invariance is exact.
"""
from __future__ import annotations

import numpy as np
import sympy as sp

from ..derivation.derive import invariance_defect
from ..discretisation.discretise import mechanical_model
from ..declaration.rank import sequential_lambdify
from .report import CheckResult
from .series import _Expander, expansion_scope

NAME = "noether"
#: Relative size of the defect, against the sum of the magnitudes of its terms, below which
#: it is rounding: the terms are O(1) sums of a few products at h = 0.1.
TOLERANCE = 1e-11
_SAMPLES = 5


def readable(window, groupoid) -> dict:
    """Stencil symbol → the groupoid's discrete symbol for it (``theta_1``, ``Omega2_0``):
    names for messages."""
    mapping = groupoid.discrete_mapping(len(window.fs), window.xs, window.fs)
    return {v: k for k, v in mapping.items() if isinstance(v, sp.Symbol)}


def defect_samples(dm, symmetry, seed: int, samples: int = _SAMPLES) -> list[tuple[float, float, dict]]:
    """(defect, scale, sample point) at random points of one window, h = 0.1."""
    terms, window = invariance_defect(dm, symmetry)
    names = readable(window, dm.groupoid)
    fixed = dict(zip(dm.parameters, dm.defaults)) | {dm.step: 0.1}
    args = list(window.z) + list(fixed)
    evaluate = sequential_lambdify(args, window.definitions, sp.Matrix(terms))
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(samples):
        z = rng.uniform(-0.7, 0.7, len(window.z))
        values = np.array(evaluate(*z, *fixed.values()), dtype=float).ravel()
        out.append((float(values.sum()), float(np.abs(values).sum()),
                    {str(names.get(s, s)): round(float(v), 6) for s, v in zip(window.z, z)}))
    return out


@expansion_scope
def leading_defect(dm, symmetry) -> sp.Expr:
    """The lowest-order term in h of δL_d − Δf, simplified: the continuous defect, which
    names the terms of the Lagrangian that break the symmetry. Found by the checks'
    Laurent series in h (:mod:`.series`), which expands the window's base points on
    demand and the exponential's coefficients through their Taylor series (cancelling
    the substituted defect and setting h = 0 took one cancellation per trial power and
    gave 0/0 for the exponential)."""
    terms, window = invariance_defect(dm, symmetry)
    defect = sp.Add(*terms)
    expander = _Expander(dm.step, {}, dict(window.definitions))
    power = expander.true_order(defect)
    lead = sp.simplify(expander.series(defect, power).coefficient(power))
    return (lead * dm.step**power).xreplace(readable(window, dm.groupoid))


def run(ctx) -> CheckResult:
    model = ctx.model
    if not model.symmetries:
        return CheckResult.skipped(NAME, "the model declares no symmetries")
    dm, symmetries = ctx.discrete, model.symmetries
    if model.constraints:
        system = model.control_system
        if system is None or system.equations != "variational" or not dm.gauges:
            return CheckResult.skipped(NAME, "constrained models: Noether symmetries of "
                                             "L_d + λΦ_d are not checked")
        # the symmetries the solver relies on: exact for the first-order L_d of L
        dm = mechanical_model(model)
        symmetries = dm.symmetries
    details, data = [], {}
    for z in symmetries:
        samples = defect_samples(dm, z, ctx.seed)
        worst = max(samples, key=lambda s: abs(s[0]) / max(s[1], 1e-300))
        relative = abs(worst[0]) / max(worst[1], 1e-300)
        kind = "quasi-invariant" if z.potential != 0 else "invariant"
        data[z.name] = {"relative_defect": relative, "kind": kind}
        if relative > TOLERANCE:
            details.append(f"{z.name}: L_d is not {kind} under Z = {list(z.section)}: "
                           f"δL_d − Δf = {worst[0]:.3e} (relative {relative:.1e}) at "
                           f"h = 0.1, {worst[2]}")
            details.append(f"  leading term: δL_d − Δf = {leading_defect(dm, z)} + …")
    names = ", ".join(z.name for z in symmetries)
    if details:
        return CheckResult.failed(NAME, f"symmetry not exact: {names}", details, **data)
    worst = max(d["relative_defect"] for d in data.values())
    use = ("F_Z compiled as the noether kernel" if not model.constraints else
           "exact dependencies of the constraints, removed by the solver")
    return CheckResult.passed(NAME, f"{len(symmetries)} symmetr"
                                    f"{'y' if len(symmetries) == 1 else 'ies'} "
                                    f"({names}): exact, relative defect ≤ {worst:.1e}; "
                                    f"{use}", **data)
