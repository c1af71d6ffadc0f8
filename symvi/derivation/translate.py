"""SymPy ↔ SymEngine, each distinct subexpression translated once.

The expressions of a derivation are trees with much sharing: se3_body's step Jacobian
counts 181,000 operations as a tree and 1,073 distinct subexpressions. SymEngine's own
translations (``symengine.sympify``, ``_sympy_``) and SymPy's ``atoms`` and
``free_symbols`` walk the tree; here every distinct node is visited once, children
first, and built by the same constructor the library's translation calls for it (SymEngine
``add``, ``mul``, ``**``, its functions; SymPy ``Add``, ``Mul``, ``**``, its functions), so
the result is the very expression the library would build. A node of a kind not handled
here is handed to the library's translation whole.
"""
from __future__ import annotations

from typing import Callable, Iterable

import symengine as se
import sympy as sp
from symengine.lib.symengine_wrapper import OneArgFunction, mul

#: SymPy functions of one argument that SymEngine translates to its function of that name.
_ENGINE_FUNCTIONS = {getattr(sp, name): getattr(se, name) for name in (
    "sin", "cos", "tan", "cot", "csc", "sec", "asin", "acos", "atan", "acot", "sinh",
    "cosh", "tanh", "asinh", "acosh", "atanh", "log")}


def distinct_nodes(exprs: Iterable[sp.Basic]) -> set[sp.Basic]:
    """Every distinct subexpression of ``exprs`` (a tree walk visits shared ones once)."""
    seen: set[sp.Basic] = set()
    stack = list(exprs)
    while stack:
        x = stack.pop()
        if x not in seen:
            seen.add(x)
            stack.extend(x.args)
    return seen


def _post_order(root, memo: dict, leaf: Callable, build: Callable) -> None:
    """memo[x] = the translation of every node x under ``root``: ``leaf(x)`` if that is
    not None (asked once per node), else ``build(x, translated arguments)``."""
    stack = [(root, False)]
    while stack:
        x, expanded = stack.pop()
        if x in memo:
            continue
        if expanded:
            memo[x] = build(x, [memo[a] for a in x.args])
            continue
        done = leaf(x)
        if done is not None:
            memo[x] = done
            continue
        stack.append((x, True))
        stack.extend((a, False) for a in x.args if a not in memo)


def to_engine(expr: sp.Basic, memo: dict, leaf: Callable[[sp.Basic], object | None],
              whole: Callable[[sp.Basic], object] = se.sympify):
    """``expr`` in SymEngine. ``leaf(x)`` is the translation of a node to be taken as it
    is (a stand-in), else None; a node this module does not build (not
    :func:`translatable`) is translated by ``whole`` (SymEngine's own translation), atoms
    by ``symengine.sympify``."""
    def taken(x):
        done = leaf(x)
        if done is None and x.args and not translatable(x):
            return whole(x)
        return se.sympify(x) if done is None and not x.args else done

    _post_order(expr, memo, taken, _engine_node)
    return memo[expr]


def translatable(x: sp.Basic) -> bool:
    """Whether :func:`to_engine` builds the node ``x`` from its translated arguments
    exactly as ``symengine.sympify`` would (a power as base ** exponent when those are its
    arguments: (1/2)**x is translated by SymEngine as 2**(−x))."""
    if isinstance(x, sp.Pow):
        return x.as_base_exp() == x.args
    return isinstance(x, (sp.Add, sp.Mul, sp.exp)) or type(x) in _ENGINE_FUNCTIONS


def _engine_node(x: sp.Basic, args: list):
    if isinstance(x, sp.Add):
        return se.add(*args)
    if isinstance(x, sp.Mul):
        return mul(*args)
    if isinstance(x, sp.Pow):
        return args[0] ** args[1]
    if isinstance(x, sp.exp):
        return se.E ** args[0]
    return _ENGINE_FUNCTIONS[type(x)](args[0])


def to_sympy(expr, memo: dict) -> sp.Expr:
    """A SymEngine expression in SymPy (a stand-in becomes what it stands for)."""
    def taken(x):
        return sp.sympify(x) if not x.args else None

    _post_order(expr, memo, taken, _sympy_node)
    return memo[expr]


def _sympy_node(x, args: list):
    if isinstance(x, se.Add):
        return sp.Add(*args)
    if isinstance(x, se.Mul):
        return sp.Mul(*args)
    if isinstance(x, se.Pow):
        return args[0] ** args[1]
    if isinstance(x, OneArgFunction) and hasattr(sp, type(x).__name__):
        return getattr(sp, type(x).__name__)(args[0])
    return sp.sympify(x)
