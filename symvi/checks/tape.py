"""A kernel output as a NumPy function of z with its Jacobian: forward mode on a tape.

Every distinct subexpression of the kernel's definitions (named base points) and of the
output becomes one step of the tape — an operation on earlier steps, stencil coordinates
z_j, parameters or numbers — and its gradient row over z follows from its arguments' rows
by the chain rule. Sums and products are evaluated directly; any other operation (sin,
powers, the exponential's analytic coefficients) through ``sympy.lambdify`` of the
operation and of its partial derivatives. Differentiating the expanded expressions with
SymPy instead takes seconds per kernel on the action groupoids.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import sympy as sp

#: A step's argument: ("z", j), ("k", i) a fixed value, ("v", n) an earlier step, or
#: ("c", value) a number.
Ref = tuple[str, object]


@dataclass(frozen=True)
class _Step:
    """One assignment of the tape: ``op`` "add", "mul" or "call" of ``args``."""

    op: str
    args: tuple[Ref, ...]
    value: Callable | None = None           # "call": the operation
    partials: tuple[Callable, ...] = ()     # "call": ∂/∂ each argument


class ForwardTape:
    """``tape(z) -> (F, dF/dz)`` for output ``output`` of ``kernel`` with ``fixed`` values
    (symbol → number) for the parameters and the step."""

    def __init__(self, kernel, output: str, fixed: dict):
        F = dict(kernel.outputs)[output]
        self.nz, self.size = len(kernel.z), F.shape[0] * F.shape[1]
        self.fixed = np.array([float(v) for v in fixed.values()])
        self._refs: dict = {s: ("z", j) for j, s in enumerate(kernel.z)}
        self._refs |= {p: ("k", i) for i, p in enumerate(fixed)}
        self._steps: list[_Step] = []
        self._memo: dict = {}
        self._operations: dict = {}
        for symbol, e in kernel.definitions:
            self._refs[symbol] = self._visit(sp.sympify(e))
        self._outputs = [self._visit(sp.sympify(e)) for e in F]

    # -- recording ----------------------------------------------------------------------
    def _visit(self, e) -> Ref:
        if e in self._refs:
            return self._refs[e]
        if e.is_Number:
            return ("c", float(e))
        if e.is_Symbol:
            raise ValueError(f"kernel expression uses an unknown symbol {e}")
        if e in self._memo:
            return self._memo[e]
        args = tuple(self._visit(a) for a in e.args)
        if e.is_Add or e.is_Mul:
            step = _Step("add" if e.is_Add else "mul", args)
        else:
            step = self._call(e, args)
        ref = ("v", len(self._steps))
        self._steps.append(step)
        self._memo[e] = ref
        return ref

    def _call(self, e, args: tuple[Ref, ...]) -> _Step:
        """An operation other than + and × (lambdified once per function and arity)."""
        key = (e.func, len(args))
        if key not in self._operations:
            slots = sp.symbols(f"a0:{len(args)}", real=True)
            op = e.func(*slots)
            self._operations[key] = (sp.lambdify(slots, op, "numpy"), tuple(
                sp.lambdify(slots, sp.diff(op, s), "numpy") for s in slots))
        value, partials = self._operations[key]
        return _Step("call", args, value, partials)

    # -- evaluation ---------------------------------------------------------------------
    def __call__(self, zv) -> tuple[np.ndarray, np.ndarray]:
        z, eye = np.asarray(zv, dtype=float), np.eye(self.nz)
        values: list[float] = []
        rows: list[np.ndarray | None] = []

        def get(ref: Ref) -> tuple[float, np.ndarray | None]:
            where, i = ref
            if where == "v":
                return values[i], rows[i]
            if where == "z":
                return z[i], eye[i]
            return (self.fixed[i], None) if where == "k" else (i, None)

        for step in self._steps:
            vals, grads = zip(*(get(a) for a in step.args))
            value, row = _apply(step, vals, grads)
            values.append(value)
            rows.append(row)
        F = np.empty(len(self._outputs))
        J = np.zeros((len(self._outputs), self.nz))
        for n, ref in enumerate(self._outputs):
            F[n], row = get(ref)
            if row is not None:
                J[n] = row
        return F, J.reshape(self.size, self.nz)


def _apply(step: _Step, vals, grads) -> tuple[float, np.ndarray | None]:
    """The value and gradient row of one step from its arguments'."""
    if step.op == "add":
        value = float(sum(vals))
        weights = [1.0] * len(vals)
    elif step.op == "mul":
        value = float(np.prod(vals))
        weights = [float(np.prod([v for j, v in enumerate(vals) if j != i]))
                   for i in range(len(vals))]
    else:
        value = float(step.value(*vals))
        # only along arguments that vary (∂/∂n of xⁿ at x < 0 is not even real)
        weights = [float(d(*vals)) if g is not None else 0.0
                   for d, g in zip(step.partials, grads)]
    terms = [w * g for w, g in zip(weights, grads) if g is not None and w != 0.0]
    return value, (sum(terms[1:], terms[0]) if terms else None)
