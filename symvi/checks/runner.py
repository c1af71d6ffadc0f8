"""Run the derivation checks on a model (issue 5).

Each check is a module of this package with a function ``run(ctx: Context) ->
CheckResult``; :data:`CHECKS` lists them in the order they run. A check reads the model
and whatever it needs from the shared :class:`Context`, which derives the discrete model
once and caches it.
"""
from __future__ import annotations

import importlib
from functools import cached_property
from typing import Sequence

from ..derivation.derive import DerivedModel, derive
from ..discretisation.discretise import DiscreteModel, discretise
from ..errors import ModelError
from ..declaration.model import Model
from .report import CheckReport, CheckResult

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
    """

    def __init__(self, model: Model, equations: Sequence = (), seed: int = 20261121):
        self.model = model
        self.equations = tuple(equations)
        self.seed = seed

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
    """Run the check called ``name``; a ModelError raised inside it is that check failing."""
    if name not in CHECKS:
        raise ValueError(f"no check {name!r}; checks: {', '.join(CHECKS)}")
    module = importlib.import_module(f"{__package__}.{name}")
    try:
        return module.run(ctx)
    except ModelError as exc:
        return CheckResult.failed(name, f"the model cannot be checked: {exc}")


def check(model: Model, *, only: Sequence[str] | None = None, equations: Sequence = (),
          seed: int = 20261121) -> CheckReport:
    """Run the derivation checks on ``model`` and return their :class:`CheckReport`.

    ``only`` restricts the run to some of :data:`CHECKS`; ``equations`` are hand-derived
    equations for the ``equations`` check (:class:`symvi.checks.equations.HandDerived`).
    """
    names = list(CHECKS) if only is None else list(only)
    unknown = [n for n in names if n not in CHECKS]
    if unknown:
        raise ValueError(f"unknown check(s) {unknown}; checks: {', '.join(CHECKS)}")
    ctx = Context(model, equations, seed)
    return CheckReport(model.name, tuple(run_check(n, ctx) for n in names))
