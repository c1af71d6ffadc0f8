"""Check ``consistency``: the order in h at which the discrete residual approximates the
continuous equations (DESIGN.md §5; issue 5, item 3).

The residual at the middle node of the derived stencil is expanded in h along a smooth
curve (:mod:`symvi.checks.expansions`: pair nodes q(t + jh), group increments ξ_i sampled at the
middle of their element, action base points from β, multipliers at their window's middle
node). It passes when its leading term is ±h^p·E with E the variational derivative of the
action —

* pair groupoid: E(L) = ∂L/∂q − d/dt ∂L/∂q̇ + d²/dt² ∂L/∂q̈ (of order r:
  Σ_{j=0}^{r} (−d/dt)^j ∂L/∂q⁽ʲ⁾);
* Lie groups, action groupoids, products: E = −EL_r(L) on the Lie algebroid (Appendix C.2
  for r = 1; the second-order operator EL₂ with P = ∂L̃/∂y − d/dt ∂L̃/∂ẏ for r = 2; of
  order r, P = Σ_{j<r} (−d/dt)^j ∂L/∂y⁽ʲ⁾);
* constrained (optimal-control) models: the residual of the augmented action with smooth
  multipliers λ_A(t) against E(L̃ + λ_A Φ^A) (d/dt acting on λ, ERRATA item 8), *and* the
  discrete constraints of one window against h·Φ —

and reports p, the sign and the order (next power − leading power: the relative error of
the residual as an approximation of h^p·E). A correct symmetric rule gives +h·E + O(h³),
order 2 (measured also for the order-k rules ``central3`` … ``central6`` and
``lie_central3`` … ``lie_central6``: the h² term vanishes, the h³ one does not). It fails
when the leading term is not ±h^p·E — naming, per component, the leading coefficient, the expected one and their difference — or when the order falls
short of the rule's declared ``consistency_order`` (:mod:`symvi.discretisation.rules`).

Skipped: models declared with a discrete Lagrangian only (there is no continuous equation;
:func:`symvi.checks.expansions.check_consistency` takes a continuous reference model), groupoids
the expansion cannot sample, and residuals with operations the series arithmetic does not
support (the reason says which).
"""
from __future__ import annotations

import time

import sympy as sp

from .expansions import (ConsistencyReport, check_consistency, compact, component_names,
                           unsupported)
from ..errors import ModelError
from .report import CheckResult

NAME = "consistency"
#: Of the Lagrangian's step map: skipped in pure minimum time (:mod:`.runner`).
OF_THE_LAGRANGIAN = True

def _equation(model) -> str:
    """What E is, in words."""
    r, groupoid = model.order, model.groupoid
    if groupoid.elements_are_node_pairs and not model.constraints:
        if r > 2:
            return f"E(L) = Σ_{{j=0}}^{{{r}}} (−d/dt)^j ∂L/∂q⁽ʲ⁾"
        return ("E(L) = ∂L/∂q − d/dt ∂L/∂q̇" if r == 1
                else "E(L) = ∂L/∂q − d/dt ∂L/∂q̇ + d²/dt² ∂L/∂q̈")
    operator = "EL(L)" if r == 1 else "EL₂(L̃)" if r == 2 else \
        f"EL_{r}(L) with P = Σ_{{j<{r}}} (−d/dt)^j ∂L/∂y⁽ʲ⁾"
    if model.constraints:   # first order: the extended Lagrangian of a nonholonomic problem
        operator = "EL₂(L̃ + λ_A Φ^A)" if r == 2 else "EL(L̃ + λ_A Φ^A)"
    return f"E = −{operator} ({groupoid.equation_setting(r)})"


def _term(sign: int | None, power: int | None, what: str = "E") -> str:
    if power is None:
        return "0"
    s = "−" if sign == -1 else "+"
    return f"{s}h^{power}·{what}"


def _describe(part: ConsistencyReport) -> dict:
    e = part.expansion
    return {"power": part.power, "sign": part.sign, "order": part.order,
            "next_power": e.next_power, "through": e.through}


