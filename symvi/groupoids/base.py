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

The contract, in one place (everything the engine, the rules, the templates and the run
time call on a groupoid is declared here):

1. Abstract — every groupoid gives them: ``source_dim``, ``fibre_dim``, ``target``,
   ``right``, ``left``, ``continuous_symbols``, ``leading_symbols``, ``rules``,
   ``discrete_symbols``, ``discrete_mapping``, ``predictor``, ``fingerprint``.
2. What its rules read (:mod:`symvi.discretisation.rules`; a rule applies to the
   groupoids that give what it reads, each groupoid lists its rules): ``window_nodes``
   and ``point`` (node rules), ``algebra_point``, ``base_point`` and ``base_quadrature``
   (increment rules), ``factors`` and ``factor_slots`` (product rules).
3. Hooks with defaults: ``algebroid``, ``state_symbols``, ``step_scaled``, ``move``
   (with ``whole_trajectory``), ``manifold``, ``c_context`` (a :class:`CContext`: the C
   of the group factors and of the fibres that copy nodes), ``coefficient_functions``,
   ``fibre_nodes``, ``initial_layout``, ``check_initial``, ``default_discretisation``,
   ``rule``, ``derivative``; for the checks ``identity``, ``multiply``, ``inverse``,
   ``basis_curve``, ``fibre_sampling``, ``component_names``, ``matrix_groups``,
   ``equation_setting``, ``step_matrix_name``, ``preserved_structure``.
