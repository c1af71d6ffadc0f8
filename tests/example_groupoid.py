"""An example groupoid written against :mod:`symvi.groupoids.base` alone (issue 49).

The pair groupoid Q×Q ⇉ Q over Q = Rⁿ in other coordinates: an element (q₀, q₁) is its
source x = q₀ and its mean velocity f = (q₁ − q₀)/h, so that

* β(x, f) = x + h f;
* g·σ_a(ε) = (q₀, q₁ + ε e_a): x is unchanged and f moves by e_a/h, right = [0; I/h];
* σ_a(ε)⁻¹·g = (q₀ + ε e_a, q₁): x moves by e_a and f by −e_a/h, left = [I; −I/h];
* f is an increment divided by h (``step_scaled``): holding the element fixed while h
  varies holds h·f fixed.

Nothing else of symvi knows it: no kind is registered, no template or run-time file
changes. Its default rule is its own (a :class:`~symvi.discretisation.rules.Rule` made
here, the midpoint L_d = h L((q₀ + q₁)/2, f)); it also lists the shared first-order
increment rule ``lie``, which reads the window through the hooks ``algebra_point`` and
``base_quadrature`` (the trapezoid h/2 [L(q₀, f) + L(q₁, f)]). With the midpoint rule its
discrete Lagrangian is the pair groupoid's midpoint one, so both compute the same path.
"""
from __future__ import annotations

from typing import Sequence

import sympy as sp

from symvi.discretisation.rules import LIE, Rule
from symvi.groupoids.base import Algebroid, Groupoid


def _velocity_midpoint(g: "VelocityPairGroupoid", xs, fs, h):
    """L at the element's middle: q = x + h f/2, q̇ = f."""
    middle = [x + h * v / 2 for x, v in zip(xs[0], fs[0])]
    return [(sp.Integer(1), g.base_point(middle) | g.algebra_point(fs, h))]


VELOCITY_MIDPOINT = Rule("velocity_midpoint", 1,
                         "velocity pair: L_d(x, f) = h L(x + h f/2, f)", _velocity_midpoint)


class VelocityPairGroupoid(Groupoid):
    """Q×Q in (source, mean velocity) coordinates; ``names`` are those of q."""

    kind = "velocity_pair"
    max_order = 1

    def __init__(self, names: str):
        self.names = tuple(names.split())
        self.q = tuple(sp.Symbol(n, real=True) for n in self.names)
        self.v = tuple(sp.Symbol(f"{n}_dot", real=True) for n in self.names)

    def __repr__(self) -> str:
        return f"VelocityPairGroupoid({' '.join(self.names)!r})"

    # -- the abstract methods ------------------------------------------------------------
    @property
    def source_dim(self) -> int:
        return len(self.names)

    @property
    def fibre_dim(self) -> int:
        return len(self.names)

    def target(self, x, f, h):
        return tuple(a + h * b for a, b in zip(x, f))

    def right(self, x, f, h):
        n = self.fibre_dim
        return sp.Matrix.vstack(sp.zeros(n, n), sp.eye(n) / h)

    def left(self, x, f, h):
        n = self.fibre_dim
        return sp.Matrix.vstack(sp.eye(n), -sp.eye(n) / h)

    def continuous_symbols(self, order):
        return self.q + self.v

    def leading_symbols(self, order):
        return self.v

    def rules(self, order):
        return (VELOCITY_MIDPOINT, LIE)

    def discrete_symbols(self, order):
        return self.q + tuple(sp.Symbol(f"{n}_v", real=True) for n in self.names)

    def discrete_mapping(self, order, xs, fs):
        return dict(zip(self.discrete_symbols(order), tuple(xs[0]) + tuple(fs[0])))

    def predictor(self, xs: Sequence, fs: Sequence):
        return tuple(fs[-1])          # the velocity carried on

    def fingerprint(self):
        return f"velocity_pair:{','.join(self.names)}"

    # -- what its rules read ---------------------------------------------------------------
    def algebra_point(self, fs, h):
        return dict(zip(self.v, fs[0]))

    def base_point(self, x):
        return dict(zip(self.q, x))

    # -- hooks -------------------------------------------------------------------------------
    def step_scaled(self):
        return (True,) * self.fibre_dim

    def algebroid(self):
        n = self.fibre_dim
        return Algebroid(self.q, self.v, tuple(sp.Symbol(f"{s}_dot", real=True) for s in self.v),
                         sp.eye(n), (sp.zeros(n, n),) * n)
