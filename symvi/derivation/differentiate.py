"""Jacobians computed in SymEngine, with SymPy expressions in and out.

SymPy's ``diff`` spends most of a derivation asking every subexpression for its free
symbols and assumptions (se3_body: 52 of 62 s in ``Matrix.jacobian``). SymEngine
differentiates the same expressions in C++; the derivation keeps building its
expressions in SymPy and hands each matrix to be differentiated across once, with its
Jacobians and their chain-rule products computed on the SymEngine side and translated
back once.

Translation. Every free symbol becomes a SymEngine symbol with a fresh name (SymPy's
``Dummy`` does not survive a round trip by itself), and every application c(s) of an
analytic coefficient (:class:`~symvi.groupoids.analytic.AnalyticCoefficient`, which
SymEngine does not know) becomes a symbol w; the chain rule through it is applied here,
dF/dz = ∂F/∂z + ∂F/∂w · c′(s) · ds/dz, c′ again a coefficient
(:func:`~symvi.groupoids.analytic.derivative`) standing for a symbol of its own, so
Hessians differentiate through c′ in turn. A stand-in translates back to the very SymPy
object it stands for (no substitution over the result). A SymPy function SymEngine does
not know (a Bessel function) is differentiated by SymPy's own rule through SymEngine's
wrapper; what neither differentiates (Abs, undefined functions of the coordinates) the
declaration refuses (:mod:`symvi.declaration.validation`), and an expression SymEngine
cannot translate at all is differentiated by SymPy instead.

The same translation compiles a matrix for numerical evaluation (:func:`engine_function`,
SymEngine's ``Lambdify``): the derivation hands it to the sampled rank of its step
Jacobian (:func:`symvi.declaration.rank.generic_rank`).
"""
from __future__ import annotations

import uuid
from typing import Sequence

import numpy as np
import symengine as se
import sympy as sp

from ..groupoids.analytic import AnalyticCoefficient, derivative
from .translate import distinct_nodes, to_engine, to_sympy

#: What SymEngine raises for an expression it cannot translate or differentiate.
_UNTRANSLATABLE = (RuntimeError, TypeError, NotImplementedError)


class _StandIn(se.Symbol):
    """A SymEngine symbol that translates back to the SymPy object it stands for."""

    def __init__(self, name: str, target: sp.Basic):
        super().__init__(name)
        self.target = target

    def _sympy_(self):
        return self.target


class _Translation:
    """Stand-ins for the symbols and coefficient applications of one computation."""

    def __init__(self):
        self.stand_ins: dict[sp.Basic, "_StandIn"] = {}
        #: name of the stand-in of c(s) -> (the class of c, s in SymEngine)
        self.applications: dict[str, tuple[type, object]] = {}
        #: translations of the distinct subexpressions met so far, each way
        self._engine_memo: dict = {}
        self._sympy_memo: dict = {}

    def stand_in(self, atom: sp.Basic) -> "_StandIn":
        if atom not in self.stand_ins:
            # SymEngine caches derivatives by symbol name across calls, so a name must
            # never stand for two things in one process
            self.stand_ins[atom] = _StandIn(f"_z{uuid.uuid4().hex}", atom)
        return self.stand_ins[atom]

    def engine(self, M: sp.Matrix):
        """M as a SymEngine matrix in stand-ins."""
        return se.Matrix(M.rows, M.cols, [self._to_engine(e) for e in M])

    def _to_engine(self, e: sp.Basic):
        return to_engine(e, self._engine_memo, self._leaf, self._whole)

    def _leaf(self, x: sp.Basic):
        """The stand-in of a symbol or a coefficient application, else None."""
        if isinstance(x, AnalyticCoefficient):
            w = self.stand_in(x)
            if w.name not in self.applications:
                self.applications[w.name] = (type(x), self._to_engine(x.args[0]))
            return w
        if isinstance(x, sp.Symbol):
            return self.stand_in(x)
        return None

    def _whole(self, x: sp.Basic):
        """A node the memoised translation does not handle, by SymEngine's own (its
        symbols and coefficients replaced by their stand-ins afterwards)."""
        mapping = {se.sympify(s): self._leaf(s)
                   for s in distinct_nodes([x])
                   if isinstance(s, (sp.Symbol, AnalyticCoefficient))}
        return se.sympify(x).xreplace(mapping)

    def derivative_of(self, name: str):
        """The stand-in of c′(s) for the stand-in ``name`` of c(s)."""
        cls, argument = self.applications[name]
        w = self.stand_in(derivative(cls)(sp.sympify(argument)))
        self.applications.setdefault(w.name, (derivative(cls), argument))
        return w

    def sympy(self, M) -> sp.Matrix:
        """A SymEngine matrix back in SymPy (each stand-in becomes what it stands for)."""
        return sp.Matrix(M.rows, M.cols, [to_sympy(e, self._sympy_memo) for e in M])

    def jacobian(self, F, z: Sequence):
        """dF/dz of a SymEngine column F with respect to SymEngine symbols z."""
        J = F.jacobian(se.Matrix(list(z)))
        used = set().union(*(e.free_symbols for e in F)) if len(F) else set()
        for w in sorted((s for s in used if s.name in self.applications), key=str):
            _, argument = self.applications[w.name]
            ds = self.jacobian(se.Matrix([argument]), z)
            if any(e != 0 for e in ds):
                J += F.diff(w) * self.derivative_of(w.name) * ds
        return J


