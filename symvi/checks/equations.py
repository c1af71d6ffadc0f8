"""Check ``equations``: are hand-derived equations the ones symvi derives? (issue 5, item 7)

A user hands over equations — their own, or copied from a paper — as
:class:`~symvi.checks.hand.HandDerived` objects (re-exported here), each naming the derived object it claims to reproduce (its
``target``). :func:`compare` decides, and says where they differ:

* ``mode="equations"`` (controlled equations, constraints, discrete constraints, the
  discrete Euler–Lagrange residual): equivalence *modulo rescaling and recombination* —
  the same solution set. Every hand equation is first paired with the derived equation it
  matches best, up to a factor free of the variables; if that does not settle it, the
  derived system is solved for unknowns in which it is linear (controls, highest
  derivatives, the last slot's coordinates) and the solution substituted into the hand
  equations, which must then vanish and determine the same unknowns.
* ``mode="value"`` (Lagrangians, the target map): the expressions must be equal; a factor
  (``hand = derived × 1/h``) or increments scaled by h are named as such.

A mismatch is located by the terms that differ, grouped by the parameters they carry and
written in the user's own symbols: ``I3bar*Omega2*Omega3_dot where I3bar*Omega2*Omega3 is
right``, ``missing -J2*Omega3*theta2_dot``, ``-P1*Omega2*Omega3 where
-(I2 - I3)*Omega2*Omega3/I1 is right (reciprocal coefficient) [P1 = I1/(I2 - I3)]``.
Symbols are matched by *name*, so hand equations need no access to symvi's objects; a
symbol that names nothing is reported as undefined. The paper's displays are shipped as
fixtures (:mod:`symvi.fixtures`), where this check reproduces ``ERRATA.md``.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import sympy as sp
from scipy.optimize import linear_sum_assignment

from ..discretisation.discretise import DiscreteModel, discretise
from ..errors import ModelError
from .budget import SKIPPED, Budget
from .hand import HandDerived
from .equivalence import (Hand, coefficient_note, in_controls, is_zero, limit_note,
                          linear_unknowns, matrix_rank, scaled_increments, show, simplified,
                          solve_linear)
from .sampled import POINTS, Sampled, sampled_equations, sampled_values
from .spaces import ALGEBROID, CONTINUOUS, Space, symbol_space
from .report import CheckResult

NAME = "equations"

__all__ = ["NAME", "HandDerived", "Comparison", "compare", "run"]

@dataclass(frozen=True)
class EquationResult:
    """One hand expression: ``ok``, and what it matched or where it differs."""

    label: str
    ok: bool
    message: str

    def to_dict(self) -> dict:
        return {"label": self.label, "ok": self.ok, "message": self.message}


@dataclass(frozen=True, eq=False)
class Comparison:
    """Outcome of :func:`compare`: per-expression results and a one-line summary."""

    hand: HandDerived
    ok: bool
    summary: str
    equations: tuple[EquationResult, ...] = ()
    undefined: tuple[str, ...] = ()
    #: a note per function of time that names no model quantity
    functions: tuple[str, ...] = ()
    #: why the location of the differences was cut (the check's time budget), if it was
    cut: str = ""

    def details(self) -> list[str]:
        """One line per problem, each starting with the display's name (its location)."""
        lines = [] if self.equations else [f"{self.hand.name}: {self.summary}"]
        if self.undefined:
            lines.append(f"{self.hand.name}: undefined symbol{'s' * (len(self.undefined) > 1)} "
                         f"{', '.join(self.undefined)}")
        lines += [f"{self.hand.name}: {note}" for note in self.functions]
        lines += [f"{self.hand.name}, {r.label}: {r.message}" for r in self.equations if not r.ok]
        if self.equations and not self.ok and all(r.ok for r in self.equations):
            lines.append(f"{self.hand.name}: {self.summary}")
        if self.cut:
            lines.append(f"{self.hand.name}: {self.cut}")
        return lines

    def to_dict(self) -> dict:
        return {"name": self.hand.name, "target": self.hand.target, "mode": self.hand.mode,
                "ok": self.ok, "summary": self.summary, "undefined": list(self.undefined),
                "functions": list(self.functions), "cut": self.cut,
                "equations": [r.to_dict() for r in self.equations]}


