"""Optimal control of mechanical systems on Lie algebroids (paper §3.3, DESIGN.md §4).

A controlled mechanical system lives on the Lie algebroid AG of a groupoid: base
coordinates q, fibre coordinates y, anchor ρ(q) and structure functions C(q)
(:meth:`Groupoid.algebroid`), with a Lagrangian L(q, y). Its controlled equations are
EL(L)_a = u_a on the actuated directions a and EL(L)_A = 0 on the others, with q̇ = ρ(q) y
and the Euler–Lagrange operator of Appendix C.2

    EL(L)_α = d/dt ∂L/∂y^α − ρ^i_α ∂L/∂q^i + C^γ_{αβ} y^β ∂L/∂y^γ,
    d/dt F(q, y) = ∂F/∂q^i ρ^i_β y^β + ∂F/∂y^β ẏ^β.

Minimising ∫ C(q, y, u) dt is then the second-order variational problem with
L̃(q, y, ẏ) = C(q, y, EL(L)_a) (eq. ``costLtilde``), constrained by Φ^A = EL(L)_A = 0
when underactuated (§3.3.2). :func:`optimal_control` builds that problem as a
:class:`~symvi.declaration.model.Model` with constraints; the groupoid's second-order rule discretises
L̃ and Φ (DESIGN.md §3) and the whole-trajectory solve finds the optimal path, its
multipliers and the controls u_k = EL(L)_a at each window's quadrature point.

That is the paper's discretisation (``equations="paper"``). The alternative
``equations="variational"`` discretises the controlled equations themselves, as the forced
discrete Euler–Lagrange equations of the first-order L_d of L (discrete mechanics and
optimal control): on the window (g_{k−1}, g_k, g_{k+1}), D_k = the node variation of
L_d(g_{k−1}, g_k) + L_d(g_k, g_{k+1}) at g_k (paper §2.2), u_k = −D_{k,a}/h, Φ^A_d = −D_{k,A}
and L̃_d = h C(q, y, u_k). Its discrete Noether identity is exact: for a symmetry Z of L
with no actuated component, Σ_k Z(x_k)·Φ_d^k telescopes to boundary terms, so the
constraints are exactly dependent and the multipliers are fixed only up to λ^k + c Z(x_k).
The compiled ``gauge`` kernel lets the solver fix c (:mod:`symvi._runtime.bvp.gauge`), where
with the paper's rule the identity holds only to O(h⁴) and the optimality system is
singular in double precision from N ≈ 100 (tests/test_constraint_degeneracy.py).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import sympy as sp

from ..errors import ModelError
from ..groupoids.base import Algebroid, Groupoid
from .inequalities import declared, discrete, parameter_expression
from .model import Example, Model, _sympify_parameters
from .symmetry import Symmetry
from .validation import scalar

#: How the controlled equations are discretised (see the module docstring).
EQUATIONS = ("paper", "variational")


@dataclass(frozen=True)
class ControlSystem:
    """The controlled mechanical system behind an optimal-control :class:`Model` (paper
    §3.3.1): Lagrangian L(q, y), cost C(q, y, u), one control symbol per actuated fibre
    direction, and the discretisation of its controlled equations (:data:`EQUATIONS`)."""

    lagrangian: sp.Expr
    cost: sp.Expr
    controls: tuple[sp.Symbol, ...]
    actuated: tuple[int, ...]
    equations: str = "paper"
    #: Per control, its (lower, upper) bound: None (unbounded) or an expression in the
    #: parameters, so that a limit can change at run time (issue 21).
    bounds: tuple[tuple[sp.Expr | None, sp.Expr | None], ...] = ()
    #: Named path inequalities g(q, y, u) ≤ 0, the coordinates' bounds among them
    #: (:mod:`symvi.declaration.inequalities`).
    path_inequalities: tuple[tuple[str, sp.Expr], ...] = ()
    #: ρ of a free horizon (cost C + ρ·T over a horizon T to be optimised), an expression
    #: in the parameters; None for a fixed horizon.
    time_cost: sp.Expr | None = None
    #: The final end: None (fixed: both nodes of the last element given), () (free) or
    #: named equalities ψ(q, y) = 0 in the first-order symbols and parameters, on the
    #: last element (:func:`end_conditions`).
    end: tuple[tuple[str, sp.Expr], ...] | None = None

    def fingerprint(self) -> str:
        return ":".join([self.equations, sp.srepr(self.lagrangian), sp.srepr(self.cost),
                         sp.srepr(self.controls), repr(self.actuated), sp.srepr(self.bounds),
                         sp.srepr(self.path_inequalities), sp.srepr(self.time_cost),
                         sp.srepr(self.end)])

    @property
    def pure_minimum_time(self) -> bool:
        """The cost is T alone (C independent of the controls, ρ given): the controls are
        determined only through their bounds, the Lagrangian C∘u is not regular and the
        barrier of the interior point supplies the curvature (issue 50)."""
        return self.time_cost is not None and not self.cost.free_symbols & set(self.controls)

    def unactuated(self, n: int) -> tuple[int, ...]:
        """The fibre directions no control acts on, in the order of the constraints
        Φ^A = EL(L)_A = 0 they give (paper §3.3.2)."""
        return tuple(A for A in range(n) if A not in self.actuated)

    def inequalities(self, controls: Sequence[sp.Expr], average) -> tuple[tuple[str, sp.Expr], ...]:
        """The named inequalities c ≤ 0 of one window, given its discrete controls and
        the rule's ``average`` (:func:`symvi.declaration.inequalities.discrete`)."""
        return discrete(self.bounds, self.path_inequalities, self.controls, controls, average)

    def state_inequalities(self, average) -> tuple[tuple[str, sp.Expr], ...]:
        """The named path inequalities that involve no control (bounds on coordinates,
        keep-out zones), each averaged by ``average`` over one element: what fixed
        boundary elements must satisfy (no control is defined there)."""
        return tuple((name, average(g)) for name, g in self.path_inequalities
                     if not g.free_symbols & set(self.controls))