def _column(M: sp.Matrix) -> sp.Matrix:
    return M.reshape(len(M), 1)


def jacobian(F: sp.Matrix, z: Sequence[sp.Symbol],
             chain: Sequence[tuple[Sequence[sp.Symbol], sp.Matrix]] = ()) -> sp.Matrix:
    """dF/dz + Σ ∂F/∂x · D over ``chain`` = [(x, D = dx/dz), …] (named intermediate
    quantities x of the kernel, :func:`~symvi.derivation.derive._stencil`)."""
    F = _column(sp.Matrix(F))
    try:
        t = _Translation()
        Fe = t.engine(F)
        J = t.jacobian(Fe, [t.stand_in(s) for s in z])
        for x, D in chain:
            J += t.jacobian(Fe, [t.stand_in(s) for s in x]) * t.engine(D)
        return t.sympy(J)
    except _UNTRANSLATABLE:
        return _sympy_jacobian(F, z, chain)


def gradient(f: sp.Expr, z: Sequence[sp.Symbol], translation: "_Translation"):
    """The column ∂f/∂z of a scalar f as a SymEngine matrix in the stand-ins of
    ``translation`` (to be worked with there, and brought back by its ``sympy``)."""
    return translation.jacobian(translation.engine(sp.Matrix([f])),
                                [translation.stand_in(s) for s in z]).T


def gradient_and_hessian(f: sp.Expr, z: Sequence[sp.Symbol]) -> tuple[sp.Matrix, sp.Matrix]:
    """The row ∂f/∂z and the matrix ∂²f/∂z² of a scalar f."""
    try:
        t = _Translation()
        ze = [t.stand_in(s) for s in z]
        gradient = t.jacobian(t.engine(sp.Matrix([f])), ze)
        hessian = t.jacobian(gradient.T, ze)
        return t.sympy(gradient), t.sympy(hessian)
    except _UNTRANSLATABLE:
        gradient = sp.Matrix([f]).jacobian(z)
        return gradient, gradient.T.jacobian(z)


def _sympy_jacobian(F, z, chain) -> sp.Matrix:
    J = F.jacobian(z)
    for x, D in chain:
        J += F.jacobian(x) * D
    return J


def engine_function(args: Sequence[sp.Symbol], definitions: Sequence[tuple[sp.Symbol, sp.Expr]],
                    matrix: sp.Matrix):
    """``matrix`` as a NumPy function of ``args`` (each a float), through SymEngine's
    ``Lambdify`` (C++, its own common subexpressions): on the 20-link chain's step
    Jacobian 0.3 s where SymPy's ``lambdify`` took 6 s. ``definitions`` are (symbol,
    expression) pairs the matrix may use, substituted into it on the SymEngine side
    (shared subtrees stay shared). None where SymEngine cannot take the expressions or
    they hold analytic coefficients (which it cannot evaluate): the caller then compiles
    the matrix otherwise (:func:`symvi.declaration.rank.sequential_lambdify`)."""
    try:
        t = _Translation()
        values = t.engine(sp.Matrix([e for _, e in definitions] + list(matrix)))
        if t.applications:
            return None
        defined = [t.stand_in(s) for s, _ in definitions]
        exprs = list(values)[len(definitions):]
        for symbol, value in reversed(list(zip(defined, values))):
            exprs = [e.xreplace({symbol: value}) for e in exprs]
        f = se.Lambdify([t.stand_in(a) for a in args], exprs, real=True, cse=True)
    except _UNTRANSLATABLE:
        return None
    shape = matrix.shape

    def evaluate(*point):
        return np.asarray(f(np.asarray(point, dtype=float)), dtype=float).reshape(shape)
    return evaluate
