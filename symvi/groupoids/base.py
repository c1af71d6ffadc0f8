"""The groupoid interface of the derivation engine (DESIGN.md §2, "vary the shared node").

An element g of a Lie groupoid G ⇉ Q is described in coordinates by its source
x = α(g) ∈ Q (``source_dim`` numbers) and its α-fibre part f (``fibre_dim`` numbers, the
rank of the algebroid AG). A groupoid supplies only

* ``target(x, f, h)``: the coordinates of β(g) (h for groupoids whose fibre coordinates
  are scaled by the time step);
* ``right(x, f, h)``: the matrix whose column a is d/dε of the coordinates (x, f) of
  g·σ_a(ε) at ε = 0 — the left-invariant field of the basis section e_a (paper §2.1);
  h is the time step, for groupoids whose fibre coordinates are scaled by it;
* ``left(x, f, h)``: the same for σ_a(ε)⁻¹·g — the paper's −X⃗_a(g); g's source moves too;
* ``predictor``: an explicit guess of the next fibre part from the previous elements,
  used to start Newton's method.

Everything else (discrete Euler–Lagrange residuals of any order, momenta, Jacobians) is
built from these by :mod:`symvi.derive`, so a new groupoid is a new subclass only.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Sequence

import numpy as np
import sympy as sp

from ..errors import ModelError


def _shape(value, expected: tuple[int, ...], what: str) -> None:
    shape = np.shape(value)
    if shape != expected:
        raise ModelError(f"{what} has shape {shape}, expected {expected}")


class Groupoid(ABC):
    """A Lie groupoid in coordinates; see the module docstring for the contract."""

    #: Short name of the groupoid kind, stored in generated modules' metadata.
    kind: str = "abstract"

    @property
    @abstractmethod
    def source_dim(self) -> int:
        """Number of coordinates of a base point x ∈ Q."""

    @property
    @abstractmethod
    def fibre_dim(self) -> int:
        """Rank n of the algebroid: number of fibre coordinates f of an element."""

    @abstractmethod
    def target(self, x: Sequence[sp.Expr], f: Sequence[sp.Expr],
               h: sp.Expr) -> tuple[sp.Expr, ...]:
        """Coordinates of β(g) for g = (x, f)."""

    @abstractmethod
    def right(self, x: Sequence[sp.Expr], f: Sequence[sp.Expr], h: sp.Expr) -> sp.Matrix:
        """(m+n)×n matrix: column a is d/dε (x, f)(g·σ_a(ε)) at ε = 0."""

    @abstractmethod
    def left(self, x: Sequence[sp.Expr], f: Sequence[sp.Expr], h: sp.Expr) -> sp.Matrix:
        """(m+n)×n matrix: column a is d/dε (x, f)(σ_a(ε)⁻¹·g) at ε = 0."""

    @abstractmethod
    def continuous_symbols(self, order: int) -> tuple[sp.Symbol, ...]:
        """Symbols a continuous Lagrangian of this order may use (besides parameters)."""

    @abstractmethod
    def leading_symbols(self, order: int) -> tuple[sp.Symbol, ...]:
        """The highest derivatives of an order-``order`` Lagrangian (Legendre condition)."""

    @abstractmethod
    def rules(self, order: int) -> tuple[str, ...]:
        """Names of the discretisations (:data:`symvi.discretise.RULES`) this groupoid
        supports at ``order``; the first is the default."""

    @abstractmethod
    def quadrature(self, rule: str, xs, fs, h: sp.Expr) -> list[tuple[sp.Expr, dict]]:
        """Weighted points of ``rule`` on a window of slots: L_d = h Σ w·L(point), each
        point a substitution of :meth:`continuous_symbols` (DESIGN.md §3)."""

    def default_discretisation(self, order: int) -> str:
        """Name of the rule used when a model names none."""
        return self.rules(order)[0]

    def step_scaled(self) -> tuple[bool, ...]:
        """Per fibre coordinate: True when it is an increment divided by h (ξ = τ⁻¹(w)/h).

        Holding a groupoid element fixed while h varies (the discrete energy) then holds
        h·ξ fixed.
        """
        return (False,) * self.fibre_dim

    @abstractmethod
    def discrete_symbols(self, order: int) -> tuple[sp.Symbol, ...]:
        """Symbols in which a discrete Lagrangian of this order is written directly."""

    @abstractmethod
    def discrete_mapping(self, order: int, xs, fs) -> dict:
        """Map :meth:`discrete_symbols` to the coordinates of ``order`` composable slots."""

    @abstractmethod
    def predictor(self, xs: Sequence[Sequence[sp.Expr]],
                  fs: Sequence[Sequence[sp.Expr]]) -> tuple[sp.Expr, ...]:
        """Guess of the next fibre part given earlier sources ``xs`` and fibres ``fs``."""

    @abstractmethod
    def fingerprint(self) -> str:
        """A string that changes whenever the groupoid's geometry changes (build cache)."""

    @property
    def element_dim(self) -> int:
        """Number of coordinates (x, f) of one element."""
        return self.source_dim + self.fibre_dim

    def check_initial(self, initial, order: int) -> None:
        """Raise ModelError unless ``initial`` is valid step-map initial data."""
        first, fibres = initial
        _shape(first, (self.source_dim,), "initial base point")
        _shape(fibres, (2 * order - 1, self.fibre_dim), "initial fibre parts")

    def c_context(self) -> dict:
        """Numbers the C templates need beyond the kernels.

        ``configuration_dim``: numbers of the configuration reconstructed along a path
        (Σ d² over matrix-group factors); ``groups``: one dict per matrix-group factor
        (see :meth:`MatrixLieGroup.group_context`).
        """
        return {"configuration_dim": 0, "groups": []}

    def coefficient_functions(self) -> list:
        """Analytic coefficient functions the C reconstruction uses (exponential maps)."""
        return []

    #: The unknowns of a whole-trajectory solve: "nodes" (the base points themselves, pair
    #: groupoid), "configurations" (matrix Lie groups, corrected multiplicatively; DESIGN.md
    #: §4) or None (not supported; the stencil Jacobian is then not emitted).
    whole_trajectory: str | None = None