def _mismatch(part: ConsistencyReport, names, what: str, symbol: str) -> tuple[list, list]:
    """(components, lines): the components whose leading coefficient is not ±(expected),
    three lines each — the difference, the leading coefficient and the expected one."""
    e = part.expansion
    if e.leading is None:
        return list(names), [f"{what}: every coefficient through h^{e.through} vanishes"]
    sign, rows = e.compare(part.expected)
    sign = sign or 1
    s = "" if sign == 1 else "−"
    t = e.time
    lines = []
    for i in rows:
        lead, expected = e.leading[i], sign * part.expected[i]
        difference = sp.expand(lead - expected)
        lines.append(f"{what} component {names[i]} (row {i}): leading h^{e.leading_power} "
                     f"coefficient minus {s}{symbol}_{i} = {compact(difference, t)}")
        label = f"expected {s}{symbol}_{i}:"
        lines.append(f"    leading coefficient: {compact(lead, t)}")
        lines.append(f"    {label:21s}{compact(expected, t)}")
    return [names[i] for i in rows], lines


def run(ctx) -> CheckResult:
    model = ctx.model
    if model.lagrangian is None:
        return CheckResult.skipped(
            NAME, "declared with a discrete Lagrangian only: there is no continuous "
                  "equation to compare with (symvi.checks.expansions.check_consistency(model, "
                  "lagrangian_model=reference) takes one)")
    reason = unsupported(model.groupoid)
    if reason is not None:
        return CheckResult.skipped(NAME, reason)
    derived = ctx.derived
    start = time.perf_counter()
    try:
        report = check_consistency(model, derived=derived)
    except ModelError as exc:
        return CheckResult.skipped(NAME, f"cannot expand the residual in h: {exc}")
    seconds = round(time.perf_counter() - start, 3)
    names = component_names(model.groupoid)
    e = report.expansion
    sampling = model.groupoid.sampling_text
    if model.constraints:
        sampling += "; multipliers λ^w = λ(t_w) at their window's middle node"
    data = {**_describe(report), "equation": _equation(model), "sampling": sampling,
            "seconds": seconds}
    tail = (f"O(h^{e.next_power})" if e.next_power is not None
            else f"nothing further through h^{e.through}")
    head = f"R = {_term(report.sign, report.power)} + {tail}"
    constraint_text = ""
    details: list[str] = []
    problems: list[str] = []
    if report.sign is None:
        bad, lines = _mismatch(report, names, "residual", "E")
        details += lines
        problems.append(f"the residual vanishes through h^{e.through}" if report.power is None
                        else f"the residual's leading term h^{report.power} is not "
                             f"±h^{report.power}·E in {', '.join(bad)}")
    rule = model.groupoid.rule(model.discretisation)
    if report.sign is not None and report.order is not None \
            and report.order < rule.consistency_order:
        problems.append(f"the residual is consistent to order {report.order}, below the order "
                        f"{rule.consistency_order} of the rule {rule.name!r}")
    if report.constraints is not None:
        c = report.constraints
        data["constraints"] = _describe(c)
        ctail = (f"O(h^{c.expansion.next_power})" if c.expansion.next_power is not None
                 else f"nothing further through h^{c.expansion.through}")
        constraint_text = (f"; constraints Φ_d = {_term(c.sign, c.power, 'Φ')} + {ctail}"
                           + (f" (order {c.order})" if c.order is not None else ""))
        if c.sign is None:
            bad, lines = _mismatch(c, [f"Φ{a}" for a in range(len(model.constraints))],
                                   "constraint", "Φ")
            details += lines
            problems.append(f"the discrete constraints' leading term h^{c.power} is not "
                            f"±h^{c.power}·Φ in {', '.join(bad)}")
    if problems:
        return CheckResult.failed(
            NAME, f"inconsistent with {data['equation']}: {'; '.join(problems)}", details,
            **data)
    order = (f"order {report.order}" if report.order is not None
             else f"order ≥ {e.through + 1 - report.power}")
    return CheckResult.passed(
        NAME, f"consistent: {head} ({order}), {data['equation']}{constraint_text}", **data)
