"""Bounds and path inequalities of an optimal-control problem (issue 21).

What the user writes in :func:`symvi.optimal_control`: ``bounds`` on the controls and on
the first-order coordinates of the algebroid (base coordinates q, fibre coordinates y:
joint limits, rate limits), and ``inequalities`` g(q, y, u) ≤ 0 (keep-out zones, cones).
Each side of a bound is a number, an expression in the parameters (a limit that changes
at run time) or None. Bounds on the controls act on the discrete controls u_k of every
window; bounds on coordinates and inequalities are evaluated as the controls are, at the
window's quadrature point (the rule's average; DESIGN.md §3), with u the discrete controls.
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import sympy as sp

from ..errors import ModelError
from .validation import NOT_NUMBERS, scalar

Interval = tuple[sp.Expr | None, sp.Expr | None]


def parameter_expression(value, what: str, defaults: Mapping[sp.Symbol, float],
                         hint: str = "") -> sp.Expr:
    """``value`` as a scalar expression in the parameters (``defaults``: symbol → default
    value), finite at their defaults; a :class:`ModelError` naming ``what`` (with
    ``hint`` when infinite) otherwise. A string or a boolean is refused, as the run time
    refuses them for numbers (``time_cost="1"`` would otherwise be parsed to 1)."""
    if isinstance(value, NOT_NUMBERS):
        raise ModelError(f"{what} must be a real number or an expression in the "
                         f"parameters, got {value!r}")
    expr = scalar(value, what)
    unknown = expr.free_symbols - set(defaults)
    if unknown:
        raise ModelError(f"the {what} uses {sorted(map(str, unknown))}, which are not "
                         f"parameters; it is a number or an expression in the parameters")
    if not sp.sympify(expr.xreplace(defaults)).is_finite:
        raise ModelError(f"the {what} is not finite ({expr}){hint}")
    return expr


def _interval(what: str, pair, defaults: Mapping[sp.Symbol, float]) -> Interval:
    """(lower, upper) of ``what``, each an expression in the parameters or None (open),
    checked to be a proper interval at the parameters' default values."""
    if not isinstance(pair, (tuple, list)) or len(pair) != 2:
        raise ModelError(f"bounds of {what} must be a pair (lower, upper), None for an open "
                         f"side; got {pair!r}")
    lower, upper = (None if value is None else
                    parameter_expression(value, f"{side} bound of {what}", defaults,
                                         "; give None for an open side")
                    for side, value in zip(("lower", "upper"), pair))
    if lower is not None and upper is not None \
            and not float(lower.xreplace(defaults)) < float(upper.xreplace(defaults)):
        raise ModelError(f"{what}: lower bound {lower} is not below upper bound {upper} (at "
                         f"the parameters' default values)")
    return lower, upper


def _named(inequalities) -> list[tuple[str, Any]]:
    if isinstance(inequalities, Mapping):
        return [(str(k), v) for k, v in inequalities.items()]
    if isinstance(inequalities, (sp.Expr, str)):
        inequalities = [inequalities]
    return [(f"g{i}", v) for i, v in enumerate(inequalities)]


def declared(bounds: Mapping | None, inequalities, controls: Sequence[sp.Symbol],
             coordinates: Sequence[sp.Symbol], defaults: Mapping[sp.Symbol, float],
             hint: str = ""):
    """(per control its :data:`Interval`, path inequalities as (name, g) with g ≤ 0 in the
    coordinates, controls and parameters), from what :func:`symvi.optimal_control` got;
    ``defaults`` maps each parameter symbol to its default value; ``hint`` ends the
    message of an inequality in unknown symbols."""
    by_name = {str(s): s for s in list(controls) + list(coordinates)}
    control_bounds = {u: (None, None) for u in controls}
    path: list[tuple[str, sp.Expr]] = []
    for key, pair in dict(bounds or {}).items():
        symbol = by_name.get(str(key))
        if symbol is None:
            raise ModelError(f"bounds given for {key!r}, which is not a control or coordinate; "
                             f"the controls are {[str(u) for u in controls]}, the coordinates "
                             f"{[str(c) for c in coordinates]}")
        is_control = symbol in control_bounds
        lower, upper = _interval(f"{'control' if is_control else 'coordinate'} {symbol}",
                                 pair, defaults)
        if is_control:
            control_bounds[symbol] = (lower, upper)
            continue
        if upper is not None:
            path.append((f"{symbol} <= {upper}", symbol - upper))
        if lower is not None:
            path.append((f"{symbol} >= {lower}", lower - symbol))
    allowed = set(controls) | set(coordinates) | set(defaults)
    for name, value in _named(inequalities or ()):
        g = scalar(value, f"inequality {name!r}")
        unknown = g.free_symbols - allowed
        if unknown:
            raise ModelError(f"inequality {name!r} uses {sorted(map(str, unknown))}; it is "
                             f"g(q, y, u) ≤ 0 in the coordinates {[str(c) for c in coordinates]}"
                             f", the controls {[str(u) for u in controls]} and parameters"
                             f"{hint}")
        if not g.free_symbols & (set(controls) | set(coordinates)):
            raise ModelError(f"inequality {name!r} ({g} <= 0) depends on no coordinate or control")
        path.append((f"{name}: {g} <= 0", g))
    return tuple(control_bounds[u] for u in controls), tuple(path)


def discrete(control_bounds: Sequence[Interval], path: Sequence[tuple[str, sp.Expr]],
             controls: Sequence[sp.Symbol], discrete_controls: Sequence[sp.Expr],
             average) -> tuple[tuple[str, sp.Expr], ...]:
    """The named inequalities c ≤ 0 of one window: the controls' bounds on the discrete
    controls, then each path inequality averaged by the rule (``average``: a continuous
    expression → its window value) with the controls replaced by the discrete ones."""
    out = []
    for u, u_d, (lower, upper) in zip(controls, discrete_controls, control_bounds):
        if upper is not None:
            out.append((f"{u} <= {upper}", u_d - upper))
        if lower is not None:
            out.append((f"{u} >= {lower}", lower - u_d))
    held = [sp.Dummy(str(u), real=True) for u in controls]
    for name, g in path:
        value = average(g.xreplace(dict(zip(controls, held))))
        out.append((name, value.xreplace(dict(zip(held, discrete_controls)))))
    return tuple(out)