def euler_lagrange_operator(algebroid: Algebroid, lagrangian: sp.Expr) -> sp.Matrix:
    """EL(L) of a Lagrangian L(q, y) on ``algebroid`` (paper Appendix C.2), an n-vector in
    (q, y, ẏ). Its vanishing is the Euler–Lagrange (Euler–Poincaré, Lagrange–Poincaré)
    equations; on TQ it is d/dt ∂L/∂q̇ − ∂L/∂q, on so(3) with L = ½ΩᵀIΩ it is
    IΩ̇ + Ω×IΩ."""
    q, y, ydot = algebroid.q, algebroid.y, algebroid.ydot
    rho, C = algebroid.anchor, algebroid.structure
    qdot = rho * sp.Matrix(y) if q else sp.zeros(0, 1)
    dLdy = [sp.diff(lagrangian, v) for v in y]
    dLdq = sp.Matrix([sp.diff(lagrangian, v) for v in q])

    def ddt(F):
        return sum((sp.diff(F, a) * b for a, b in zip(q, qdot)), sp.S.Zero) \
            + sum((sp.diff(F, a) * b for a, b in zip(y, ydot)), sp.S.Zero)

    n = len(y)
    out = []
    for alpha in range(n):
        anchor_term = (rho[:, alpha].T * dLdq)[0, 0] if q else sp.S.Zero
        bracket = sum((C[g][alpha, b] * y[b] * dLdy[g] for g in range(n) for b in range(n)),
                      sp.S.Zero)
        out.append(sp.expand(ddt(dLdy[alpha]) - anchor_term + bracket))
    return sp.Matrix(out)


def _actuated(actuated, n: int) -> tuple[int, ...]:
    if actuated is None:
        return tuple(range(n))
    indices = tuple(int(a) for a in actuated)
    bad = [a for a in indices if not 0 <= a < n]
    if bad or len(set(indices)) != len(indices) or not indices:
        raise ModelError(f"actuated directions must be distinct indices in 0..{n - 1} of the "
                         f"fibre coordinates, got {list(actuated)}")
    return tuple(sorted(indices))