# -- helpers ------------------------------------------------------------------------------
# -- the comparison -----------------------------------------------------------------------
def compare(hand: HandDerived, model=None, discrete: DiscreteModel | None = None,
            derived=None, budget: Budget | None = None, seed: int = 20261121,
            memo: dict | None = None) -> Comparison:
    """Compare ``hand`` with the derived object it targets on ``model`` (``hand.model``
    when given). ``discrete`` (``discretise(model)``) and ``derived`` (``derive(...)``) are
    reused when passed.

    The verdict comes first from sampled points (:mod:`.sampled`); the symbolic location
    of the differences (and the pairing of agreeing rows with derived equations) after
    it, within ``budget`` when given — past it the location is cut with a note and the
    sampled verdict stands. Where the symbolic comparison cannot show two forms equal
    (sin(q₁ − q₂) against its expansion, after the simplification it does) the sampled
    verdict decides too; an exact symbolic proof of agreement decides over a sampled
    disagreement. ``memo``, a dict the caller keeps across displays, holds the unknowns
    chosen for each derived system (the displays of one target share them)."""
    model = hand.model if hand.model is not None else model
    if model is None:
        raise ValueError(f"{hand.name}: no model to compare with")
    try:
        space = symbol_space(hand, model, discrete, derived)
    except ModelError as exc:
        return Comparison(hand, False, f"cannot compare with {hand.target}: {exc}")
    derived_exprs = [simplified(e) for e in space.derived]
    if hand.select is not None:
        bad = [i for i in hand.select if not 0 <= i < len(derived_exprs)]
        if bad:
            return Comparison(hand, False, f"select {bad} out of range: {hand.target} has "
                                           f"{len(derived_exprs)} expressions")
        derived_exprs = [derived_exprs[i] for i in hand.select]
    resolved = Hand(hand, space)
    controls = {c.name for c, _ in space.controls}
    if hand.target != "controls" and space.controls and any(
            s.name in controls for e in resolved.math for s in e.free_symbols):
        rewritten = in_controls(space, derived_exprs)
        if rewritten is not None:
            derived_exprs = [simplified(e) for e in rewritten]
        else:
            resolved.math = [e.xreplace(dict(space.controls)) for e in resolved.math]
    functions = tuple(dict.fromkeys(resolved.functions.values()))
    key = (tuple(derived_exprs), hand.unknowns)
    memo = {} if memo is None else memo
    unknowns = memo[key] if key in memo else memo.setdefault(
        key, _unknowns(hand, derived_exprs, space))
    verdict = None if resolved.undefined or resolved.functions or isinstance(unknowns, str) \
        else (sampled_values(resolved.math, derived_exprs, seed) if hand.mode == "value"
              else sampled_equations(resolved.math, derived_exprs, unknowns,
                                     space.variables, seed))
    if hand.mode == "value":
        locate = (_compare_values, resolved, derived_exprs, hand)
    else:
        locate = (_compare_equations, resolved, derived_exprs, hand, space, unknowns, verdict)
    label = f"location of the differences in {hand.name}"
    results = locate[0](*locate[1:]) if budget is None else budget.attempt(label, *locate)
    cut = results is SKIPPED
    if cut:
        results = _from_sampled(verdict, resolved, hand, unknowns, budget.note(label))
    elif verdict is not None and verdict.decided and not isinstance(results, str):
        results = _with_sampled(results, verdict, hand)
    if isinstance(results, str):
        return Comparison(hand, False, results, (), resolved.undefined, functions)
    results = _missing_rows(results, resolved, derived_exprs, hand, space.variables, seed)
    if hand.target == "discrete_action" and not all(r.ok for r in results) and not cut:
        results = _miscounted_terms(hand, model, discrete) or results
    ok = all(r.ok for r in results) and not resolved.undefined and not resolved.functions
    wrong = [r.label for r in results if not r.ok]
    if ok:
        summary = f"agrees with the derived {hand.target}"
    elif wrong:
        summary = f"differs from the derived {hand.target} in {', '.join(wrong)}"
    else:
        summary = "uses undefined symbols or functions"
    return Comparison(hand, ok, summary, tuple(results), resolved.undefined, functions,
                      budget.note(label) if cut else "")


def _unknowns(hand: HandDerived, derived: list, space: Space):
    """The unknowns the derived equations are solved for: the display's own, else those
    in which they are linear (:func:`.equivalence.linear_unknowns`); None for values or
    where there are none; a message when the display names unknowns the model lacks."""
    if hand.mode == "value":
        return None
    names = hand.unknowns
    if any(u not in space.names for u in names):
        return f"unknowns {[u for u in names if u not in space.names]} are not model symbols"
    unknowns = ([space.names[u] for u in names] if names else
                linear_unknowns(derived, space.candidates, space.fixed))
    return unknowns if unknowns and len(unknowns) == len(derived) else None


