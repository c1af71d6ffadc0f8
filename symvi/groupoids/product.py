"""Products G₁×…×G_k of Lie groupoids (DESIGN.md §2: "concatenation, blockwise").

An element is a tuple of elements; its source and fibre coordinates are the factors'
concatenated, and the node variations act blockwise (a basis section of the product
algebroid is a basis section of one factor). The heavy top with rotors of paper §3.3 lives
on the action groupoid of SO(3) times the pair groupoid of the rotor angles.
"""
from __future__ import annotations

import itertools
import sympy as sp

from ..errors import ModelError
from ..discretisation.rules import product
from .base import Algebroid, CContext, Groupoid, _shape, block_algebroid


class ProductGroupoid(Groupoid):
    """The product of groupoids; the discretisation is each factor's default, combined."""

    kind = "product"
    sampling_text = "pair factors at nodes, group factors at element midpoints, base points from β"

    def __init__(self, *factors: Groupoid):
        if len(factors) < 2 or not all(isinstance(f, Groupoid) for f in factors):
            raise ModelError("ProductGroupoid needs two or more symvi groupoids")
        self._factors = tuple(factors)
        symbols = [s for f in factors for s in f.continuous_symbols(self.max_order)]
        repeated = sorted({str(s) for s in symbols if symbols.count(s) > 1})
        # a coordinate's clash repeats in its derivatives' names: name the coordinates
        first = {str(s) for f in factors for s in f.continuous_symbols(1)}
        repeated = [name for name in repeated if name in first] or repeated
        if repeated:
            raise ModelError(f"the factors of a product share coordinate names {repeated}; "
                             f"rename them")
        self._m = [f.source_dim for f in factors]
        self._n = [f.fibre_dim for f in factors]

    def __repr__(self) -> str:
        return " × ".join(map(repr, self.factors))

    @property
    def max_order(self) -> int:
        """The highest order every factor takes."""
        return min(f.max_order for f in self.factors)

    def _split(self, values, sizes) -> list[tuple]:
        values, out = tuple(values), []
        for offset, size in zip(itertools.accumulate([0] + sizes), sizes):
            out.append(values[offset:offset + size])
        return out

    def factor_slots(self, xs, fs):
        """Per factor: its sources and fibres of every slot (the product rules)."""
        xs = [self._split(x, self._m) for x in xs]
        fs = [self._split(f, self._n) for f in fs]
        return [([x[i] for x in xs], [f[i] for f in fs]) for i in range(len(self.factors))]

    def _blocks(self, side: str, x, f, h) -> sp.Matrix:
        M, N = sum(self._m), sum(self._n)
        out = sp.zeros(M + N, N)
        mo = no = 0
        for factor, xi, fi in zip(self.factors, self._split(x, self._m), self._split(f, self._n)):
            block = getattr(factor, side)(xi, fi, h)
            m, n = factor.source_dim, factor.fibre_dim
            out[mo:mo + m, no:no + n] = block[:m, :]
            out[M + no:M + no + n, no:no + n] = block[m:, :]
            mo, no = mo + m, no + n
        return out

    # -- structure maps, blockwise (a basis section e_a is one factor's) -----------------
    def _join(self, parts) -> tuple[tuple, tuple]:
        return (tuple(v for x, _ in parts for v in x), tuple(v for _, f in parts for v in f))

    def identity(self, x):
        return self._join([F.identity(xi) for F, xi in zip(self.factors, self._split(x, self._m))])

    def multiply(self, x, f, x2, f2, h):
        return self._join([F.multiply(*args, h) for F, *args in zip(
            self.factors, self._split(x, self._m), self._split(f, self._n),
            self._split(x2, self._m), self._split(f2, self._n))])

    def inverse(self, x, f, h):
        return self._join([F.inverse(xi, fi, h) for F, xi, fi in zip(
            self.factors, self._split(x, self._m), self._split(f, self._n))])

    def basis_curve(self, x, a, eps, h):
        parts, offset = [], 0
        for F, xi in zip(self.factors, self._split(x, self._m)):
            local = a - offset
            parts.append(F.basis_curve(xi, local, eps, h) if 0 <= local < F.fibre_dim
                         else F.identity(xi))
            offset += F.fibre_dim
        return self._join(parts)

    # -- groupoid interface -------------------------------------------------------------
    @property
    def source_dim(self) -> int:
        return sum(self._m)

    @property
    def fibre_dim(self) -> int:
        return sum(self._n)

    def target(self, x, f, h):
        return tuple(v for factor, xi, fi in zip(self.factors, self._split(x, self._m),
                                                 self._split(f, self._n))
                     for v in factor.target(xi, fi, h))

    def right(self, x, f, h):
        return self._blocks("right", x, f, h)

    def left(self, x, f, h):
        return self._blocks("left", x, f, h)

    @property
    def factors(self) -> tuple[Groupoid, ...]:
        return self._factors

    @property
    def whole_trajectory(self) -> bool:
        return all(f.whole_trajectory for f in self.factors)

    @property
    def structure_check(self) -> bool:
        return all(f.structure_check for f in self.factors)

    def matrix_groups(self):
        return tuple(G for f in self.factors for G in f.matrix_groups())

    def configuration_base(self) -> tuple[int, ...]:
        out, offset = [], 0
        for factor in self.factors:
            out += [i if i < 0 else i + offset for i in factor.configuration_base()]
            offset += sum(G.matrix_dim ** 2 for G in factor.matrix_groups())
        return tuple(out)

    def fibre_sampling(self):
        out, offset = [], 0
        for factor in self.factors:
            out += [i if i is None else i + offset for i in factor.fibre_sampling()]
            offset += factor.source_dim
        return tuple(out)

    def equation_setting(self, order):
        return "on the product algebroid"

    def preserved_structure(self, order):
        # one structure when the factors agree (products of pair groupoids are symplectic)
        texts = {f.preserved_structure(order) for f in self.factors}
        return texts.pop() if len(texts) == 1 else super().preserved_structure(order)

    def algebroid(self) -> Algebroid:
        return block_algebroid([f.algebroid() for f in self.factors])

    def manifold(self, x):
        return tuple(v for factor, xi in zip(self.factors, self._split(x, self._m))
                     for v in factor.manifold(xi))

    def move(self, x, eta):
        return tuple(v for factor, xi, ei in zip(self.factors, self._split(x, self._m),
                                                 self._split(eta, self._n))
                     for v in factor.move(xi, ei))

    def predictor(self, xs, fs):
        return tuple(v for factor, (fx, ff) in zip(self.factors, self.factor_slots(xs, fs))
                     for v in factor.predictor(fx, ff))

    def continuous_symbols(self, order):
        return tuple(s for f in self.factors for s in f.continuous_symbols(order))

    def leading_symbols(self, order):
        return tuple(s for f in self.factors for s in f.leading_symbols(order))

    def rules(self, order):
        return (product(order),)

    def step_scaled(self):
        return tuple(s for f in self.factors for s in f.step_scaled())

    def discrete_symbols(self, order):
        return tuple(s for f in self.factors for s in f.discrete_symbols(order))

    def discrete_mapping(self, order, xs, fs):
        mapping = {}
        for factor, (fx, ff) in zip(self.factors, self.factor_slots(xs, fs)):
            mapping |= factor.discrete_mapping(order, fx, ff)
        return mapping

    def check_initial(self, initial, order):
        parts = list(initial)
        if len(parts) not in (2, 3):
            raise ModelError("initial data must be (x_0, f) or (x_0, g_0, f)")
        _shape(parts[0], (self.source_dim,), "initial base point x_0")
        _shape(parts[-1], (2 * order - 1, self.fibre_dim), "initial fibre parts")

    def fingerprint(self) -> str:
        return "product:" + "|".join(f.fingerprint() for f in self.factors)

    def c_context(self) -> CContext:
        """The factors' contexts, moved to their offsets in the product's coordinates."""
        groups, copies, x_offset, f_offset = [], [], 0, 0
        for factor in self.factors:
            context = factor.c_context().shifted(x_offset, f_offset)
            groups += context.groups
            copies += context.node_copies
            x_offset += factor.source_dim
            f_offset += factor.fibre_dim
        return CContext(sum(G.matrix_dim ** 2 for G in groups), tuple(groups), tuple(copies))

    def coefficient_functions(self) -> list:
        return [c for f in self.factors for c in f.coefficient_functions()]
