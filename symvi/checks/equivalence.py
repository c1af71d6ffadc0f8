"""The symbolic machinery of the check ``equations`` (:mod:`symvi.checks.equations`).

A :class:`Hand` is a hand-derived display resolved against the :class:`Space` of its
target (:mod:`symvi.checks.spaces`), in the model's symbols and in the user's own. On these: the unknowns in which a derived system is
linear and its solution (:func:`linear_unknowns`, :func:`solve_linear`), the terms in
which a hand expression differs from a derived one, grouped by the parameters they carry
(:meth:`Hand.locate`), and notes naming a recognisable mistake — increments ξ = τ⁻¹(w)/h
mis-scaled (:func:`scaled_increments`), named constants with the wrong value
(:func:`coefficient_note`), a target map that does not tend to the identity as h → 0
(:func:`limit_note`).
"""
from __future__ import annotations

import re
from collections import Counter
from typing import TYPE_CHECKING, Any, Mapping, NamedTuple

import sympy as sp
from sympy.core.function import AppliedUndef

from ..discretisation.discretise import h as STEP
from ..declaration.rank import generic_rank
from ..derivation.differentiate import engine_function
from ..groupoids.base import derivative_name
from .series import vanishes_at
from .spaces import Space

if TYPE_CHECKING:
    from .hand import HandDerived

# -- symbols and expressions --------------------------------------------------------------
def _plain(expr: sp.Expr) -> sp.Expr:
    """Every symbol replaced by a plain Symbol of its name (symbols compare by name)."""
    return expr.xreplace({s: sp.Symbol(s.name) for s in expr.free_symbols})


def functions_of_time(expr: sp.Expr, names) -> tuple[sp.Expr, dict[str, str]]:
    """``expr`` with each undefined function of one variable F(t), and its derivatives,
    made a plain symbol; and a note per such function that names no model quantity.

    A display may write the model's quantities as functions of time: Ω₁(t) is the model
    symbol Omega1 and its k-th derivative the jet symbol of that name
    (:func:`~symvi.groupoids.base.derivative_name`: ``Omega1_dot``, …, ``Omega1_d4``) where
    the model declares it. Anything else — λ(t) where the multipliers are lambda1,
    lambda2, lambda3 — becomes a placeholder symbol printed as the term itself, so that
    the comparison goes on with it undefined (and shows "lambda(t) where lambda1 is
    right"), and its note names the declared quantities it may have meant. ``names``:
    the model's symbol names."""
    names = set(names)
    replacements, notes = {}, {}
    terms = [(d, d.expr, sum(count for _, count in d.variable_count))
             for d in expr.atoms(sp.Derivative) if _function_of_time(d.expr)]
    terms += [(f, f, 0) for f in expr.atoms(AppliedUndef) if _function_of_time(f)]
    for term, f, order in terms:
        name = derivative_name(f.func.__name__, order)
        replacements[term] = sp.Symbol(name if name in names else str(term))
        if name not in names:
            notes[str(term)] = _function_note(f, names)
    return expr.xreplace(replacements) if replacements else expr, notes


def _function_of_time(f) -> bool:
    return isinstance(f, AppliedUndef) and len(f.args) == 1


def _function_note(f: sp.Expr, names: set) -> str:
    """Why the function of time ``f`` (with its derivatives) names no model quantity,
    with the declared quantities it may have meant: those starting like it, not their
    derivatives."""
    stem = f.func.__name__.lower()[:3]
    similar = sorted(n for n in names if n.lower().startswith(stem)
                     and not _JET_SUFFIX.search(n))
    hint = f"declared: {', '.join(similar[:8])}{', …' if len(similar) > 8 else ''}" \
        if similar else "write the display in the model's symbols"
    return (f"{f} (and its derivatives) is a function of time that names no declared "
            f"quantity — the model's quantities are symbols, or functions of time named "
            f"like them; {hint}")