def _missing_rows(results: list, hand: Hand, derived: list, spec: HandDerived,
                  variables, seed: int) -> list:
    """A display with fewer rows than the derived equations, whose rows agree: its
    "system" result names the derived equations no row is (by sampled proportionality),
    written out, and what the target holds (:data:`TARGET_HOLDS`) — the ``constraints`` of
    a nonholonomic model are its kinematic constraints too, not only the unactuated
    equations."""
    if len(hand.math) >= len(derived) or spec.select is not None \
            or not any(r.label == "system" and not r.ok for r in results):
        return results
    pairs = sampled_equations(hand.math, derived, None, variables, seed).pairs
    missing = [j for j in range(len(derived)) if j not in pairs]
    if not missing:
        return results
    listed = "; ".join(f"eq. {j + 1}: {show(hand.show(derived[j]))} = 0" for j in missing)
    rows = f"{len(hand.math)} row{'s' * (len(hand.math) > 1)}"
    text = (f"{rows} for the {len(derived)} derived {spec.target}; no row is {listed}. "
            f"{TARGET_HOLDS.get(spec.target, 'Give every derived equation')}, or compare "
            f"some of them with select=")
    return [EquationResult(r.label, False, f"{r.message} — {text}") if r.label == "system"
            else r for r in results]


#: What a display of a target must hold besides the equations it is named after.
TARGET_HOLDS = {
    "constraints": "The constraints target is every constraint of the model, in its order: "
                   "on a nonholonomic model the kinematic constraints (the velocities lie "
                   "in the distribution) as well as the unactuated equations of motion",
    "euler_lagrange": "The euler_lagrange target holds the constraints Φ^A = 0 after the "
                      "Euler–Lagrange equations",
}


def _from_sampled(verdict: Sampled | None, hand: Hand, spec: HandDerived, unknowns,
                  note: str) -> list:
    """Row results from the sampled verdict alone, when the location was cut."""
    if verdict is None or not verdict.decided:
        why = ("the display uses undefined symbols or functions" if hand.undefined
               or hand.functions else "the sampled points could not be evaluated")
        return [EquationResult(label, False, f"no verdict: {why}, and the {note}")
                for label in spec.labels]
    results = [EquationResult(label, ok, (
        f"agrees at {POINTS} random points" if ok else
        f"differs from the derived {spec.target} at {POINTS} random points; where is not "
        f"located: {note}")) for label, ok in zip(spec.labels, verdict.rows)]
    if all(verdict.rows) and verdict.rank is not None and verdict.rank < verdict.unknowns:
        results.append(_underdetermined(verdict, hand, unknowns))
    return results


def _underdetermined(verdict: Sampled, hand: Hand | None = None,
                     unknowns=()) -> EquationResult:
    """The display's rows agree but determine only ``verdict.rank`` of the unknowns."""
    named = f" {', '.join(str(hand.show(u)) for u in unknowns)}" if hand and unknowns else ""
    return EquationResult("system", False, f"determines only {verdict.rank} of the "
                                           f"{verdict.unknowns} unknowns{named}: an equation "
                                           f"is missing or two are dependent")


def _with_sampled(results: list, verdict: Sampled, spec: HandDerived) -> list:
    """The located results under the sampled verdict: a row the symbolic comparison could
    not show equal, but which agrees at the sampled points, agrees (two forms the
    simplification did not bring together); rows that differ keep their location."""
    rows = dict(zip(spec.labels, verdict.rows))
    return [EquationResult(r.label, True, f"agrees at {POINTS} random points (forms the "
                                          f"symbolic comparison did not reduce to one)")
            if not r.ok and rows.get(r.label) else r for r in results]



def _miscounted_terms(hand: HandDerived, model, discrete) -> list | None:
    """A discrete action that is the sum over one element more or fewer: its terms are
    miscounted (ERRATA 9: a sum to k = N−1 needs a ξ_N)."""
    discrete = discrete or discretise(model)
    r = discrete.order
    for elements in (hand.elements + 1, hand.elements - 1):
        if elements < r:
            continue
        recounted = replace(hand, elements=elements)
        space = symbol_space(recounted, model, discrete, None)
        other = Hand(recounted, space)
        if not other.undefined and all(is_zero(H - D) for H, D in zip(other.math,
                                                                        space.derived)):
            have, claimed = hand.elements - r + 1, elements - r + 1
            return [EquationResult(hand.labels[0], False,
                                   f"sums {claimed} windows (k = 0 … {claimed - 1}) where a "
                                   f"trajectory of {hand.elements} elements has {have} "
                                   f"(k = 0 … {have - 1}): it is the action of "
                                   f"{elements} elements")]
    return None


