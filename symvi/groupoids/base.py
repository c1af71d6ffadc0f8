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
built from these by :mod:`symvi.derivation.derive`, so a new groupoid is a new subclass only.
"""
from __future__ import annotations

import operator
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import sympy as sp

from ..errors import ModelError
from ..discretisation.rules import RULES, Rule, rule_names


def derivative_name(name: str, k: int) -> str:
    """Name of the k-th time derivative of the coordinate ``name``: ``x``, ``x_dot``,
    ``x_ddot``, ``x_dddot``, then ``x_d4``, … (the symbols of Lagrangians of order k)."""
    return name + (("", "_dot", "_ddot", "_dddot")[k] if k < 4 else f"_d{k}")


def _check_derivative(j, highest: int) -> int:
    """``j`` as an int in 0 … ``highest`` (Lagrangians go up to order
    :data:`symvi.discretisation.rules.MAX_ORDER`). Python, NumPy and SymPy integers are
    integers; booleans, floats (even 3.0) and anything else are refused."""
    # operator.index is the integer protocol int, np.int64 and sp.Integer share; a float
    # has no __index__, a bool has one but means a flag, not an order
    try:
        index = None if isinstance(j, (bool, np.bool_)) else operator.index(j)
    except TypeError:
        index = None
    if index is None:
        raise ModelError(f"derivative({j!r}): the order of the derivative must be an "
                         f"integer, got {type(j).__name__}")
    if not 0 <= index <= highest:
        raise ModelError(f"derivative({index}): the derivatives of a Lagrangian's symbols go "
                         f"from 0 to {highest} (Lagrangians up to order 6)")
    return index


def subscript(number: int) -> str:
    """``number`` in subscript digits, for messages (12 → ₁₂)."""
    return str(number).translate(str.maketrans("0123456789", "₀₁₂₃₄₅₆₇₈₉"))


def step_matrix(order: int) -> str:
    """D₁₂L_d, D₁₃L_d, …: the mixed derivative of L_d in its first and last nodes, whose
    invertibility defines the step map of ``order``."""
    return f"D₁{subscript(order + 1)}L_d"


def _shape(value, expected: tuple[int, ...], what: str) -> None:
    shape = np.shape(value)
    if shape != expected:
        raise ModelError(f"{what} has shape {shape}, expected {expected}")


@dataclass(frozen=True)
class Algebroid:
    """The Lie algebroid AG of a groupoid in the coordinates of its basis sections e_α.

    Base coordinates ``q`` (m), fibre coordinates ``y`` (n) and their rates ``ydot``
    (the continuous symbols of the groupoid's Lagrangians), the anchor ``anchor``
    (m×n: q̇ = ρ(q) y) and the structure functions, ``structure[γ][α, β]`` = C^γ_{αβ}(q)
    with ⟦e_α, e_β⟧ = C^γ_{αβ} e_γ (paper §3.3.1, Appendix C).
    """

    q: tuple[sp.Symbol, ...]
    y: tuple[sp.Symbol, ...]
    ydot: tuple[sp.Symbol, ...]
    anchor: sp.Matrix
    structure: tuple[sp.Matrix, ...]


def block_algebroid(parts: Sequence[Algebroid]) -> Algebroid:
    """The algebroid of a product: anchors and structure functions blockwise."""
    anchor = sp.diag(*[a.anchor for a in parts]) if parts else sp.zeros(0, 0)
    n = sum(len(a.y) for a in parts)
    structure, offset = [], 0
    for a in parts:
        k = len(a.y)
        for C in a.structure:
            M = sp.zeros(n, n)
            M[offset:offset + k, offset:offset + k] = C
            structure.append(M)
        offset += k
    return Algebroid(tuple(s for a in parts for s in a.q), tuple(s for a in parts for s in a.y),
                     tuple(s for a in parts for s in a.ydot), anchor, tuple(structure))


class Groupoid(ABC):
    """A Lie groupoid in coordinates; see the module docstring for the contract."""

    #: Short name of the groupoid kind, stored in generated modules' metadata.
    kind: str = "abstract"
    #: The highest order of Lagrangian declared on this groupoid (the number of slots of
    #: its L_d): 2 unless a groupoid's rules and symbols go further (at most
    #: :data:`symvi.discretisation.rules.MAX_ORDER`).
    max_order: int = 2

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
    def rules(self, order: int) -> tuple[Rule, ...]:
        """The discretisation rules (:mod:`symvi.discretisation.rules`) that apply to this groupoid at
        ``order``; the first is the default. Each owns its quadrature."""

    def default_discretisation(self, order: int) -> str:
        """Name of the rule used when a model names none."""
        return self.rules(order)[0].name

    def rule(self, name: str) -> Rule:
        """The rule of this groupoid called ``name``; a ModelError for any other name."""
        mine = {r.name: r for order in range(1, self.max_order + 1) for r in self.rules(order)}
        if name in mine:
            return mine[name]
        if name in RULES:
            raise ModelError(f"discretisation {name!r} does not apply to {self!r}; its rules "
                             f"are {sorted(mine)}")
        raise ModelError(f"unknown discretisation {name!r}; known: {rule_names()}")

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

    def algebroid(self) -> Algebroid:
        """The Lie algebroid AG in coordinates (optimal control, paper §3.3)."""
        raise NotImplementedError(f"{self!r} does not describe its Lie algebroid")

    # -- structure maps in element coordinates (paper §2.1) -----------------------------
    # Used only by ``symvi check`` (check "routes"), which rebuilds the invariant fields
    # X⃖_a, X⃗_a by differentiating these maps, independently of ``right``/``left``. Each
    # takes and returns coordinates (x, f) as tuples of SymPy numbers or expressions.
    def identity(self, x: Sequence[sp.Expr]) -> tuple[tuple, tuple]:
        """Coordinates (x, f) of the identity ε(x) at the base point x."""
        raise NotImplementedError(f"{self!r} does not give its structure maps")

    def multiply(self, x: Sequence[sp.Expr], f: Sequence[sp.Expr], x2: Sequence[sp.Expr],
                 f2: Sequence[sp.Expr], h: sp.Expr) -> tuple[tuple, tuple]:
        """Coordinates of m(g, g') = g·g' for a composable pair g = (x, f), g' = (x2, f2)
        (β(g) = α(g') = x2; not checked)."""
        raise NotImplementedError(f"{self!r} does not give its structure maps")

    def inverse(self, x: Sequence[sp.Expr], f: Sequence[sp.Expr],
                h: sp.Expr) -> tuple[tuple, tuple]:
        """Coordinates of i(g) = g⁻¹; its source is β(g)."""
        raise NotImplementedError(f"{self!r} does not give its structure maps")

    def basis_curve(self, x: Sequence[sp.Expr], a: int, eps: sp.Expr,
                    h: sp.Expr) -> tuple[tuple, tuple]:
        """Coordinates of σ_a(ε): a curve in the α-fibre of x through ε(x) whose tangent at
        ε = 0 is the basis section e_a of the algebroid (the σ_a of DESIGN.md §2)."""
        raise NotImplementedError(f"{self!r} does not give its structure maps")

    def move(self, x: Sequence[sp.Expr], eta: Sequence[sp.Expr]) -> tuple[sp.Expr, ...]:
        """Base point of a node after the variation g → g·τ(η) of the elements meeting
        there (the whole-trajectory update; pair groupoid: x + η)."""
        raise NotImplementedError(f"{self!r} has no whole-trajectory update")

    def c_context(self) -> dict:
        """Numbers the C templates need beyond the kernels.

        ``configuration_dim``: numbers of the configuration reconstructed along a path
        (Σ d² over matrix-group factors); ``groups``: one dict per matrix-group factor
        (see :meth:`MatrixLieGroup.group_context`); ``factors``: how the fibre of an
        element follows from its two nodes, per factor — ``pair`` (a copy of the target
        node's coordinates) or ``group`` (τ⁻¹(g_k⁻¹g_{k+1})/h of matrix group ``group``).
        """
        return {"configuration_dim": 0, "groups": [], "factors": []}

    def coefficient_functions(self) -> list:
        """Analytic coefficient functions the C reconstruction uses (exponential maps)."""
        return []

    #: Whether the whole-trajectory solve (DESIGN.md §4) is available: the nodes are
    #: the unknowns, moved by :meth:`move` and, on matrix-group factors, corrected
    #: multiplicatively.
    whole_trajectory: bool = False

    # -- what the checks need to know (symvi.checks; no kind branches outside here) ------
    #: Whether an element is the pair of its end nodes in Rⁿ (the pair groupoid): a path
    #: is then its nodes, and its residual expands in them directly (E(L) in q, q̇, q̈).
    elements_are_node_pairs: bool = False
    #: How the consistency check samples an element along a smooth curve, in words.
    sampling_text: str = "fibres sampled along a curve of the Lie algebroid"
    #: Whether :mod:`symvi.checks.stepmap` knows the Poisson structure its step map
    #: preserves (pair groupoid, Lie group, action groupoid and their products).
    structure_check: bool = False

    @property
    def factors(self) -> tuple["Groupoid", ...]:
        """The factors of a product groupoid; ``(self,)`` for any other."""
        return (self,)

    def manifold(self, x: Sequence[sp.Expr]) -> tuple[sp.Expr, ...]:
        """Equations F(x) = 0 of the submanifold of the base that the model's base points
        live on (an action groupoid's declared ``manifold``); none by default. Compiled
        into the ``manifold`` kernel, with which the run time checks the user's data."""
        return ()

    def matrix_groups(self) -> tuple:
        """The matrix Lie groups of this groupoid (a Lie group, an action groupoid's
        acting group, a product's): their Lie algebra bases must close."""
        return ()

    def fibre_sampling(self) -> tuple[int | None, ...]:
        """How each fibre coordinate is sampled along a curve (consistency expansions):
        the index of the base coordinate whose value at the element's target node it is
        (a pair factor's fibre is the next node), or None for an increment sampled at the
        middle of the element (ξ of a group factor)."""
        raise NotImplementedError(f"consistency expansions do not know how to sample the "
                                  f"fibre of {self!r} along a curve")

    def component_names(self) -> tuple[str, ...]:
        """Names of the residual's components (the fibre directions e_α): a pair factor's
        coordinate names, a group factor's Lie algebra coordinates."""
        algebroid = self.algebroid()
        base = [str(s) for s in algebroid.q]
        return tuple(base[i] if i is not None else str(y)
                     for i, y in zip(self.fibre_sampling(), algebroid.y))

    def equation_setting(self, order: int) -> str:
        """Where the continuous Euler–Lagrange equations live, for messages."""
        return "on the Lie algebroid"

    def step_matrix_name(self, order: int) -> str:
        """The matrix that defines the step map (regularity), for messages."""
        return f"{step_matrix(order)} analogue"

    def preserved_structure(self, order: int) -> str:
        """The structure the step map of ``order`` preserves (paper §4.3), for messages; of
        order r ≥ 3 the reduced T*(H^r) in the chart of the first r nodes
        (:meth:`symvi.checks.stepmap.StepMap.legendre`), for every groupoid."""
        if order == 1:
            return "linear Poisson structure of A*G, (x_k, μ_k) ↦ (x_{k+1}, μ_{k+1})"
        if order == 2:
            return "Poisson structure of A*(P^αG) = A*G × T*H, (x, ν, w_k, p) one element on"
        f, p = (", ".join(f"{c}{subscript(j)}" for j in range(order - 1)) for c in "fp")
        return (f"Poisson structure of A*G × T*(H^{order - 1}) (the reduced T*(H^{order}); on "
                f"a pair groupoid the canonical form of T*(Q^{order})), (x₀, ν; {f}; {p}) one "
                f"element on")