def _control_symbols(controls, count: int) -> tuple[sp.Symbol, ...]:
    if isinstance(controls, str):
        controls = controls.replace(",", " ").split()
    symbols = tuple(sp.Symbol(c, real=True) if isinstance(c, str) else c for c in controls)
    if not all(isinstance(s, sp.Symbol) for s in symbols) or len(set(symbols)) != len(symbols):
        raise ModelError(f"controls must be distinct SymPy symbols (or names), got {controls!r}")
    if len(symbols) != count:
        raise ModelError(f"{len(symbols)} control symbols for {count} actuated directions")
    return symbols


def _time_cost(value, defaults: Mapping[sp.Symbol, float]) -> sp.Expr | None:
    """ρ of a free horizon: an expression in the parameters, positive at their defaults
    (with ρ ≤ 0 nothing stops the horizon from growing without end)."""
    if value is None:
        return None
    rho = parameter_expression(value, "time_cost", defaults)
    if not float(rho.xreplace(defaults)) > 0:
        raise ModelError(f"time_cost ρ = {rho} is not positive (at the parameters' default "
                         f"values): with no cost on T and no end condition fixing it, a free "
                         f"horizon has no optimum")
    return rho


def _pure_minimum_time(name: str, controls: Sequence[sp.Symbol], rho: sp.Expr | None,
                       bounds: Sequence[tuple[sp.Expr | None, sp.Expr | None]],
                       path: Sequence[tuple[str, sp.Expr]],
                       defaults: Mapping[sp.Symbol, float]) -> None:
    """Check a cost that does not depend on the controls: only pure minimum time (a free
    horizon, issue 50) is well posed so, and only with every control bounded on both
    sides — by its bounds, or by a path inequality g ≤ 0 that grows without bound as the
    control does (u² ≤ 1, ‖τ‖ ≤ τ_max; not x·u ≤ 1, open where x = 0) — since an
    unbounded control reaches any state in an arbitrarily short time."""
    if rho is None:
        raise ModelError(f"the cost of {name!r} does not depend on the controls "
                         f"{list(map(str, controls))}; with a fixed horizon the controls "
                         f"are then left undetermined (give a control cost, or time_cost "
                         f"for pure minimum time)")
    open_ = [str(u) for u, (lower, upper) in zip(controls, bounds)
             if not ((upper is not None or _limits(u, +1, path, defaults))
                     and (lower is not None or _limits(u, -1, path, defaults)))]
    if open_:
        raise ModelError(f"pure minimum time (the cost of {name!r} does not depend on the "
                         f"controls) needs every control bounded on both sides, by its "
                         f"bounds or an inequality growing with it; {open_} "
                         f"{'is' if len(open_) == 1 else 'are'} not, and an unbounded "
                         f"control reaches the end in an arbitrarily short time")


#: Values of the other symbols at which an inequality must grow with a control
#: (:func:`_limits`): generic, of both signs.
_SAMPLES = ((0.7318, -1.2391, 0.4127, -0.8853), (-0.5531, 0.9174, -1.4462, 0.2659))


def _limits(u: sp.Symbol, direction: int, path: Sequence[tuple[str, sp.Expr]],
            defaults: Mapping[sp.Symbol, float]) -> bool:
    """Whether some path inequality g ≤ 0 has g → +∞ as u → direction·∞ at generic
    values of every other symbol (the parameters at their defaults): it bounds u there."""
    for _, g in path:
        if u not in g.free_symbols:
            continue
        others = sorted(g.free_symbols - {u} - set(defaults), key=str)
        grows = True
        for sample in _SAMPLES:
            values = dict(defaults) | {v: sample[i % len(sample)] for i, v in enumerate(others)}
            try:
                limit = sp.limit(g.xreplace(values), u, direction * sp.oo)
            except (NotImplementedError, ValueError, TypeError):
                limit = None
            grows = grows and limit == sp.oo
        if grows:
            return True
    return False


