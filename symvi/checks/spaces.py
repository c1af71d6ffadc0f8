"""The derived object each ``equations`` target names, and the symbols a hand display of
it may use (:mod:`symvi.checks.equations`).

:func:`symbol_space` builds a :class:`Space`: for the continuous targets, the continuous
symbols of §3.3 (and for ``euler_lagrange`` the named jets of
:func:`symvi.checks.jets.continuous_equations`); for the discrete ones, one window's discrete
symbols (DESIGN.md §3), the stencil of the residual, or a trajectory for the discrete
action.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import sympy as sp

from ..discretisation.discretise import DiscreteModel, discretise, h as STEP, slot_symbols
from ..errors import ModelError
from .jets import continuous_equations
from .._runtime.core.model_info import Kernel as KernelName

if TYPE_CHECKING:
    from .hand import HandDerived

#: Targets compared in the continuous symbols (the others on discrete windows).
CONTINUOUS = ("controls", "constraints", "lagrangian", "euler_lagrange")
#: Targets that are the groupoid's algebroid itself (its base and fibre symbols).
ALGEBROID = ("anchor", "structure_functions", "variation", "lift")


@dataclass
class Space:
    """The derived expressions of one target and the symbols hand expressions may use."""

    derived: list
    names: dict            # name → model symbol (for binding)
    variables: list        # model symbols that are unknown quantities (not parameters, h)
    display: dict          # model symbol → plain Symbol of its public name
    candidates: list       # preferred unknowns of the equations mode, in order
    scaled: list = field(default_factory=list)   # increments ξ = τ⁻¹(w)/h, per slot
    controls: tuple = ()   # (control symbol, EL(L)_a) for continuous targets
    leading: list = field(default_factory=list)
    fixed: dict = field(default_factory=dict)    # parameter defaults and h for sampling
    convert: Any = None    # hand expression → the space's symbols (functions of time → jets)


def _window_names(groupoid, order, xs, fs) -> dict[str, sp.Symbol]:
    """Public name → slot symbol: the groupoid's discrete symbols, plus ``<base>_<j>`` for
    the base point of node j where the groupoid has no name for it (action groupoids)."""
    names = {}
    for public, value in groupoid.discrete_mapping(order, xs, fs).items():
        if isinstance(value, sp.Symbol):
            names.setdefault(public.name, value)
    for i, x0 in enumerate(xs[0]):
        base = next((n for n, v in names.items() if v == x0), None)
        if base is None:
            continue
        stem = base[:-2] if base.endswith("_0") else base
        names.setdefault(f"{stem}_0", x0)
        for j in range(1, len(xs)):
            if xs[j]:
                names.setdefault(f"{stem}_{j}", xs[j][i])
    return names


def symbol_space(hand: HandDerived, model, discrete: DiscreteModel | None, derived) -> Space:
    """The space of ``hand.target`` on ``model``: continuous symbols (§3.3) or one window's
    discrete symbols (DESIGN.md §3). ``discrete`` and ``derived`` are reused when passed."""
    params = {s.name: s for s in model.parameter_symbols}
    fixed = dict(model.parameters) | {STEP: 0.1}
    if hand.target in CONTINUOUS:
        return _continuous_space(hand, model, params, fixed)
    if hand.target in ALGEBROID:
        return _algebroid_space(hand.target, model, params, fixed)
    if hand.target == "residual":
        exprs, names, slots, fs = _residual_window(model, discrete, derived)
    elif hand.target == "discrete_action":
        exprs, names, slots, fs = _action(model, discrete, hand.elements)
    else:
        exprs, names, slots, fs = _window(hand.target, model, discrete)
    public = {v: sp.Symbol(k) for k, v in reversed(list(names.items()))}
    display = {s: public.get(s, sp.Symbol(s.name)) for s in slots}
    scaled = [[v for v, s in zip(f, model.groupoid.step_scaled()) if s] for f in fs]
    return Space(exprs, names | params | {"h": STEP}, slots, display, slots,
                 scaled=scaled, fixed=fixed)


def _continuous_space(hand: HandDerived, model, params: dict, fixed: dict) -> Space:
    """Controls, constraints or L̃ in the continuous symbols and the control symbols."""
    g, target = model.groupoid, hand.target
    if target == "euler_lagrange":
        return _euler_lagrange_space(model, params, fixed)
    if model.lagrangian is None:
        raise ModelError(f"model {model.name!r} has no continuous Lagrangian to compare "
                         f"with")
    count = len(model.controls)
    names = hand.controls or tuple(f"u{a + 1}" for a in range(count))
    if len(names) != count:
        raise ModelError(f"{len(names)} control names for the {count} controls of "
                         f"{model.name!r}")
    c = tuple(sp.Symbol(n, real=True) for n in names)
    cont = list(g.continuous_symbols(model.order))
    leading = [s for s in g.leading_symbols(model.order) if s in cont]
    exprs = {"controls": ([u - ci for ci, u in zip(c, model.controls)]
                          if hand.mode == "equations" else list(model.controls)),
             "constraints": list(model.constraints),
             "lagrangian": [model.lagrangian]}[target]
    if not exprs:
        raise ModelError(f"model {model.name!r} has no {target}")
    symbols = cont + list(c)
    return Space(exprs, {s.name: s for s in symbols} | params, symbols,
                 {s: sp.Symbol(s.name) for s in symbols},
                 list(c) if target == "controls" else leading,
                 controls=tuple(zip(c, model.controls)), leading=leading, fixed=fixed)


def _algebroid_space(target: str, model, params: dict, fixed: dict) -> Space:
    """The anchor ρ(q)y, the bracket C^γ_{αβ} a^α b^β of constant sections, or the complete
    lift (ρη, η̇ + C y η) of the model's algebroid (paper §3.3.1) — the variation whose
    stationarity gives the Euler–Lagrange equations the derivation uses — followed, for
    ``lift``, by the vertical lift (0, η)."""
    A = model.groupoid.algebroid()
    n = len(A.y)

    def named(stem: str, suffix: str = "") -> list:
        return [sp.Symbol(f"{stem}{a + 1}{suffix}", real=True) for a in range(n)]

    def bracket(a, b) -> list:
        return [sum((C[i, j] * a[i] * b[j] for i in range(n) for j in range(n)), sp.S.Zero)
                for C in A.structure]
    if target == "anchor":
        exprs, extra = list(A.anchor * sp.Matrix(A.y)), list(A.y)
    elif target == "structure_functions":
        a, b = named("a"), named("b")
        exprs, extra = bracket(a, b), a + b
    else:
        eta, eta_dot = named("eta"), named("eta", "_dot")
        exprs = list(A.anchor * sp.Matrix(eta)) + [
            rate + term for rate, term in zip(eta_dot, bracket(A.y, eta))]
        if target == "lift":                  # then the vertical lift (0, η)
            exprs += [sp.S.Zero] * len(A.q) + eta
        extra = list(A.y) + eta + eta_dot
    symbols = list(A.q) + extra
    names = [s.name for s in symbols]
    if len(set(names)) != len(names):
        raise ModelError(f"the {target} of {model.name!r}: its symbols "
                         f"{sorted({x for x in names if names.count(x) > 1})} repeat a name "
                         f"of the groupoid's coordinates")
    return Space(exprs, {s.name: s for s in symbols} | params, symbols,
                 {s: sp.Symbol(s.name) for s in symbols}, symbols, fixed=fixed)


def _euler_lagrange_space(model, params: dict, fixed: dict) -> Space:
    """EL_r(L + λ_AΦ^A) and Φ^A in named jet symbols; hand expressions may be written in
    functions of time (:func:`symvi.checks.jets.continuous_equations`)."""
    eqs = continuous_equations(model)
    symbols = list(eqs.symbols.values())
    return Space(list(eqs.equations), eqs.symbols | params, symbols,
                 {s: s for s in symbols}, list(eqs.leading), fixed=fixed, convert=eqs.named)


def _residual_window(model, discrete, derived) -> tuple[list, dict, list, list]:
    """(residual, names, slots, fibres) of the ``step`` kernel's stencil (§2.2)."""
    g = model.groupoid
    dk = derived if derived is not None else _derive(model, discrete)
    try:
        kernel = dk.kernel(KernelName.STEP)
    except StopIteration:
        raise ModelError(f"model {model.name!r} has no step residual (constrained models "
                         f"are solved as whole trajectories)") from None
    residual = dict(kernel.outputs)["residual"]
    for symbol, expr in reversed(kernel.definitions):
        residual = residual.xreplace({symbol: expr})
    m, n, K = g.source_dim, g.fibre_dim, 2 * dk.order
    x0 = tuple(kernel.z[:m])
    fs = [tuple(kernel.z[m + k * n:m + (k + 1) * n]) for k in range(K)]
    names = _window_names(g, K, [x0] + [()] * (K - 1), fs)
    slots = [v for f in reversed(fs) for v in f] + list(x0)
    return list(residual), names, slots, fs