#: The suffixes of derivatives' jet symbols (Omega1_dot, …, Omega1_d4).
_JET_SUFFIX = re.compile(r"_(d+ot|d\d+)$")


def _substitute(expr: sp.Expr, table: Mapping[str, sp.Expr], depth: int = 12) -> sp.Expr:
    """Replace symbols named in ``table`` (repeatedly: values may use other keys)."""
    for _ in range(depth):
        subs = {s: table[s.name] for s in expr.free_symbols
                if s.name in table and table[s.name] != s}
        if not subs:
            return expr
        expr = expr.xreplace(subs)
    raise ValueError(f"the symbol mapping is circular around {sorted(map(str, subs))}")


def is_zero(expr: sp.Expr) -> bool:
    """Whether ``expr`` vanishes identically (cancelled; simplified if not rational).

    A value at a random point that is not zero decides at once (:func:`.series.vanishes_at`):
    most comparisons of a display with a slip are of that kind, and cancelling them took
    most of the equations check's time."""
    if vanishes_at(expr, 0) is False:
        return False
    e = sp.cancel(sp.together(expr))
    if e == 0:
        return True
    if e.has(sp.Function, sp.Pow) and not e.is_rational_function():
        return sp.simplify(e) == 0
    return False


def simplified(expr: sp.Expr) -> sp.Expr:
    """``expr`` with sin²x + cos²x = 1 applied where it shortens it: each sin(x)^k, k ≥ 2,
    becomes sin(x)^(k−2)·(1 − cos²x) and the result is kept when it has fewer operations
    (the derived constraints of the Chaplygin sled, m·u̇·(sin²θ + cos²θ) − m·a·ω²·(sin²θ +
    cos²θ), become m·u̇ − m·a·ω², which a display's terms are located against). A
    polynomial rewrite, not ``trigsimp``: it costs an expansion, and it never turns a
    product of sines of the coordinates into a sine of their sum."""
    sines = [f for f in expr.atoms(sp.sin) if expr.has(sp.cos(f.args[0]))]
    if not sines:
        return expr
    best, size = expr, sp.count_ops(expr)
    for f in sines:
        trial = sp.expand(best).replace(
            lambda e: e.is_Pow and e.base == f and e.exp.is_Integer and e.exp >= 2,
            lambda e: f ** (e.exp - 2) * (1 - sp.cos(f.args[0]) ** 2))
        trial = sp.factor_terms(sp.expand(trial))
        trial_size = sp.count_ops(trial)
        if trial_size < size:
            best, size = trial, trial_size
    return best


def aligned(a: sp.Expr, b: sp.Expr) -> tuple[sp.Expr, sp.Expr]:
    """``a`` and ``b`` with sines and cosines of sums expanded on both when either holds
    one the other lacks (cos(q₁ − q₂) against sin q₁ sin q₂ + cos q₁ cos q₂, as
    ``LagrangesMethod`` writes chained frames), so that their terms compare one by one."""
    trig = (sp.sin, sp.cos)
    ta, tb = a.atoms(*trig), b.atoms(*trig)
    if ta == tb or not any(f.args[0].is_Add for f in ta ^ tb):
        return a, b
    return simplified(sp.expand_trig(a)), simplified(sp.expand_trig(b))


def show(expr: sp.Expr) -> str:
    """``expr`` as written in messages."""
    return sp.sstr(expr)


# -- linear algebra on the derived system -------------------------------------------------
def matrix_rank(matrix: sp.Matrix, fixed: dict) -> int:
    """Generic rank of ``matrix`` at random points, ``fixed`` symbols at their values."""
    free = sorted(matrix.free_symbols - set(fixed), key=str)
    return generic_rank(matrix, free, {k: v for k, v in fixed.items()
                                       if k in matrix.free_symbols},
                        engine=engine_function) or 0