def end_conditions(end: Any, groupoid: Groupoid, defaults: Mapping[sp.Symbol, float],
                   controls: Sequence[sp.Symbol]) -> tuple[tuple[str, sp.Expr], ...] | None:
    """:attr:`ControlSystem.end` from ``optimal_control(end=...)``: ``"fixed"`` (None),
    ``"free"`` (()), or ψ — one expression, a list, or a mapping name → expression — in
    the first-order symbols of ``groupoid`` (q, q̇ or ξ) and the parameters, at most as
    many as the state has coordinates."""
    if isinstance(end, str) and end in ("fixed", "free"):
        return None if end == "fixed" else ()
    if isinstance(end, str) or end is None:
        raise ModelError(f"end must be 'fixed', 'free' or the end conditions ψ(q, y) = 0 "
                         f"(an expression, a list or a mapping name → expression), got {end!r}")
    named = list(end.items()) if isinstance(end, Mapping) else \
        [(f"psi{i}", v) for i, v in enumerate([end] if isinstance(end, sp.Expr) else end)]
    coordinates = groupoid.continuous_symbols(1)
    state = groupoid.source_dim + groupoid.fibre_dim
    if not named or len(named) > state:
        raise ModelError(f"{len(named)} end conditions ψ = 0 for a state of {state} "
                         f"coordinates {[str(c) for c in coordinates]}: give between 1 and "
                         f"{state}, or end='free'")
    out = []
    for name, value in named:
        psi = scalar(value, f"end condition {name!r}")
        unknown = psi.free_symbols - set(coordinates) - set(defaults)
        if unknown:
            hint = " (controls are not part of the state)" if unknown & set(controls) else ""
            raise ModelError(f"end condition {name!r} uses {sorted(map(str, unknown))}{hint}; "
                             f"it is ψ(q, y) = 0 in {[str(c) for c in coordinates]} and the "
                             f"parameters")
        out.append((str(name), psi))
    return tuple(out)


#: Where an inequality names symbols of its own on a groupoid with a matrix group: the
#: configuration is reached through the group acting on itself (issue 50, item 4).
_CONFIGURATION_HINT = ("; an inequality on a matrix group's configuration g (a world-frame "
                       "position, a pointing direction) is written on "
                       "ActionGroupoid.on_itself(group), in the entries of its "
                       ".configuration")