def _window(target: str, model, discrete) -> tuple[list, dict, list, list]:
    """(expressions, names, slots, fibres) of L_d, Φ_d or β on one window."""
    g = model.groupoid
    dm = discrete if discrete is not None else discretise(model)
    xs, fs = [s[0] for s in dm.slots], [s[1] for s in dm.slots]
    names = _window_names(g, dm.order, xs, fs)
    slots = [v for j in reversed(range(dm.order)) for v in fs[j] + xs[j]]
    if target == "target_map":
        exprs = list(g.target(xs[0], fs[0], STEP))
        if not exprs:
            raise ModelError(f"the groupoid of {model.name!r} has no base: its target "
                             f"map is empty")
    else:
        exprs = [dm.lagrangian] if target == "discrete_lagrangian" else list(dm.constraints)
        if not exprs:
            raise ModelError(f"model {model.name!r} has no discrete constraints")
    return exprs, names, slots, fs


def _action(model, discrete, elements: int) -> tuple[list, dict, list, list]:
    """(Σ_k L_d, names, slots, fibres) on a trajectory of ``elements`` composable elements:
    one term per window of r consecutive elements, k = 0 … elements − r (§2.2, eq.
    hamprinc)."""
    g = model.groupoid
    dm = discrete if discrete is not None else discretise(model)
    if elements < dm.order:
        raise ModelError(f"a trajectory of {elements} elements has no window of "
                         f"{dm.order}")
    trajectory = slot_symbols(g, elements)
    xs, fs = [trajectory[0][0]], [s[1] for s in trajectory]
    for k in range(1, elements):
        # composable: a base coordinate the target map gives as a coordinate (a pair
        # node) is that coordinate; the others (action base points) stay free, named
        beta = g.target(xs[k - 1], fs[k - 1], STEP)
        xs.append(tuple(b if isinstance(b, sp.Symbol) else x
                        for b, x in zip(beta, trajectory[k][0])))
    window = [v for x, f in dm.slots for v in x + f]

    def term(k):
        values = [v for j in range(k, k + dm.order) for v in tuple(xs[j]) + tuple(fs[j])]
        return dm.lagrangian.xreplace(dict(zip(window, values)))
    total = sum((term(k) for k in range(elements - dm.order + 1)), sp.S.Zero)
    slots = list(dict.fromkeys(v for j in reversed(range(elements)) for v in fs[j] + xs[j]))
    return [total], _window_names(g, elements, xs, fs), slots, fs


def _derive(model, discrete):
    from ..derivation.derive import derive
    return derive(discrete if discrete is not None else discretise(model))
