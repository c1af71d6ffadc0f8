"""C emission: kernels → C source text through the Jinja templates in ``templates/``.

Python hands the templates printed expressions and names only; all C text lives in the
templates. Common subexpressions are eliminated once over all outputs of a kernel
(residual and Jacobian together), with SymPy's ``cse``.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Sequence

import jinja2
import sympy as sp
from sympy.printing.c import C99CodePrinter
from sympy.printing.codeprinter import PrintMethodNotImplementedError

from ..version import __version__
from ..derivation.derive import DerivedModel, Kernel
from ..errors import ModelError
from ..groupoids.analytic import THETA, AnalyticCoefficient, c_definition
from ..groupoids.base import GroupFactor
from .schedule import SPLIT_ABOVE, Statement, on_demand, split

#: Kernels of more statements than this are compiled as translation units of their own,
#: in parallel with the model's (:mod:`symvi.build.ccompile`); smaller ones stay with the
#: step loop that inlines them.
UNIT_ABOVE = 400


class ArrayPrinter(C99CodePrinter):
    """C99 printer that maps symbols to array slots and expands small integer powers."""

    def __init__(self, names: dict[sp.Symbol, str]):
        super().__init__()
        self._names = names

    def _print_Symbol(self, expr):
        return self._names.get(expr) or super()._print_Symbol(expr)

    _print_Dummy = _print_Symbol

    def _print_Function(self, expr):
        if isinstance(expr, AnalyticCoefficient):
            return f"{type(expr).__name__}({self._print(expr.args[0])})"
        return super()._print_Function(expr)

    def _print_cot(self, expr):
        return f"(1.0/tan({self._print(expr.args[0])}))"

    def _print_Pow(self, expr):
        base, exp = expr.as_base_exp()
        if exp.is_Integer and 2 <= abs(int(exp)) <= 4:
            b = self.parenthesize(base, 100)
            product = "*".join([b] * abs(int(exp)))
            return f"({product})" if exp > 0 else f"(1.0/({product}))"
        return super()._print_Pow(expr)


@dataclass(frozen=True)
class CSource:
    """The emitted sources of one model and a digest of them all.

    ``c_source`` is the model's translation unit (the runtime, the small kernels);
    ``units`` the kernels of more than :data:`UNIT_ABOVE` statements, each a translation
    unit of its own, as (name, C text), compiled in parallel; ``cdef`` the cffi
    declarations of every exported function (C prototypes).
    """

    c_source: str
    cdef: str
    digest: str
    units: tuple[tuple[str, str], ...] = ()

    @property
    def size(self) -> int:
        """Characters of C in all units."""
        return len(self.c_source) + sum(len(text) for _, text in self.units)


def template_dir() -> Path:
    """Directory of the C and Python templates.

    Installed, they ship inside the package as ``symvi/templates``; in a source checkout
    they are the top-level ``templates/``.
    """
    package = Path(__file__).resolve().parent.parent
    installed = package / "templates"
    return installed if (installed / "module.c.j2").exists() else package.parent / "templates"


def environment() -> jinja2.Environment:
    return jinja2.Environment(loader=jinja2.FileSystemLoader(str(template_dir())),
                              undefined=jinja2.StrictUndefined, keep_trailing_newline=True,
                              trim_blocks=True, lstrip_blocks=True)


def _levels(definitions) -> list[list[tuple[sp.Symbol, sp.Expr]]]:
    """Group definitions so that each group uses only symbols of earlier groups."""
    level: dict[sp.Symbol, int] = {}
    groups: list[list] = []
    for symbol, expr in definitions:
        k = max((level[s] + 1 for s in expr.free_symbols if s in level), default=0)
        level[symbol] = k
        while len(groups) <= k:
            groups.append([])
        groups[k].append((symbol, expr))
    return groups


def _render_kernel(kernel: Kernel, dm: DerivedModel) -> dict:
    names = {s: f"z[{i}]" for i, s in enumerate(kernel.z)}
    names |= {s: f"p[{i}]" for i, s in enumerate(dm.parameters)}
    names |= {s: f"d{i}" for i, (s, _) in enumerate(kernel.definitions)}
    names[dm.step] = "h"
    printer = ArrayPrinter(names)
    local: dict[sp.Symbol, str] = {}     # the temporaries' symbols and C names
    # cse skips the symbols of the expressions it is given, not those of the others (a
    # parameter t0 used by a definition only would be taken for the temporary t0)
    inputs = (*kernel.z, *dm.parameters, dm.step)

    def statement(target: str, expr: sp.Expr, temporary: bool) -> Statement:
        uses = tuple(sorted(local[s] for s in expr.free_symbols if s in local))
        return Statement(target, printer.doprint(expr), temporary, uses)

    temporaries = []

    def define(symbol: sp.Symbol, name: str, expr: sp.Expr) -> None:
        temporaries.append(statement(name, expr, True))
        local[symbol] = name

    # Definitions first, one CSE per dependency level, so that every temporary is
    # computed after the definitions it uses.
    for k, group in enumerate(_levels(kernel.definitions)):
        shared, reduced = sp.cse([e for _, e in group], order="none",
                                 symbols=sp.numbered_symbols(f"u{k}_", exclude=inputs))
        for t, e in shared:
            define(t, str(t), e)
        for (sym, _), e in zip(group, reduced):
            define(sym, names[sym], e)
    flat = [e for _, M in kernel.outputs for e in M]
    shared, reduced = sp.cse(flat, symbols=sp.numbered_symbols("t", exclude=inputs),
                             order="none")
    for t, e in shared:
        define(t, str(t), e)
    targets = [f"{name}[{i}]" for name, M in kernel.outputs for i in range(len(M))]
    code = on_demand(temporaries, [statement(t, e, False) for t, e in zip(targets, reduced)])
    parts, work = split(code) if len(code) > SPLIT_ABOVE else ([], 0)
    return {"name": kernel.name, "doc": kernel.doc, "nz": len(kernel.z), "along": kernel.along,
            "statements": code, "parts": parts, "work": work, "unit": len(code) > UNIT_ABOVE,
            "outputs": [{"name": name, "size": len(M)} for name, M in kernel.outputs]}


def _printed(render, kernel: Kernel, dm: DerivedModel) -> dict:
    """``render(kernel, dm)``, with a function C99 lacks reported as a ModelError."""
    try:
        return render(kernel, dm)
    except PrintMethodNotImplementedError as exc:
        missing = str(exc).splitlines()[0].rsplit(":", 1)[-1].strip()
        raise ModelError(
            f"model {dm.name!r}: kernel {kernel.name!r} ({kernel.doc}) needs the function "
            f"{missing}, which C99 does not have; write the model with elementary functions "
            f"(those of <math.h>)") from None


def emit(dm: DerivedModel) -> CSource:
    """Render the C source and cffi declarations of a derived model."""
    env = environment()
    context = {
        "version": __version__, "name": dm.name, "m": dm.source_dim, "n": dm.fibre_dim,
        "unit_note": "The model's unit: its runtime and small kernels.",
        "K": dm.stencil_elements, "order": dm.order, "np": len(dm.parameters),
        "kernels": [_printed(_render_kernel, k, dm) for k in dm.kernels],
        "whole_trajectory": dm.whole_trajectory, "constraints": dm.constraint_count,
        "inequalities": len(dm.inequality_names),
        "end_free": dm.end_free, "end_conditions": len(dm.end_names),
        "fibre_sources": list(dm.fibre_sources),
        "coefficients": [c_definition(c, ArrayPrinter({THETA: "theta"}))
                         for c in dm.coefficients],
        "configuration_dim": dm.c_context.configuration_dim,
        "node_copies": list(dm.c_context.node_copies),
        "groups": _with_configuration_offsets(dm.c_context.groups),
    }
    c_source = env.get_template("module.c.j2").render(**context)
    cdef = env.get_template("cdef.h.j2").render(**context)
    unit = env.get_template("unit.c.j2")
    units = tuple((k["name"], unit.render(context | {
        "k": k, "unit_note": f"Kernel {k['name']}, a unit of its own."}))
        for k in context["kernels"] if k["unit"])
    digest = hashlib.sha256("\0".join([c_source, cdef, *(t for u in units for t in u)])
                            .encode()).hexdigest()
    return CSource(c_source, cdef, digest, units)


def _with_configuration_offsets(groups: Sequence[GroupFactor]) -> list[GroupFactor]:
    """Each group factor with ``g_offset``, where its d×d block starts in a node's
    configuration (the factors' matrices, concatenated)."""
    out, at = [], 0
    for G in groups:
        out.append(replace(G, g_offset=at))
        at += G.matrix_dim ** 2
    return out


def generic_source() -> str:
    """The C of the generic library (``templates/generic.c.j2``): the band factorisation,
    solves and products and the lifted system's inertia and equilibration, which depend on
    no model; compiled once and linked into every package (:mod:`symvi.build.generic`)."""
    return environment().get_template("generic.c.j2").render()


def templates_digest() -> str:
    """Content hash of every template (part of the build cache key)."""
    h = hashlib.sha256()
    for path in sorted(template_dir().glob("*.j2")):
        h.update(path.name.encode() + path.read_bytes())
    return h.hexdigest()
