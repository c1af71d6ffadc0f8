"""The memoised SymPy ↔ SymEngine translation (``symvi/derivation/translate.py``) builds
the very expressions of the libraries' own translations, node type by node type, on
random expressions with shared subtrees — the property the derivation's byte-identical C
rests on."""
from __future__ import annotations

import random

import pytest
import symengine as se
import sympy as sp

from symvi.derivation.translate import distinct_nodes, to_engine, to_sympy

x, y, z = sp.symbols("x y z", real=True)
d = sp.Dummy("d")
# hyperbolic functions only of symbols: SymPy's own evaluation of them on large arguments
# takes minutes (their assumptions)
LEAVES = [x, y, z, d, sp.Integer(2), sp.Integer(-3), sp.Rational(1, 2), sp.Rational(-5, 7),
          sp.Float(0.1), sp.pi, sp.E, sp.Integer(0), sp.Integer(1), sp.sinh(x), sp.cosh(y),
          sp.tanh(z), sp.asinh(x), sp.acosh(y), sp.atanh(z), sp.acos(x), sp.acot(y)]
UNARY = [sp.sin, sp.cos, sp.tan, sp.exp, sp.log, sp.sqrt, sp.atan, sp.Abs, sp.cot, sp.asin]


def _tree_size(expr: sp.Basic, sizes: dict) -> int:
    """Nodes of ``expr`` as a tree (what the libraries' translations walk)."""
    if expr not in sizes:
        sizes[expr] = 1 + sum(_tree_size(a, sizes) for a in expr.args)
    return sizes[expr]


def _random_expression(rng: random.Random, depth: int, pool: list) -> sp.Expr:
    """A random finite expression over ``pool``, reusing earlier subtrees (shared
    subexpressions), small enough as a tree for the libraries' translations."""
    if depth == 0 or rng.random() < 0.15:
        return rng.choice(pool)
    while True:
        kind = rng.randrange(6)
        a = _random_expression(rng, depth - 1, pool)
        b = _random_expression(rng, depth - 1, pool)
        expr = (a + b, a * b, a - 2 * b, a ** rng.choice([2, 3, -1, -2, sp.Rational(1, 2)]),
                rng.choice(UNARY)(a), sp.Rational(1, 2) ** a + b ** sp.Rational(-3, 2))[kind]
        if _tree_size(expr, {}) < 2000 and not any(
                n in (sp.zoo, sp.oo, -sp.oo, sp.nan) or isinstance(n, sp.AccumBounds)
                for n in distinct_nodes([expr])):
            pool.append(expr)
            return expr


@pytest.mark.parametrize("seed", range(40))
def test_both_ways_as_the_libraries_translate(seed):
    rng = random.Random(seed)
    pool = list(LEAVES)
    exprs = [_random_expression(rng, 4, pool) for _ in range(4)]
    memo: dict = {}
    for expr in exprs:
        engine = to_engine(expr, memo, lambda node: None)
        assert engine == se.sympify(expr), expr
        back = to_sympy(engine, {})
        assert back == sp.sympify(engine), engine
        assert back.func == sp.sympify(engine).func


def test_leaves_are_taken_whole_and_shared_nodes_visited_once():
    shared = sp.sin(x + y) * sp.cos(x + y)
    expr = sum(shared ** k for k in range(1, 30))
    stand_in = se.Symbol("w")
    visits = []

    def leaf(node):
        visits.append(node)
        return stand_in if node == x else None

    engine = to_engine(expr, {}, leaf)
    assert engine == se.sympify(expr).xreplace({se.Symbol("x"): stand_in})
    assert len(visits) == len(distinct_nodes([expr]))
