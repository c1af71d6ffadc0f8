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

What differs between retractions is each class's methods and data, never a test of its
name elsewhere: the C of ``templates/retractions.c.j2`` is chosen by the macro names of
:meth:`Retraction.c_context` (a :class:`RetractionC`), the structure maps of ``symvi
check`` call :meth:`Retraction.element` and :meth:`Retraction.logarithm`. The names
``"cayley"`` and ``"exp"`` appear only in :data:`RETRACTIONS`, the registry that
:func:`make` reads.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, Protocol, Sequence

import mpmath
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


@dataclass(frozen=True)
class RetractionC:
    """What ``templates/retractions.c.j2`` needs of a group factor's retraction.

    ``retract_macro`` names the macro that defines ``retract_i``, ``minus_identity_i`` and
    ``chart_i`` (τ(X), τ(X) − I, the chart test); ``log_macro`` the body of
    ``element_log_i`` (ξ from τ(hξ) = I + D); ``log_warm_start`` whether that body starts
    from the fibre already in the element (then the whole-trajectory update gives it the
    first-order change as a warm start). ``coefficients``: the closed form's coefficients
    (C expressions in s = θ², or the names of analytic coefficient functions of s),
    ``quadratic_form`` the matrix of θ² (None without a closed form), ``chart_theta_squared``
    the chart's bound on θ² (C text; None: no bound).
    """

    retract_macro: str
    log_macro: str
    log_warm_start: bool
    coefficients: tuple[str, ...] = ()
    quadratic_form: list | None = None
    chart_theta_squared: str | None = None


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
    def c_context(self) -> RetractionC:
        """What the C of ``templates/retractions.c.j2`` needs (its macros, by name)."""

    @abstractmethod
    def element(self, x: Sequence[sp.Expr]) -> sp.Matrix:
        """τ(X), X = Σ x_a E_a, from the retraction's definition, not from the closed
        forms of :meth:`matrix` (the structure maps of ``symvi check``, which must be
        independent of them): numbers meant, symbolic entries where possible."""

    @abstractmethod
    def logarithm(self, W: sp.Matrix) -> sp.Matrix:
        """X = τ⁻¹(W) as a d×d matrix of the algebra, from the definition; a
        NotImplementedError where the retraction has no τ⁻¹ for the entries given."""

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

    def element(self, x):
        """(I − X/2)⁻¹(I + X/2) by a linear solve (any entries)."""
        X, eye = self.group.hat(x), sp.eye(self.group.matrix_dim)
        return (eye - X / 2).LUsolve(eye + X / 2)

    def logarithm(self, W):
        """cay⁻¹(W) = 2(W + I)⁻¹(W − I) (any entries)."""
        W, eye = sp.Matrix(W), sp.eye(self.group.matrix_dim)
        return 2 * (W + eye).LUsolve(W - eye)

    def c_context(self):
        """With a minimal-polynomial structure, cay(X) − I = Σ_k d_k(θ²) X^k in closed
        form (so(3): 4 (X + X²/2)/(4 + θ²)), which the C evaluates in a few products
        instead of a pivoted solve of (I − X/2) D = X per retraction (a fifth of a path
        update on SO(3)); the denominators are powers of 4 + θ² > 0, θ² being positive
        semi-definite. Either way the Cayley inverse is the chart's exact logarithm
        (``cayley_log``: no Newton, no warm start)."""
        structure = self.group.minimal_structure
        if structure is None:
            return RetractionC("cayley_solve", "cayley_log", log_warm_start=False)
        s = sp.Symbol("s", nonnegative=True)
        terms = analytic.minus_identity_coefficients(analytic.CAYLEY, *structure["matrix"], s)
        return RetractionC("cayley_polynomial", "cayley_log", log_warm_start=False,
                           coefficients=tuple(sp.ccode(sp.nsimplify(t)) for t in terms),
                           quadratic_form=[[float(v) for v in row]
                                           for row in structure["quadratic_form"].tolist()])


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

    def element(self, x):
        """exp(X): mpmath's expm at the working precision for numbers, else the closed
        form of :meth:`matrix`."""
        X = self.group.hat(x)
        return _from_mp(mpmath.expm(_to_mp(X))) if _numeric(X) else self.matrix(x)

    def logarithm(self, W):
        """The principal logarithm (:func:`_logm`), numbers only."""
        W = sp.Matrix(W)
        if not _numeric(W):
            raise NotImplementedError(f"{self.group.label}: no τ⁻¹ for symbolic matrices")
        return _from_mp(_logm(_to_mp(W)))

    def coefficient_functions(self):
        return list(analytic.coefficients(analytic.EXP, *self.matrix_structure))

    def c_context(self):
        """exp(X) = Σ c_k(θ²) X^k with analytic coefficient functions; its logarithm is
        Newton's from the warm start or from the Cayley inverse rescaled to the angle
        (``exponential_log``)."""
        return RetractionC("exponential", "exponential_log", log_warm_start=True,
                           coefficients=tuple(c.__name__ for c in self.coefficient_functions()),
                           quadratic_form=[[float(v) for v in row]
                                           for row in self.quadratic_form.tolist()],
                           chart_theta_squared=repr(math.pi ** 2))