4. Flags and data (class attributes): ``kind`` (a label for messages and metadata, never
   branched on outside this package), ``names``, ``max_order``, ``whole_trajectory``,
   ``elements_are_node_pairs`` (a path is its nodes: initial data in the ``"nodes"``
   layout, the checks' expansions in q, q̇, …), ``sampling_text``, ``structure_check``.
"""
from __future__ import annotations

import operator
from abc import ABC, abstractmethod
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np
import sympy as sp

from ..errors import ModelError
from ..discretisation.rules import RULES, Points, Rule, rule_names
from .retraction import RetractionC


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


@dataclass(frozen=True)
class NodeCopy:
    """Fibre coordinates f[f_offset : f_offset + dim] that are the element's target node's
    base coordinates x[x_offset : x_offset + dim] (a pair factor: the element is the pair
    of its nodes). The C copies them (``templates/fibres.c.j2``); the run time maps a
    state (x, v) to such a fibre as x + h v (``INFO.fibre_nodes``)."""

    x_offset: int
    f_offset: int
    dim: int


@dataclass(frozen=True)
class GroupFactor:
    """One matrix-group factor for ``templates/group.c.j2`` and ``retractions.c.j2``: its ξ
    starts at f[offset], its d×d configuration at g[g_offset] of a node
    (:func:`symvi.codegen.emit`), ``invariants`` what the run time checks of it
    (:meth:`MatrixLieGroup.invariants`), ``retraction`` the C of its retraction."""

    label: str
    matrix_dim: int
    dim: int
    offset: int
    invariants: dict
    basis: list
    dual: list
    retraction: RetractionC
    g_offset: int = 0


@dataclass(frozen=True)
class CContext:
    """What the C templates need of a groupoid beyond its kernels: the configuration
    reconstructed along a path (Σ d² numbers over ``groups``), the matrix-group factors
    and the fibre coordinates that copy the target node (``node_copies``). The templates
    loop over these; they never ask which kind of groupoid made them."""

    configuration_dim: int = 0
    groups: tuple[GroupFactor, ...] = ()
    node_copies: tuple[NodeCopy, ...] = field(default=())

    def shifted(self, x_offset: int, f_offset: int) -> "CContext":
        """The same factors inside a product, whose sources start at ``x_offset`` and
        fibres at ``f_offset``."""
        return CContext(self.configuration_dim,
                        tuple(replace(G, offset=G.offset + f_offset) for G in self.groups),
                        tuple(NodeCopy(c.x_offset + x_offset, c.f_offset + f_offset, c.dim)
                              for c in self.node_copies))


class Groupoid(ABC):
    """A Lie groupoid in coordinates; see the module docstring for the contract."""

    #: Short name of the groupoid kind, stored in generated modules' metadata and shown
    #: in messages; nothing outside :mod:`symvi.groupoids` branches on it (layout test).
    kind: str = "abstract"
    #: The highest order of Lagrangian declared on this groupoid (the number of slots of
    #: its L_d): 2 unless a groupoid's rules and symbols go further (at most
    #: :data:`symvi.discretisation.rules.MAX_ORDER`).
    max_order: int = 2
    #: Names of the coordinates (a pair groupoid's, a Lie algebra's), for symbols and
    #: messages; the checks' jets of a groupoid whose elements are node pairs use them.
    names: tuple[str, ...] = ()

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

    def derivative(self, j: int) -> tuple[sp.Symbol, ...]:
        """The symbols of the j-th time derivative of the coordinates (q⁽ʲ⁾ on a pair
        groupoid, ξ⁽ʲ⁾ on a Lie group: :func:`derivative_name`), for declaring
        Lagrangians of higher order and for the checks' jets."""
        raise NotImplementedError(f"{self!r} does not name the derivatives of its coordinates")

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

    # -- what the rules read (symvi.discretisation.rules) ---------------------------------
    # A rule applies to the groupoids that list it in ``rules``; each reads the window
    # through the hooks below that its kind of quadrature needs, so a groupoid gives
    # those of the rules it lists and may leave the others.
    def window_nodes(self, xs: Sequence[Sequence[sp.Expr]],
                     fs: Sequence[Sequence[sp.Expr]]) -> list[tuple[sp.Expr, ...]]:
        """The nodes q_0, q_1, … of a window of consecutive elements (x_j, f_j), for rules
        that interpolate nodes (``midpoint``, ``trapezoid``, ``three_point``,
        ``central<k>``)."""
        raise NotImplementedError(f"{self!r} has no nodes for node rules")

    def point(self, *derivatives: Sequence[sp.Expr]) -> dict:
        """The substitution of the continuous symbols q, q̇, … by ``derivatives``: one
        quadrature point of a node rule."""
        raise NotImplementedError(f"{self!r} has no quadrature points for node rules")

    def algebra_point(self, fs: Sequence[Sequence[sp.Expr]], h: sp.Expr) -> dict:
        """The substitution of ξ, ξ̇, …, ξ⁽ᵏ⁻¹⁾ from the increments of a window of k
        elements (rules ``lie``, ``lie_midpoint``, ``lie_central<k>``)."""
        raise NotImplementedError(f"{self!r} has no Lie algebra point for increment rules")

    def base_point(self, x: Sequence[sp.Expr]) -> dict:
        """The substitution of the base coordinates by the point ``x`` (none on a group)."""
        raise NotImplementedError(f"{self!r} has no base point for increment rules")

    def base_quadrature(self, xs: Sequence[Sequence[sp.Expr]],
                        fs: Sequence[Sequence[sp.Expr]], h: sp.Expr) -> Points:
        """Weighted substitutions of the base coordinates over one element, for the
        first-order increment rule ``lie``: the trapezoid h/2 [l(x_0, ·) + l(x_1, ·)]
        with x_1 the base point after the element — given (``len(xs) > len(fs)``: then
        derivatives go through it by the chain rule) or β(x_0, f_0). A groupoid without
        base coordinates gives one point of weight 1 instead (nothing to average)."""
        x1 = xs[1] if len(xs) > len(fs) else self.target(xs[0], fs[0], h)
        return [(sp.S.Half, self.base_point(xs[0])), (sp.S.Half, self.base_point(x1))]

    def factor_slots(self, xs: Sequence[Sequence[sp.Expr]],
                     fs: Sequence[Sequence[sp.Expr]]) -> list[tuple[list, list]]:
        """Per factor (:attr:`factors`): its sources and fibres of every slot (product
        rules)."""
        return [(list(xs), list(fs))]

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
    def initial_layout(self) -> str:
        """The name of the layout of step-map initial data (``INITIAL_LAYOUTS`` of
        ``symvi/_runtime/core/paths.py``): ``"nodes"`` where a path is its nodes
        (:attr:`elements_are_node_pairs`), else ``"elements"`` (x_0, g_0, f)."""
        return "nodes" if self.elements_are_node_pairs else "elements"

    def state_symbols(self) -> tuple[tuple[sp.Symbol, ...], tuple[sp.Symbol, ...]]:
        """The symbols of a state (x, v) of a first-order Lagrangian in the order of a
        State's arrays: the base coordinates, then the velocity of each fibre coordinate
        (the inputs of the ``legendre`` kernel, ∂L/∂v). By default the algebroid's q and y
        (a product's blockwise: all base coordinates, then all velocities)."""
        algebroid = self.algebroid()
        return tuple(algebroid.q), tuple(algebroid.y)

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

    def c_context(self) -> CContext:
        """What the C templates need beyond the kernels (:class:`CContext`): how the fibre
        of an element follows from its two nodes in the whole-trajectory solve — a copy
        of the target node's coordinates (:class:`NodeCopy`) or τ⁻¹(g_k⁻¹g_{k+1})/h of a
        matrix-group factor (:class:`GroupFactor`). By default the copies that
        :meth:`fibre_nodes` finds and no group."""
        copies = [NodeCopy(j, a, 1) for a, j in enumerate(self.fibre_nodes()) if j is not None]
        return CContext(node_copies=tuple(copies))

    def coefficient_functions(self) -> list:
        """Analytic coefficient functions the C reconstruction uses (exponential maps)."""
        return []

    def fibre_nodes(self) -> tuple[int | None, ...]:
        """Per fibre coordinate f_a: the index j of the base coordinate it is at the
        element's target node (β(x, f)_j = f_a identically: a pair factor's fibre is the
        next node), or None (an increment, or anything else). By default read off
        :meth:`target` at symbolic coordinates."""
        x = sp.symbols(f"x0:{self.source_dim}", real=True)
        f = sp.symbols(f"f0:{self.fibre_dim}", real=True)
        beta = tuple(self.target(x, f, sp.Symbol("h", positive=True)))
        return tuple(beta.index(v) if v in beta else None for v in f)

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

    def check_boundary(self, value, order: int, what: str) -> None:
        """Raise ModelError unless ``value`` can be boundary data of a whole-trajectory
        solve of ``order``: a State (an object with ``v``, ``x``, ``g``; second order
        only) with a velocity per fibre coordinate, a position per base coordinate
        (those a group acting on itself holds in g may be left out) and configurations
        on their groups; or ``order`` nodes — base points (r, m), configurations
        (r, d, d) per group factor, or both as (x, g) — their configurations on their
        groups (MatrixLieGroup.check_configurations). Checked when a model is declared, before any build; the run time checks
        the same data again, with its parameters."""
        m, groups = self.source_dim, self.matrix_groups()
        if all(hasattr(value, a) for a in ("v", "x", "g")):
            if order != 2:
                raise ModelError(f"{what}: States are boundary data of second-order problems; "
                                 f"an order-{order} problem fixes its end nodes (positions)")
            _shape(value.v, (self.fibre_dim,), f"the {what} state's velocity v")
            held = m and all(i >= 0 for i in self.configuration_base())
            if m and not (held and value.x is None):
                _shape(value.x, (m,), f"the {what} state's position x")
            blocks = [] if value.g is None else [value.g] if len(groups) == 1 else list(value.g)
            for G, g in zip(groups, blocks):
                _shape(g, (G.matrix_dim, G.matrix_dim), f"the {what} state's configuration g")
                G.check_configurations(np.asarray(g, dtype=float)[None],
                                       f"the {what} state's configuration g")
            return
        pair = isinstance(value, (tuple, list)) and len(value) == 2 \
            and np.ndim(value[0]) == 2 and np.ndim(value[1]) >= 3
        held = m and all(i >= 0 for i in self.configuration_base())
        x, g = value if pair else (None, value) if held or not m else (value, None)
        if m and x is not None:
            _shape(x, (order, m), f"the {what} base points")
        blocks = [] if g is None else [g] if len(groups) == 1 else list(g)
        for G, nodes in zip(groups, blocks):
            _shape(nodes, (order, G.matrix_dim, G.matrix_dim), f"the {what} configurations")
            G.check_configurations(np.asarray(nodes, dtype=float), f"the {what} configuration")

    def configuration_base(self) -> tuple[int, ...]:
        """Per base coordinate, the row-major index into the node's flat configuration g
        (the matrix groups' entries in order) of the entry it equals, or −1: the run time
        fills and checks such base points from g (:meth:`ActionGroupoid.on_itself`)."""
        return (-1,) * self.source_dim

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