def linear_unknowns(exprs, candidates, fixed) -> list | None:
    """Greedily, unknowns in which ``exprs`` are jointly linear with a generically
    invertible Jacobian; None when no such set is found."""
    exprs = [sp.expand(e) for e in exprs]
    variables = set(candidates)

    def simplicity(item):
        """Prefer unknowns with constant coefficients in few equations (small solutions)."""
        index, s = item
        columns = [sp.diff(e, s) for e in exprs if e.has(s)]
        return (sum(bool(c.free_symbols & variables) for c in columns), len(columns), index)

    chosen, rank = [], 0
    for _, s in sorted(enumerate(candidates), key=simplicity):
        if not any(e.has(s) for e in exprs):
            continue
        trial = chosen + [s]
        if any(sp.expand(sp.diff(e, s, t)) != 0 for e in exprs for t in trial):
            continue
        r = matrix_rank(sp.Matrix(exprs).jacobian(trial), fixed)
        if r > rank:
            chosen, rank = trial, r
        if rank == len(exprs):
            return chosen
    return None


def solve_linear(exprs, unknowns) -> dict:
    """The unique solution of ``exprs = 0``, linear in ``unknowns``."""
    (solution,) = sp.linsolve([sp.expand(e) for e in exprs], list(unknowns))
    return {u: sp.cancel(v) for u, v in zip(unknowns, solution)}


# -- locating differences -----------------------------------------------------------------
def _majority(ratios: list, ties: bool = False):
    """The ratio most of ``ratios`` share; None without ratios or, unless ``ties``, when
    two ratios are shared equally often."""
    counted = Counter(ratios).most_common(2)
    if not counted or (not ties and len(counted) == 2 and counted[0][1] == counted[1][1]):
        return None
    return counted[0][0]


def _split(expr: sp.Expr, variables) -> dict:
    """Variable monomial → its coefficient (free of the variables)."""
    out: dict = {}
    for term in sp.Add.make_args(sp.expand(expr)):
        coeff, mono = term.as_independent(*variables, as_Add=False)
        out[mono] = out.get(mono, 0) + coeff
    return out


class Located(NamedTuple):
    """Where a hand expression differs from a derived one (:func:`_locate`): the factor c
    (None: no factor relates them), the groups of differing terms of own − c·derived,
    and how many of them are linear terms (one unknown times parameters)."""

    scale: Any
    groups: list
    linear: int = 0
    #: the differing terms, counted after expansion (which factor c leaves fewest)
    terms: int = 0
    #: how many groups differ (``groups`` holds their descriptions when asked for)
    count: int = 0


def _locate(own: sp.Expr, values: dict, derived: sp.Expr, coefficients: set,
            parameters: set, scale=None, described: bool = True) -> Located:
    """The factor c that matches ``own`` (hand, user's symbols) to ``derived`` (display
    symbols) and the differing terms of own − c·derived, grouped by the parameters they
    carry, with the count of differing linear terms (how :func:`.equations._pairing`
    tells which equation a row is). ``values`` gives the coefficient symbols' values.

    c is ``scale`` when given (a value claims equality: no factor is free). Otherwise it
    is chosen among the ratio most of the linear terms (one unknown — a derivative, a
    multiplier, a control, a base coordinate — times parameters) agree on (where they
    do not single out one, the ratio most of all shared terms take), the ratio most of
    all shared terms take, and their opposites: a factor under which every linear term
    agrees fixes the equation's normalisation (issue 26, item 1) — a slip in the bracket
    terms (a wrong lift, a sign of the structure constants: C y η, at least quadratic)
    does not touch them, a display multiplied by a factor is that factor times a right
    one, and one wrong coefficient of a linear term is that term; among such factors, or
    where none exists, the one that leaves the fewest differing terms (issue 53: row 6 of
    the paper's display with A, B, C differs in 43 terms at +1 and 49 at −1). Ties go to
    the linear terms' ratio. Sines and cosines of sums are expanded on both sides first
    where the two disagree in them (:func:`aligned`)."""
    own, derived = aligned(own, derived)
    variables = [s for s in own.free_symbols | derived.free_symbols
                 if s.name not in coefficients | parameters | {"h"}]
    H_own, D = _split(own, variables), _split(derived, variables)
    H = {m: sp.cancel(a.xreplace(values)) for m, a in H_own.items()}
    H = {m: a for m, a in H.items() if a != 0}
    if scale is not None:
        return _differences(H_own, H, D, scale, coefficients, parameters, values, described)
    common = [m for m in H if m in D and D[m] != 0]
    ratios = [sp.cancel(H[m] / D[m]) for m in common]
    first = _majority([r for m, r in zip(common, ratios) if m.is_Symbol]) \
        or _majority(ratios, ties=True)
    if first is None:
        return Located(None, [])
    # of the ratios the terms share, and their opposites, the one leaving the fewest
    # differing terms; the linear terms' majority (issue 26) where they tie
    overall = _majority(ratios, ties=True)
    best, fewest = first, None
    for c in dict.fromkeys([first, -first, overall, -overall]):
        at = _differences(H_own, H, D, c, coefficients, parameters, values, False)
        cost = (min(at.linear, 1), at.terms)
        if fewest is None or cost < fewest:
            best, fewest = c, cost
        if at.terms == 0:
            break
    return _differences(H_own, H, D, best, coefficients, parameters, values, described)


