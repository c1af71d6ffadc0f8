"""Discretisation: continuous Lagrangian → discrete Lagrangian L_d (DESIGN.md §3).

The output, :class:`DiscreteModel`, expresses L_d in *slot* coordinates: a first-order
L_d : G → R has one slot (x₀, f₀), a second-order L_d : G₂ → R two composable slots
(x₀, f₀), (x₁, f₁) (paper §3.1). The derivation engine only ever sees slots, so every
groupoid shares it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import sympy as sp

from ..errors import ModelError
from ..groupoids.base import Groupoid
from .rules import Rule
from ..declaration.symbols import h

if TYPE_CHECKING:
    from ..declaration.model import Model

Slot = tuple[tuple[sp.Symbol, ...], tuple[sp.Symbol, ...]]

@dataclass(frozen=True, eq=False)
class DiscreteModel:
    """L_d in slot coordinates, with everything later stages need (no Model inside)."""

    name: str
    groupoid: Groupoid
    order: int
    slots: tuple[Slot, ...]
    lagrangian: sp.Expr
    step: sp.Symbol
    parameters: tuple[sp.Symbol, ...]
    defaults: tuple[float, ...]
    continuous_lagrangian: sp.Expr | None
    fingerprint: str
    #: Discrete constraints Φ^A_d (slot coordinates) and their multipliers λ_A (paper
    #: §3.2: the augmented L_d + λ_A Φ^A_d on every window).
    constraints: tuple[sp.Expr, ...] = ()
    multipliers: tuple[sp.Symbol, ...] = ()
    #: What each constraint is, for messages: an unactuated direction's name in optimal
    #: control (its equation EL(L)_A = 0), else "constraint k".
    constraint_names: tuple[str, ...] = ()
    #: In optimal control, the fibre direction A of each constraint EL(L)_A = 0.
    unactuated: tuple[int, ...] = ()
    #: Controls at a window's quadrature point (slot coordinates).
    controls: tuple[sp.Expr, ...] = ()
    #: The controls' declared names (``tau1``, …), one per entry of :attr:`controls`.
    control_names: tuple[str, ...] = ()
    #: Declared Noether symmetries (:class:`symvi.declaration.symmetry.Symmetry`, base coordinates).
    symmetries: tuple = ()
    #: (name, Z_A) per symmetry Z that makes the constraints exactly dependent (variational
    #: controlled equations, Z without actuated components): Z's components along the
    #: constraints at the window's middle node x₁. The multipliers are then fixed only up
    #: to λ^k + c Z(x_k) (:mod:`symvi.declaration.control`).
    gauges: tuple[tuple[str, tuple[sp.Expr, ...]], ...] = ()
    #: Inequalities c ≤ 0 on every window (the controls' bounds, slot coordinates), their
    #: names and their multipliers z ≥ 0: the augmented L_d + λ·Φ_d + z·c of the
    #: interior-point solve (issue 21).
    inequalities: tuple[sp.Expr, ...] = ()
    inequality_names: tuple[str, ...] = ()
    inequality_multipliers: tuple[sp.Symbol, ...] = ()
    #: ρ of a free horizon (cost + ρ·T), or None (:mod:`symvi.declaration.control`).
    time_cost: sp.Expr | None = None
    #: Pure minimum time: the cost is T alone, L_d carries no curvature of its own and
    #: the interior point's barrier supplies it (:attr:`ControlSystem.pure_minimum_time`).
    pure_minimum_time: bool = False
    #: The inequalities that involve no control, on one element (the first slot's
    #: coordinates) by the groupoid's first first-order rule, and their names: checked
    #: on the fixed elements of the boundary data.
    boundary_inequalities: tuple[sp.Expr, ...] = ()
    boundary_names: tuple[str, ...] = ()
    #: Whether the last nodes are unknowns (end conditions other than fixed), and the
    #: end conditions ψ = 0 on the last element (the first slot's coordinates, by the
    #: groupoid's first first-order rule) with their names.
    end_free: bool = False
    end_conditions: tuple[sp.Expr, ...] = ()
    end_names: tuple[str, ...] = ()

    @property
    def window_multipliers(self) -> tuple[sp.Symbol, ...]:
        """Every multiplier of one window: λ of the constraints, then z of the
        inequalities (the layout of a window's multipliers in the compiled kernels)."""
        return self.multipliers + self.inequality_multipliers

    @property
    def window_constraints(self) -> tuple[sp.Expr, ...]:
        """Φ_d, then the inequalities: the functions the window multipliers weigh."""
        return self.constraints + self.inequalities


def slot_symbols(groupoid: Groupoid, order: int) -> tuple[Slot, ...]:
    """Fresh coordinate symbols (x_j, f_j) of the ``order`` slots of L_d."""
    m, n = groupoid.source_dim, groupoid.fibre_dim
    return tuple((tuple(sp.Dummy(f"X{j}_{i}", real=True) for i in range(m)),
                  tuple(sp.Dummy(f"F{j}_{i}", real=True) for i in range(n)))
                 for j in range(order))


def discretise(model: "Model") -> DiscreteModel:
    """Turn a validated :class:`~symvi.declaration.model.Model` into a :class:`DiscreteModel`."""
    g = model.groupoid
    slots = slot_symbols(g, model.order)
    xs, fs = [s[0] for s in slots], [s[1] for s in slots]
    system = model.control_system
    gauges = ()
    rule = g.rule(model.discretisation) if model.lagrangian is not None else None
    if system is not None and system.equations == "variational":
        Ld, constraints, controls = _variational_control(system, g, rule, xs, fs)
        gauges = _gauges(model, system, xs[1])
    elif model.lagrangian is not None:
        Ld = rule.build(g, model.lagrangian, xs, fs, h)
        constraints = tuple(rule.build(g, c, xs, fs, h) for c in model.constraints)
        controls = tuple(rule.average(g, u, xs, fs, h) for u in model.controls)
    else:
        mapping = g.discrete_mapping(model.order, xs, fs)
        Ld = model.discrete_lagrangian.xreplace(mapping)
        constraints, controls = tuple(c.xreplace(mapping) for c in model.constraints), ()
    multipliers = tuple(sp.Dummy(f"lambda{a}", real=True) for a in range(len(constraints)))
    named = () if system is None else system.inequalities(
        controls, lambda F: rule.average(g, F, xs, fs, h))
    boundary = () if system is None else _on_one_element(model, system, xs[0], fs[0])
    return DiscreteModel(name=model.name, groupoid=g, order=model.order, slots=slots,
                         lagrangian=Ld, step=h, parameters=model.parameter_symbols,
                         defaults=model.parameter_defaults,
                         continuous_lagrangian=model.lagrangian,
                         fingerprint=model.fingerprint(), constraints=constraints,
                         multipliers=multipliers, controls=controls,
                         control_names=_control_names(system, len(controls)),
                         constraint_names=_constraint_names(model, len(constraints)),
                         unactuated=() if system is None else system.unactuated(g.fibre_dim),
                         symmetries=tuple(model.symmetries), gauges=gauges,
                         inequalities=tuple(c for _, c in named),
                         inequality_names=tuple(n for n, _ in named),
                         inequality_multipliers=tuple(sp.Dummy(f"z{a}", real=True)
                                                      for a in range(len(named))),
                         time_cost=None if system is None else system.time_cost,
                         pure_minimum_time=system is not None and system.pure_minimum_time,
                         boundary_inequalities=tuple(c for _, c in boundary),
                         boundary_names=tuple(n for n, _ in boundary),
                         **_end(model, system, xs[0], fs[0]))


def _constraint_names(model: "Model", count: int) -> tuple[str, ...]:
    """:attr:`DiscreteModel.constraint_names`."""
    system = model.control_system
    if system is None:
        return tuple(f"constraint {k + 1}" for k in range(count))
    names = model.groupoid.component_names()
    return tuple(names[A] for A in system.unactuated(len(names)))


def _control_names(system, count: int) -> tuple[str, ...]:
    """:attr:`DiscreteModel.control_names`: the declared control symbols' names, or
    ``u1``, … where a system declares none for some of its controls."""
    declared = () if system is None else tuple(str(u) for u in system.controls)
    return declared if len(declared) == count else tuple(f"u{i + 1}" for i in range(count))


def _on_one_element(model: "Model", system, x, f) -> tuple[tuple[str, sp.Expr], ...]:
    """The control-free inequalities on the element (x, f) by the groupoid's first
    first-order rule (the midpoint on the pair groupoid, ξ on a Lie group), those that
    it expresses in (x, f) and the parameters alone (not, say, one in q̈)."""
    average, known = _one_element(model, x, f)
    return tuple((name, c) for name, c in system.state_inequalities(average)
                 if c.free_symbols <= known)


def _one_element(model: "Model", x, f):
    """(F ↦ F on the element (x, f) by the groupoid's first first-order rule, the symbols
    such an expression may use)."""
    g = model.groupoid
    first = g.rules(1)[0]
    known = set(x) | set(f) | set(model.parameter_symbols) | {h}
    return (lambda F: first.average(g, F, [x], [f], h)), known


def _end(model: "Model", system, x, f) -> dict:
    """The :class:`DiscreteModel` fields of the final end (``end_free``,
    ``end_conditions``, ``end_names``): ψ on the last element (x, f)."""
    if system is None or system.end is None:
        return {}
    average, known = _one_element(model, x, f)
    conditions = []
    for name, psi in system.end:
        on_element = average(psi)
        if not on_element.free_symbols <= known:
            raise ModelError(f"end condition {name!r} cannot be written on one element by "
                             f"the groupoid's first-order rule")
        conditions.append(on_element)
    return dict(end_free=True, end_conditions=tuple(conditions),
                end_names=tuple(name for name, _ in system.end))


def node_variation(groupoid: Groupoid, lagrangian: sp.Expr, rule: Rule, xs, fs) -> sp.Matrix:
    """The discrete Euler–Lagrange expression of the first-order L_d = ``rule``(L) at the
    node shared by the elements (xs[0], fs[0]) and (xs[1], fs[1]) (paper §2.2): the
    variation of L_d(g₀) + L_d(g₁) when that node moves, right(g₀)ᵀ∇L_d(g₀) +
    left(g₁)ᵀ∇L_d(g₁).

    Each L_d is written with its element's target as a named point e: moving the node
    moves e₀ = xs[1] as it moves the node's base point (the base rows of left(g₁)) and
    leaves e₁ = β(g₁) fixed. The chain rule through e keeps β, a rational function of f
    on an action groupoid, out of every derivative.
    """
    m = groupoid.source_dim
    ends = [tuple(sp.Dummy(f"e{j}_{i}", real=True) for i in range(m)) for j in range(2)]
    parts = [rule.build(groupoid, lagrangian, [x, e], [f], h) for x, e, f in zip(xs, ends, fs)]
    grads = [sp.Matrix([sp.diff(Ld, s) for s in tuple(x) + tuple(f)])
             for Ld, x, f in zip(parts, xs, fs)]
    left = groupoid.left(xs[1], fs[1], h)
    total = groupoid.right(xs[0], fs[0], h).T * grads[0] + left.T * grads[1]
    if m:
        total += left[:m, :].T * sp.Matrix([sp.diff(parts[0], e) for e in ends[0]])
    beta = groupoid.target(xs[1], fs[1], h)
    return total.xreplace(dict(zip(ends[0], xs[1])) | dict(zip(ends[1], beta)))


def _variational_control(system, g: Groupoid, rule: Rule, xs, fs):
    """(L̃_d, Φ_d, u_d) on one window from the forced discrete Euler–Lagrange equations of
    the first-order L_d of the mechanical Lagrangian (:mod:`symvi.declaration.control`): with D the
    node variation, u = −D_a/h on the actuated directions, Φ_d = −D_A on the others
    (both ≈ EL(L), resp. h·EL(L), as the paper's rule gives them) and L̃_d the rule's
    quadrature of the cost at u."""
    D = node_variation(g, system.lagrangian, g.rules(1)[0], xs, fs)
    controls = tuple(-D[a] / h for a in system.actuated)
    constraints = tuple(-D[A] for A in range(g.fibre_dim) if A not in system.actuated)
    Ld = rule.build(g, system.cost, xs, fs, h).xreplace(dict(zip(system.controls, controls)))
    return Ld, constraints, controls


def mechanical_model(model: "Model") -> DiscreteModel:
    """The first-order L_d of an optimal-control model's mechanical Lagrangian L (the
    groupoid's first-order rule), with the symmetries that make its variational
    constraints dependent: :mod:`symvi.checks.noether` verifies their invariance there."""
    system, g = model.control_system, model.groupoid
    (X, F), = slots = slot_symbols(g, 1)
    rule = g.rules(1)[0]
    names = {name for name, _ in _gauges(model, system, X)}
    return DiscreteModel(name=model.name, groupoid=g, order=1, slots=slots,
                         lagrangian=rule.build(g, system.lagrangian, [X], [F], h), step=h,
                         parameters=model.parameter_symbols, defaults=model.parameter_defaults,
                         continuous_lagrangian=system.lagrangian,
                         fingerprint=model.fingerprint(),
                         symmetries=tuple(z for z in model.symmetries if z.name in names))


def _gauges(model: "Model", system, x_middle) -> tuple[tuple[str, tuple[sp.Expr, ...]], ...]:
    """Each declared symmetry without actuated components, restricted to the unactuated
    directions at the window's middle node: the exact dependencies of Φ_d. A symmetry
    with a potential is left out (its identity involves the potential)."""
    at_node = dict(zip(model.groupoid.algebroid().q, x_middle))
    out = []
    for z in model.symmetries:
        if z.potential != 0 or any(z.section[a] != 0 for a in system.actuated):
            continue
        section = tuple(c.xreplace(at_node) for A, c in enumerate(z.section)
                        if A not in system.actuated)
        if any(c != 0 for c in section):
            out.append((z.name, section))
    return tuple(out)