#: Every retraction, by the name a group is declared with: the only place the names are
#: read (layout test).
RETRACTIONS = {"cayley": Cayley, "exp": Exponential}


def make(name: str, group: Group) -> Retraction:
    """The retraction called ``name`` ("cayley" or "exp") of ``group``."""
    if name not in RETRACTIONS:
        raise ModelError(f"unknown retraction {name!r}; known: {sorted(RETRACTIONS)}")
    return RETRACTIONS[name](group)


# -- numbers at mpmath's working precision (the structure maps of ``symvi check``) -------
def _numeric(M: sp.Matrix) -> bool:
    return all(v.is_number for v in M)


def _to_mp(M: sp.Matrix):
    return mpmath.matrix([[mpmath.mpf(sp.Float(sp.N(v, mpmath.mp.dps), mpmath.mp.dps)._mpf_)
                           for v in M.row(i)] for i in range(M.rows)])


def _logm(W):
    """Principal logarithm of the mpmath matrix W at the working precision.

    log W = 2 artanh Z = 2 Σ Z^{2k+1}/(2k+1), Z = (W − I)(W + I)⁻¹, converges to the
    principal logarithm when ‖Z‖ < 1, each term a factor ‖Z‖² smaller: for the checks'
    near-identity products (‖Z‖ ≲ 0.3) a few dozen products instead of mpmath's
    repeated square roots (``logm``: a Denman–Beavers iteration per halving, then the
    series of log(I + X); the routes check on an exponential-map model spent most of
    its time there). mpmath's ``logm`` takes the matrices this series would converge
    slowly for (‖Z‖ > 1/2).
    """
    with mpmath.extraprec(10):
        eye = mpmath.eye(W.rows)
        try:
            Z = (W - eye) * mpmath.inverse(W + eye)
        except ZeroDivisionError:   # an eigenvalue −1: no principal logarithm
            return mpmath.logm(W)
        ratio = mpmath.mnorm(Z, 1)
        if ratio > 0.5:
            return mpmath.logm(W)
        # terms k > K are below ε‖Z‖ together: ratio^{2K} ≤ ε (1 − ratio²)
        K = 0 if ratio == 0 else int(mpmath.ceil(mpmath.log(mpmath.eps * (1 - ratio**2))
                                                 / (2 * mpmath.log(ratio))))
        Z2, term, total = Z * Z, Z, Z
        for k in range(1, K + 1):
            term = term * Z2
            total += term / (2 * k + 1)
        return 2 * total


def _from_mp(M) -> sp.Matrix:
    """Back to SymPy Floats; the real part (logm of a real matrix may come back complex
    with imaginary parts at round-off)."""
    return sp.Matrix(M.rows, M.cols,
                     lambda i, j: sp.Float(mpmath.re(M[i, j]), mpmath.mp.dps))