def _differences(H_own: dict, H: dict, D: dict, c, coefficients: set, parameters: set,
                 values: dict, described: bool = True) -> Located:
    """The groups of differing terms of own − c·derived (split by monomial: ``H_own`` in
    the user's symbols, ``H`` their values, ``D`` derived), each described unless not
    ``described`` (only counted), and how many linear terms and terms in all differ."""
    linear, terms = 0, 0
    keyed: dict = {}

    def key(coeff):
        return tuple(sorted(s.name for s in coeff.free_symbols if s.name in parameters))

    def add(k, hand_own, hand_value, derived_part, whole=None):
        group = keyed.setdefault(k, [sp.S.Zero, sp.S.Zero, sp.S.Zero, []])
        group[0] += hand_own
        group[1] += hand_value
        group[2] += derived_part
        if whole is not None:
            group[3].append(whole)

    for m in list(H) + [m for m in D if m not in H]:
        a, b = H.get(m, sp.S.Zero), c * D.get(m, sp.S.Zero)
        b = b if sp.sympify(c).is_Integer else sp.cancel(b)
        if _same(a, b):
            continue
        linear += m.is_Symbol
        terms += len(sp.Add.make_args(sp.expand(a - b)))
        own_term = H_own.get(m, sp.S.Zero) * m
        if a != 0 and b != 0:
            A, B = sp.Add.make_args(sp.expand(a)), sp.Add.make_args(sp.expand(b))
            if set(A) & set(B):
                for t in A:
                    if t not in B:
                        add(key(t), t * m, t * m, sp.S.Zero)
                for t in B:
                    if t not in A:
                        add(key(t), sp.S.Zero, sp.S.Zero, t * m)
                continue
            add(key(a) or key(b), own_term, a * m, b * m, (a, b))
        elif a != 0:
            add(key(a), own_term, a * m, sp.S.Zero)
        else:
            add(key(b), sp.S.Zero, sp.S.Zero, b * m)
    messages = [_describe(*group, coefficients, values) for group in keyed.values()] \
        if described else []
    return Located(c, messages, linear, terms, len(keyed))


def _same(a: sp.Expr, b: sp.Expr) -> bool:
    """a = b for coefficients (rational functions of the parameters): expanded first,
    which decides polynomials, and cancelled only where a denominator is left."""
    difference = sp.expand(a - b)
    if difference == 0:
        return True
    if not any(p.exp.is_negative for p in difference.atoms(sp.Pow)):
        return False
    return sp.cancel(difference) == 0