def _proportional_at_samples(H: sp.Expr, D: sp.Expr, variables: set, fixed: dict) -> bool:
    """Whether H/D is free of ``variables`` at random points (the other symbols at their
    ``fixed`` values): [[H, D], [H', D']], primes at a second point, has rank < 2. A cheap
    test before cancelling H/D symbolically."""
    copies = {s: sp.Dummy(s.name) for s in variables}
    pair = sp.Matrix([[H, D], [H.xreplace(copies), D.xreplace(copies)]])
    others = pair.free_symbols - set(variables) - set(copies.values())
    return matrix_rank(pair, {s: fixed.get(s, 1.0) for s in others}) < 2


def _compare_values(hand: Hand, derived: list, spec: HandDerived):
    """``mode="value"``: equal, equal up to a factor, or a note on where they differ; a
    result string when the counts differ."""
    if len(hand.math) != len(derived):
        return (f"{len(hand.math)} hand expressions for {len(derived)} derived ones "
                f"({spec.target})")
    results = []
    for i, (H, D) in enumerate(zip(hand.math, derived)):
        label = spec.labels[i]
        if is_zero(H - D):
            results.append(EquationResult(label, True, "equal"))
            continue
        variables = set(hand.space.variables) | {
            s for s in H.free_symbols if s.name in hand.undefined or s.name in hand.functions}
        proportional = D != 0 and _proportional_at_samples(H, D, variables,
                                                             hand.space.fixed)
        ratio = sp.cancel(H / D) if proportional else sp.zoo
        if ratio.is_finite is not False and ratio != 0 and not ratio.free_symbols & variables:
            results.append(EquationResult(label, False, f"equal up to the factor "
                                                        f"{show(ratio)}: hand = "
                                                        f"{show(ratio)} × derived"))
            continue
        note = scaled_increments(H, D, hand.space) if spec.target != "target_map" else None
        if note is None:
            note = coefficient_note(hand, i, D)
        if note is None and spec.target == "target_map":
            note = limit_note(hand, H, D)
        if note is None:
            groups = hand.locate(i, D, scale=1).groups     # a value has no free factor
            note = "differs: " + ("; ".join(groups) if groups else
                                  f"hand − derived = {show(hand.show(H - D))}")
        results.append(EquationResult(label, False, note))
    return results


def _pairing(hand: Hand, derived: list) -> list:
    """Per hand expression, (j, c, differing groups) of the derived equation j it is
    paired with, up to the factor c, or None (issue 26, item 2).

    The pairing is an optimal assignment — each derived equation to at most one display
    row, the total dissimilarity least: first the linear terms the pair does not share,
    then the differing term groups (SciPy's ``linear_sum_assignment``;
    ties go to the row's own index) — not each row's own best: three rows that all look
    most like one equation are paired with three equations, so that each row's
    difference is told against its own. A row left over (more rows than equations) is
    paired with the equation it matches best."""
    located = [[hand.locate(i, D, described=False) for D in derived]
               for i in range(len(hand.math))]
    if not located or not derived:
        return [None] * len(located)
    cost = np.array([[_UNPAIRED if at.scale is None else
                      _LINEAR * at.linear + at.count + _OFF_DIAGONAL * (i != j)
                      for j, at in enumerate(row)] for i, row in enumerate(located)])
    rows, columns = linear_sum_assignment(cost)
    chosen = [None] * len(located)
    for i, j in zip(rows, columns):
        if located[i][j].scale is not None:
            chosen[i] = j
    for i, row in enumerate(located):
        if chosen[i] is None and cost[i].min() < _UNPAIRED:
            chosen[i] = int(np.argmin(cost[i]))
    pairing = [None] * len(located)
    for i, j in enumerate(chosen):
        if j is not None:
            at = hand.locate(i, derived[j], located[i][j].scale)
            pairing[i] = (j, at.scale, at.groups)
    return pairing


#: The cost of pairing a row with an equation no factor relates it to, of each linear term
#: (one unknown times parameters) the pair does not share — which equation a row is comes
#: first, how many groups of its other terms differ second — and the tie-break toward a
#: row's own index.
_UNPAIRED, _LINEAR, _OFF_DIAGONAL = 1e6, 100.0, 1e-3


