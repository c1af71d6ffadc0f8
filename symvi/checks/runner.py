"""Run the derivation checks on a model (issue 5).

Each check is a module of this package with a function ``run(ctx: Context) ->
CheckResult``; :data:`CHECKS` lists them in the order they run. A check reads the model
and whatever it needs from the shared :class:`Context`, which derives the discrete model
once and caches it.
"""
from __future__ import annotations

import importlib
from dataclasses import replace
from functools import cached_property
from typing import Callable, Sequence

from ..derivation.derive import DerivedModel, derive
from ..discretisation.discretise import DiscreteModel, discretise
from ..errors import ModelError
from ..declaration.model import Model
from ..timing import announced
from .budget import DEFAULT_BUDGET, Budget
from .report import BUDGET_SKIPPED, CheckReport, CheckResult

#: A check running longer than this (seconds) is announced on ``progress``.
SLOW_CHECK = 5.0

#: name → what it checks (paper reference), in running order.
CHECKS: dict[str, str] = {
    "algebroid": "structure equations of the Lie algebroid and closure of the Lie algebra "
                 "(Appendix C.1, eqs. estruc1, estruc2)",
    "routes": "Lagrangian submanifold Σ_{L_d} and the variational residual give one dynamics "
              "(§4.2, Theorems teoremagroupoides1, teoremagroupoides2)",
    "consistency": "order in h at which the discrete residual approximates the continuous "
                   "Euler–Lagrange (Euler–Poincaré) equations (DESIGN.md §5)",
    "regularity": "the Jacobian defining the step map (D₁₂L_d, D₁₃L_d, group analogues) is "
                  "generically non-singular (§4.3)",
    "noether": "declared symmetries leave L_d invariant or quasi-invariant; conserved F_Z "
               "(§4.4, Theorem teoremanoethergroupoids)",
    "structure": "the discrete flow preserves the symplectic form (pair groupoid) or the "
                 "Poisson structure (Lie groups) at sample points (§4.3)",
    "equations": "hand-derived equations are equivalent to the derived ones up to rescaling "
                 "and recombination (ERRATA.md)",
}


class Context:
    """What the checks share: the model, user inputs and the cached derivation.

    Parameters
    ----------
    model:
        The model to check.
    equations:
        Hand-derived equations to compare with symvi's (check ``equations``).
    seed:
        Seed of the random sample points numerical checks use (results are reproducible).
    budget:
        The time budget of each check (:class:`.budget.Budget`).
    """

    def __init__(self, model: Model, equations: Sequence = (), seed: int = 20261121,
                 budget: Budget | None = None):
        self.model = model
        self.equations = tuple(equations)
        self.seed = seed
        self.budget = budget if budget is not None else Budget()

    @cached_property
    def discrete(self) -> DiscreteModel:
        return discretise(self.model)

    @cached_property
    def derived(self) -> DerivedModel:
        """The derived kernels; raises ModelError when the model is not regular."""
        return derive(self.discrete)

    @property
    def parameter_values(self) -> dict:
        """Parameter symbol → default value."""
        return dict(self.model.parameters)


def run_check(name: str, ctx: Context) -> CheckResult:
    """Run the check called ``name`` within its time budget; a ModelError raised inside
    it is that check failing. Parts skipped for the budget are named in its ``data``."""
    if name not in CHECKS:
        raise ValueError(f"no check {name!r}; checks: {', '.join(CHECKS)}")
    module = importlib.import_module(f"{__package__}.{name}")
    system = ctx.model.control_system
    if getattr(module, "OF_THE_LAGRANGIAN", False) and system is not None \
            and system.pure_minimum_time:
        return CheckResult.skipped(name, (
            "pure minimum time: the cost is T alone, so the Lagrangian is zero and defines "
            "no step map; the controls are fixed by their bounds"))
    ctx.budget.begin()
    try:
        result = module.run(ctx)
    except ModelError as exc:
        result = CheckResult.failed(name, f"the model cannot be checked: {exc}")
    if ctx.budget.skipped:
        result = replace(result, data={**result.data, BUDGET_SKIPPED: tuple(ctx.budget.skipped)})
    return result


def selected(only: str | Sequence[str] | None, what: str = "only") -> list[str]:
    """The checks to run, each once, in the order given: all of :data:`CHECKS` for None,
    else the names in ``only`` — a sequence, or text separated by commas as ``symvi check
    --only`` takes it. No name at all (``",,"``) or a name that is not a check is a
    ValueError naming ``what`` and listing the checks: running none is no verdict."""
    if only is None:
        return list(CHECKS)
    names = only.split(",") if isinstance(only, str) else list(only)
    names = list(dict.fromkeys(str(n).strip() for n in names if str(n).strip()))
    if not names:
        raise ValueError(f"{what} names no check, got {only!r}; checks: {', '.join(CHECKS)}")
    unknown = [n for n in names if n not in CHECKS]
    if unknown:
        raise ValueError(f"{what}: unknown check(s) {unknown}; checks: {', '.join(CHECKS)}")
    return names


def check(model: Model, *, only: str | Sequence[str] | None = None, equations: Sequence = (),
          seed: int = 20261121, budget: float | None = DEFAULT_BUDGET,
          on_result: Callable[[CheckResult], None] | None = None,
          progress: Callable[[str], None] | None = None) -> CheckReport:
    """Run the derivation checks on ``model`` and return their :class:`CheckReport`.

    ``only`` restricts the run to some of :data:`CHECKS` (:func:`selected`); ``equations`` are hand-derived
    equations for the ``equations`` check (:class:`symvi.checks.equations.HandDerived`).
    ``budget`` is each check's time in seconds (None: unlimited) past which its optional,
    costly parts (the singular locus) are skipped with a note, never its verdict.
    ``on_result`` receives each check's result as it finishes; ``progress`` a line when
    a check has run for :data:`SLOW_CHECK` seconds and when it ends.
    """
    names = selected(only)
    ctx = Context(model, equations, seed, Budget(budget))
    results = []
    for name in names:
        with announced(f"check {name}", progress, SLOW_CHECK):
            results.append(run_check(name, ctx))
        if on_result is not None:
            on_result(results[-1])
    return CheckReport(model.name, tuple(results))