def _describe(hand_own, hand_value, derived_part, wholes, coefficients: set,
              values: dict) -> str:
    """One group of differing terms: missing, spurious, or hand where derived is right."""
    hand_txt, derived_txt = show(sp.factor(hand_own)), show(sp.factor(derived_part))
    if hand_value == 0:
        return f"missing {derived_txt}"
    if derived_part == 0:
        text = f"spurious {hand_txt}"
    else:
        text = f"{hand_txt} where {derived_txt} is right"
        ratio = sp.cancel(hand_value / derived_part)
        if ratio == -1:
            text += " (wrong sign)"
        elif len(wholes) == 1 and sp.cancel(wholes[0][0] * wholes[0][1] - 1) == 0:
            text += " (reciprocal coefficient)"
        elif ratio.is_number and ratio < 0:
            text += f" (wrong sign, and {show(-ratio)} times the right size)"
        elif ratio.is_number:
            text += f" ({show(ratio)} times the right one)"
    used = sorted(s.name for s in hand_own.free_symbols if s.name in coefficients)
    if used:
        text += " [" + ", ".join(f"{n} = {show(values[sp.Symbol(n)])}" for n in used) + "]"
    return text


# -- hand expressions against a space -----------------------------------------------------
class Hand:
    """A HandDerived resolved against a space: its expressions in model symbols (``math``)
    and in the user's own symbols (``own``), and how to show derived ones in the latter."""

    def __init__(self, hand: HandDerived, space: Space):
        model_names = set(space.names)
        #: notes on functions of time that name no model quantity, by their text
        self.functions: dict[str, str] = {}

        def convert(e):
            e, notes = functions_of_time((space.convert or (lambda x: x))(e), model_names)
            self.functions |= notes
            return e
        keys = {k: convert(v) for k, v in hand.symbols.items()}
        variables = set(space.variables)
        variable_names = {n for n, s in space.names.items() if s in variables}
        # one display symbol per model symbol (Gamma1 and Gamma1_0 name the same node)
        self.canon = {sp.Symbol(n): space.display[s] for n, s in space.names.items()
                      if s in space.display}
        resolved = {k: _plain(_substitute(v, keys)).xreplace(self.canon)
                    for k, v in keys.items()}
        self.coefficients, reverse, opaque = {}, {}, {}
        for k, v in resolved.items():
            free = [s for s in v.free_symbols if s.name in variable_names
                    or s.name not in model_names]
            if not free:
                self.coefficients[sp.Symbol(k)] = v
            elif len(free) == 1 and sp.diff(v, free[0], 2) == 0 \
                    and not sp.diff(v, free[0]).has(*free) and free[0].name in variable_names:
                s = free[0]
                reverse.setdefault(s, sp.cancel((sp.Symbol(k) - v.xreplace({s: 0}))
                                                / sp.diff(v, s)))
            else:
                opaque[k] = keys[k]
        self.reverse = reverse
        self.parameters = {n for n, s in space.names.items() if s not in space.variables}
        self.own, self.math, undefined = [], [], set()
        for e in map(convert, hand.expressions):
            own = _plain(_substitute(e, opaque)).xreplace(self.canon).xreplace(reverse)
            self.own.append(own)
            full = _plain(_substitute(e, keys))
            undefined |= {s.name for s in full.free_symbols
                          if s.name not in model_names and s.name not in self.functions}
            self.math.append(full.xreplace({s: space.names[s.name] for s in full.free_symbols
                                            if s.name in model_names}))
        self.undefined = tuple(sorted(undefined))
        self.space = space

    def show(self, expr: sp.Expr) -> sp.Expr:
        """A derived expression in the user's symbols where they invert, else public names."""
        return _plain(expr.xreplace(self.space.display)).xreplace(self.reverse)

    def bind(self, expr: sp.Expr) -> sp.Expr:
        """A display-level expression (plain symbols) in the model's symbols."""
        return expr.xreplace({s: self.space.names[s.name] for s in expr.free_symbols
                              if s.name in self.space.names})

    def locate(self, i: int, derived: sp.Expr, scale=None, described: bool = True
               ) -> Located:
        """Where hand expression i differs from ``derived``: at the factor ``scale`` when
        given, else the one :func:`_locate` chooses; the groups only counted unless
        ``described``."""
        return _locate(self.own[i], self.coefficients, self.show(derived),
                       {s.name for s in self.coefficients}, self.parameters, scale,
                       described)


