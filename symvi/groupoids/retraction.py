"""Retractions τ : g → G of a matrix Lie group (DESIGN.md §2).

A retraction supplies τ(X) as a matrix, the right-trivialised inverse derivative dτ⁻¹_X in
the group's basis (the only thing the variations of :mod:`symvi.groupoids.lie` need) and
what the C reconstruction g_{k+1} = g_k·τ(hξ_k) needs.

* :class:`Cayley` — cay(X) = (I − X/2)⁻¹(I + X/2) for any quadratic matrix group;
  dcay⁻¹_X(Y) = (I − X/2) Y (I + X/2) is polynomial (paper, Appendix D for SO(3)).
* :class:`Exponential` — exp with dexp⁻¹_X = Σ B_j/j! ad_Xʲ. For groups where X and ad_X
  satisfy M^a (M² + θ²)^b = 0 (so(3), se(2), se(3), …; detected and checked exactly) both
  are finite sums with coefficients analytic in θ² (:mod:`symvi.groupoids.analytic`).
  Its chart is |θ| < π, where exp is injective.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import Any, Protocol, Sequence

import sympy as sp

from ..errors import ModelError
from . import analytic



class Group(Protocol):
    """What a retraction uses of its matrix Lie group (:class:`~.lie.MatrixLieGroup`)."""

    label: str
    matrix_dim: int
    minimal_structure: Any

    def hat(self, x: Sequence[sp.Expr]) -> sp.Matrix: ...

    def ad(self, x: Sequence[sp.Expr]) -> sp.Matrix: ...


class Retraction(ABC):
    """A retraction of one matrix Lie group; see the module docstring."""

    name: str = "abstract"

    def __init__(self, group: Group):
        self.group = group

    @abstractmethod
    def inverse_derivative(self, x: Sequence[sp.Expr]) -> sp.Matrix:
        """n×n matrix of the right-trivialised dτ⁻¹_X, X = Σ x_a E_a, in the basis."""

    @abstractmethod
    def matrix(self, x: Sequence[sp.Expr]) -> sp.Matrix:
        """τ(X) as a d×d matrix."""

    @abstractmethod
    def c_context(self) -> dict:
        """Template data for ``retract`` in ``templates/group.c.j2``."""

    def coefficient_functions(self) -> list:
        """:class:`~symvi.groupoids.analytic.AnalyticCoefficient` classes the C needs."""
        return []


class Cayley(Retraction):
    """The Cayley map of a quadratic matrix group."""

    name = "cayley"

    def inverse_derivative(self, x):
        g = self.group
        X, eye = g.hat(x), sp.eye(g.matrix_dim)
        return sp.Matrix.hstack(*[g.coordinates((eye - X / 2) * E * (eye + X / 2))
                                  for E in g.basis]).applyfunc(sp.expand)

    def matrix(self, x):
        """cay(X); a polynomial in X with rational coefficients in θ² when the group has a
        minimal-polynomial structure (compact expressions), else (I − X/2)⁻¹(I + X/2)."""
        structure = self.group.minimal_structure
        if structure is not None:
            a, b = structure["matrix"]
            return analytic.apply_rational(analytic.CAYLEY, a, b, self.group.hat(x),
                                           structure["theta_squared"](x))
        X, eye = self.group.hat(x), sp.eye(self.group.matrix_dim)
        return ((eye - X / 2).inv() * (eye + X / 2)).applyfunc(sp.cancel)

    def c_context(self):
        """With a minimal-polynomial structure, cay(X) − I = Σ_k d_k(θ²) X^k in closed
        form (so(3): 4 (X + X²/2)/(4 + θ²)), which the C evaluates in a few products
        instead of a pivoted solve of (I − X/2) D = X per retraction (a fifth of a path
        update on SO(3)); the denominators are powers of 4 + θ² > 0, θ² being positive
        semi-definite."""
        structure = self.group.minimal_structure
        if structure is None:
            return {"retraction": "cayley", "cayley_coefficients": None}
        s = sp.Symbol("s", nonnegative=True)
        terms = analytic.minus_identity_coefficients(analytic.CAYLEY, *structure["matrix"], s)
        return {"retraction": "cayley",
                "cayley_coefficients": [sp.ccode(sp.nsimplify(t)) for t in terms],
                "quadratic_form": [[float(v) for v in row]
                                   for row in structure["quadratic_form"].tolist()]}


class Exponential(Retraction):
    """The exponential map, for groups whose X and ad_X have minimal polynomial
    z^a (z² + θ²)^b with θ² a positive semi-definite quadratic form in the coordinates."""

    name = "exp"

    def __init__(self, group: Group):
        super().__init__(group)
        structure = group.minimal_structure
        if structure is None:
            raise ModelError(
                f"{group.label}: no closed form of the exponential retraction: X and ad_X do "
                f"not both satisfy M^a (M² + θ²)^b = 0 with one positive semi-definite θ²; "
                f"use retraction='cayley'")
        self.matrix_structure, self.adjoint_structure = structure["matrix"], structure["adjoint"]
        self.theta_squared = structure["theta_squared"]
        self.quadratic_form = structure["quadratic_form"]

    def inverse_derivative(self, x):
        a, b = self.adjoint_structure
        return analytic.apply(analytic.DEXPINV, a, b, self.group.ad(x), self.theta_squared(x))

    def matrix(self, x):
        a, b = self.matrix_structure
        return analytic.apply(analytic.EXP, a, b, self.group.hat(x), self.theta_squared(x))

    def coefficient_functions(self):
        return list(analytic.coefficients(analytic.EXP, *self.matrix_structure))

    def c_context(self):
        return {"retraction": "exp",
                "exp_coefficients": [c.__name__ for c in self.coefficient_functions()],
                "quadratic_form": [[float(v) for v in row] for row in self.quadratic_form.tolist()],
                "chart_theta_squared": repr(math.pi ** 2)}


RETRACTIONS = {"cayley": Cayley, "exp": Exponential}


def make(name: str, group: Group) -> Retraction:
    """The retraction called ``name`` ("cayley" or "exp") of ``group``."""
    if name not in RETRACTIONS:
        raise ModelError(f"unknown retraction {name!r}; known: {sorted(RETRACTIONS)}")
    return RETRACTIONS[name](group)