def optimal_control(name: str, groupoid: Groupoid, lagrangian: Any, cost: Any,
                    controls: Sequence[Any] | str, actuated: Sequence[int] | None = None,
                    parameters: Mapping[Any, float] | None = None,
                    discretisation: str | None = None, example: Example | None = None,
                    description: str = "", equations: str = "paper",
                    symmetries: Sequence[Symmetry] = (),
                    bounds: Mapping[Any, tuple[Any, Any]] | None = None,
                    inequalities: Sequence[Any] | Mapping[str, Any] = (),
                    time_cost: Any = None, end: Any = "fixed") -> Model:
    """The optimal-control problem min ∫ C(q, y, u) dt of a mechanical system on the
    algebroid of ``groupoid``, as a constrained second-order :class:`Model`.

    Parameters
    ----------
    groupoid:
        Supplies the algebroid (q, y, ρ, C) and the discretisation.
    lagrangian:
        L(q, y) in the groupoid's first-order symbols (e.g. ``G.q, G.qdot``; ``G.xi``).
    cost:
        C(q, y, u) in those symbols and the control symbols; free of the controls only
        in pure minimum time (``time_cost``).
    controls:
        One symbol per actuated direction: u_a = EL(L)_a.
    actuated:
        Indices a of the actuated fibre directions (default: all). The others give the
        constraints Φ^A = EL(L)_A = 0 (an underactuated system, paper §3.3.2).
    parameters, discretisation, example, description, symmetries:
        As for :class:`Model` (the discretisation defaults to the groupoid's second-order
        rule).
    equations:
        ``"paper"``: L̃ and Φ discretised by the rule (paper §3.3); ``"variational"``: the
        forced discrete Euler–Lagrange equations of the first-order L_d of L (module
        docstring). With ``"variational"``, a symmetry of L with no actuated component
        makes the constraints exactly dependent, and the solver fixes the multipliers'
        freedom it leaves.
    bounds:
        ``{symbol: (lower, upper)}`` for controls and for the first-order coordinates
        (``G.q``, ``G.qdot`` or ``G.xi``: joint and rate limits), each side a number, an
        expression in the parameters (a limit that can change at run time) or None
        (open); a thruster that only pushes is ``{u: (0, None)}``.
    inequalities:
        Path inequalities g(q, y, u) ≤ 0 (a list, or a mapping name → g), e.g. a
        keep-out disc ``r**2 - (x - a)**2 - (y - b)**2``. Bounds on coordinates and
        inequalities hold at every window's quadrature point, bounds on controls for
        the discrete controls u_k (:mod:`symvi.declaration.inequalities`); with any of
        them the whole-trajectory solve is a primal–dual interior-point Newton
        (:mod:`symvi._runtime.bounded.interior`).
    time_cost:
        ρ > 0 (a number or an expression in the parameters) makes the horizon T free:
        the solve minimises J_d + ρ·T over the path and T = N·h, the ``h`` given to
        ``solve_bvp`` being the first guess (:mod:`symvi._runtime.bvp.horizon`). With
        C = 0 (any C free of the controls) the problem is pure minimum time: every
        control must then be bounded on both sides or appear in an inequality, else
        :class:`ModelError` (an unbounded control reaches the end in no time); the
        interior point's barrier supplies the curvature the Lagrangian lacks.
    end:
        The final end of the path: ``"fixed"`` (both nodes of the last element given to
        ``solve_bvp``), ``"free"`` (the last nodes are unknowns: the natural boundary
        conditions hold), or end conditions ψ(q, y) = 0 — one expression, a list, or a
        mapping name → expression in the first-order symbols and the parameters — on
        the last element, by the groupoid's first first-order rule (the midpoint on the
        pair groupoid, ξ on a Lie group), with multipliers ν (``res.end_multipliers``).
        On a Lie group the configuration enters no equation: ψ constrains ξ (and an
        action groupoid's base point). The start stays fixed.
    """
    if equations not in EQUATIONS:
        raise ModelError(f"equations must be one of {EQUATIONS}, got {equations!r}")
    algebroid = groupoid.algebroid()
    parameters = dict(parameters or {})
    L = scalar(lagrangian, "Lagrangian")
    known = set(groupoid.continuous_symbols(1)) | {
        sp.Symbol(k, real=True) if isinstance(k, str) else k for k in parameters}
    unknown = L.free_symbols - known
    if unknown:
        symbols = list(map(str, groupoid.continuous_symbols(1)))
        raise ModelError(f"undeclared symbol(s) {sorted(map(str, unknown))} in the Lagrangian "
                         f"of {name!r}; it is L(q, y) in {symbols} and parameters")
    directions = _actuated(actuated, len(algebroid.y))
    u = _control_symbols(controls, len(directions))
    C = scalar(cost, "cost")
    unknown = C.free_symbols - known - set(u)
    if unknown:
        raise ModelError(f"undeclared symbol(s) {sorted(map(str, unknown))} in the cost of "
                         f"{name!r}; it is C(q, y, u) with controls {list(map(str, u))}")
    defaults = dict(_sympify_parameters(parameters))
    rho = _time_cost(time_cost, defaults)
    bounds_u, path = declared(bounds, inequalities, u, groupoid.continuous_symbols(1), defaults,
                              _CONFIGURATION_HINT if groupoid.matrix_groups() else "")
    if not C.free_symbols & set(u):
        _pure_minimum_time(name, u, rho, bounds_u, path, defaults)
    final = end_conditions(end, groupoid, defaults, u)
    if final is not None and symmetries and equations == "variational":
        raise ModelError("declared symmetries fix the multipliers' freedom of exactly "
                         "dependent constraints between fixed ends; with end conditions "
                         "other than 'fixed' their identity has a free boundary term — "
                         "leave end='fixed' or the symmetries out")
    EL = euler_lagrange_operator(algebroid, L)
    forces = [EL[a] for a in directions]
    system = ControlSystem(L, C, u, directions, equations, bounds_u, path, rho, final)
    return Model(
        name=name, groupoid=groupoid, lagrangian=C.xreplace(dict(zip(u, forces))),
        discretisation=discretisation or groupoid.default_discretisation(2),
        parameters=parameters, example=example, description=description,
        constraints=[EL[A] for A in system.unactuated(len(EL))],
        controls=forces, symmetries=symmetries, control_system=system)