def in_controls(space: Space, exprs) -> list | None:
    """The derived expressions with the controlled highest derivatives eliminated in favour
    of the control symbols (L̃ = C(q, y, EL(L)_a) becomes C(q, y, u)); None if impossible."""
    equations = [c - u for c, u in space.controls]
    unknowns = linear_unknowns(equations, space.leading, space.fixed)
    if unknowns is None:
        return None
    solution = solve_linear(equations, unknowns)
    return [sp.cancel(e.xreplace(solution)) for e in exprs]


# -- notes on recognisable mistakes -------------------------------------------------------
def scaled_increments(H, D, space: Space) -> str | None:
    """Increments ξ = τ⁻¹(w)/h mis-scaled (hand(ξ) = derived(s·ξ), s = h or 1/h), or a
    window's (ξ_k, ξ_{k+1}) replaced by (ξ_{k+1/2}, ξ_{k,k+1}) — the rule applied twice."""
    flat = [v for slot in space.scaled for v in slot]
    if not flat:
        return None
    for s, text in ((STEP, "h·ξ = τ⁻¹(w)"), (1 / STEP, "ξ/h = τ⁻¹(w)/h²")):
        if is_zero(H - D.xreplace({v: s * v for v in flat})):
            return (f"hand = derived with every increment ξ = τ⁻¹(w)/h replaced by {text}: "
                    f"its arguments are mis-scaled by {show(s)}")
    if len(space.scaled) == 2:
        twice = {a: (a + b) / 2 for a, b in zip(*space.scaled)} \
            | {b: (b - a) / STEP for a, b in zip(*space.scaled)}
        if is_zero(H - D.xreplace(twice)):
            return ("hand = derived evaluated at (ξ_{k+1/2}, ξ_{k,k+1}) in place of "
                    "(ξ_k, ξ_{k+1}): the midpoint and the difference quotient are taken twice")
    return None


def coefficient_note(hand: Hand, i: int, D) -> str | None:
    """When the hand expression uses named constants (the paper's P_i): the values that
    would make it agree, if any, against the ones it was given."""
    own = hand.own[i]
    keys = sorted((k for k in hand.coefficients if own.has(k)), key=str)
    if not keys:
        return None
    variables = [s for s in own.free_symbols | hand.show(D).free_symbols
                 if s not in keys and s.name not in hand.parameters]
    conditions = [c for c in _split(own - hand.show(D), variables).values() if c != 0]
    try:
        solutions = sp.solve(conditions, keys, dict=True)
    except NotImplementedError:
        return None
    if len(solutions) != 1 or set(solutions[0]) != set(keys):
        return None
    wrong = [k for k in keys if sp.cancel(solutions[0][k] - hand.coefficients[k]) != 0]
    right = ", ".join(f"{k} = {show(sp.factor(solutions[0][k]))}" for k in wrong)
    given = ", ".join(f"{k} = {show(hand.coefficients[k])}" for k in wrong)
    return f"agrees if {right}; given {given}"


def limit_note(hand: Hand, H, D) -> str | None:
    """For maps that must tend to the identity as h → 0 (the target map)."""
    try:
        h0, d0 = (sp.cancel(e).xreplace({STEP: 0}) for e in (H, D))
    except (ZeroDivisionError, ValueError):
        return None
    if h0.has(sp.zoo, sp.nan) or d0.has(sp.zoo, sp.nan) or is_zero(h0 - d0):
        return None
    first = sp.cancel(sp.diff(D, STEP).xreplace({STEP: 0}))
    return (f"as h → 0 the hand value tends to {show(hand.show(h0))}, the derived one to "
            f"{show(hand.show(d0))} (derived = {show(hand.show(d0))} + h·"
            f"({show(hand.show(first))}) + O(h²)): the hand map is not consistent")