def _compare_equations(hand: Hand, derived: list, spec: HandDerived, space: Space,
                       unknowns, verdict: Sampled | None = None):
    """``mode="equations"``: paired term by term; a row not matched so is decided by the
    sampled ``verdict`` where it decided, else by solving the derived system for
    ``unknowns`` (:func:`_unknowns`) symbolically — the step that cost the triple
    pendulum's 32 minutes. A result string when the unknowns are not symbols."""
    n = len(derived)
    pairing = _pairing(hand, derived)

    def matched(i):
        j, c, _ = pairing[i]
        return f"= derived eq. {j + 1}" + ("" if c == 1 else f" × {show(c)}")

    exact = [p is not None and not p[2] and is_zero(
        hand.math[i] - hand.bind(p[1]) * derived[p[0]]) for i, p in enumerate(pairing)]
    if all(exact) and len({p[0] for p in pairing}) == n:
        return [EquationResult(spec.labels[i], True, matched(i)) for i in range(len(pairing))]

    def differs(i):
        if pairing[i] is None:
            return "matches no derived equation term by term"
        j, c, groups = pairing[i]
        scale = "" if c == 1 else f" × {show(c)}"
        return f"vs derived eq. {j + 1}{scale}: " + "; ".join(groups or ["differs"])

    if isinstance(unknowns, str):
        return unknowns
    if verdict is not None and verdict.decided and unknowns:
        results = [EquationResult(spec.labels[i], True, matched(i) if exact[i] else
                                  "a combination of the derived equations") if ok else
                   EquationResult(spec.labels[i], False, differs(i))
                   for i, ok in enumerate(verdict.rows)]
        if all(verdict.rows) and verdict.rank < n:
            results.append(_underdetermined(verdict, hand, unknowns))
        return results
    if not unknowns:
        results = [EquationResult(spec.labels[i], exact[i], matched(i) if exact[i]
                                  else differs(i)) for i in range(len(pairing))]
        if all(exact):
            results.append(EquationResult("system", False, f"covers only "
                                          f"{len({p[0] for p in pairing})} of the {n} derived "
                                          f"equations"))
        return results
    solution = solve_linear(derived, unknowns)
    results = []
    for i, H in enumerate(hand.math):
        residual = sp.cancel(sp.together(H.xreplace(solution)))
        if is_zero(residual):
            text = matched(i) if exact[i] else "a combination of the derived equations"
            results.append(EquationResult(spec.labels[i], True, text))
        else:
            results.append(EquationResult(spec.labels[i], False, differs(i)))
    if all(r.ok for r in results):
        J = sp.Matrix(hand.math).jacobian(unknowns).xreplace(solution)
        rank = matrix_rank(J, space.fixed)
        if rank < n:
            results.append(_underdetermined(Sampled((), rank, n), hand, unknowns))
    return results


# -- the check ----------------------------------------------------------------------------
def run(ctx) -> CheckResult:
    """Compare every hand-derived display of ``ctx.equations`` with symvi's derivation."""
    if not ctx.equations:
        return CheckResult.skipped(NAME, "no hand-derived equations given (a paper fixture "
                                         "or a model file's `equations`)")
    comparisons, memo = [], {}
    for hand in ctx.equations:
        if not isinstance(hand, HandDerived):
            return CheckResult.failed(NAME, f"equations must be HandDerived objects, got "
                                            f"{type(hand).__name__}")
        own = hand.model is None or hand.model is ctx.model
        discrete = ctx.discrete if own and hand.target not in CONTINUOUS + ALGEBROID else None
        derived = ctx.derived if own and hand.target == "residual" else None
        comparisons.append(compare(hand, ctx.model, discrete, derived, ctx.budget, ctx.seed,
                                   memo))
    data = {"comparisons": [c.to_dict() for c in comparisons]}
    failed = [c for c in comparisons if not c.ok]
    if not failed:
        return CheckResult.passed(NAME, f"{len(comparisons)} hand-derived display(s) agree "
                                        f"with the derivation", **data)
    details = [line for c in failed for line in c.details()]
    agreeing = [c.hand.name if c.ok else
                f"{c.hand.name} ({', '.join(r.label for r in c.equations if r.ok)})"
                for c in comparisons if c.ok or any(r.ok for r in c.equations)]
    if agreeing:
        details.append("agree: " + "; ".join(agreeing))
    return CheckResult.failed(NAME, f"{len(failed)} of {len(comparisons)} hand-derived "
                                    f"display(s) differ from the derivation", details, **data)
