"""The pair groupoid Q×Q ⇉ Q over Q = Rⁿ (paper §2.1, first example; DESIGN.md §2)."""
from __future__ import annotations

from typing import Sequence

import sympy as sp

from ..errors import ModelError
from ..discretisation.rules import MAX_ORDER, MIDPOINT, THREE_POINT, TRAPEZOID, central
from .base import (Algebroid, CContext, Groupoid, NodeCopy, _check_derivative, _shape,
                   derivative_name, step_matrix)


def _names(coordinates: str | Sequence[str]) -> tuple[str, ...]:
    if isinstance(coordinates, str):
        coordinates = coordinates.replace(",", " ").split()
    names = tuple(str(c) for c in coordinates)
    if not names:
        raise ModelError("PairGroupoid needs at least one coordinate name")
    if len(set(names)) != len(names):
        raise ModelError(f"PairGroupoid coordinate names repeat: {names}")
    for name in names:
        if not name.isidentifier():
            raise ModelError(f"coordinate name {name!r} is not a valid identifier")
    return names


class PairGroupoid(Groupoid):
    """Q×Q with α(q₀, q₁) = q₀, β(q₀, q₁) = q₁ and (q₀, q₁)(q₁, q₂) = (q₀, q₂).

    An element is (x, f) = (q_k, q_{k+1}). The variations of DESIGN.md §2 are
    ``right = ∂/∂f`` and ``left = ∂/∂x``, so the engine reproduces
    D₁L_d(q_k, q_{k+1}) + D₂L_d(q_{k−1}, q_k) = 0 and, for second order, eq. ``dsoel``.

    Symbols for declaring Lagrangians: ``q`` (coordinates), ``qdot`` (velocities),
    ``qddot`` (accelerations), ``derivative(j)`` (q⁽ʲ⁾ for any j ≤ 6: ``x_dddot``,
    ``x_d4``, …, for a Lagrangian of order j; ``derivative(1)`` is ``qdot``) and, for a
    discrete Lagrangian given directly, ``nodes(k)`` — the coordinates of the k+1 nodes
    q_0, …, q_k of one window (order k).

    Parameters
    ----------
    coordinates:
        Names of the coordinates, as a list or a space/comma separated string.
    """

    kind = "pair"
    whole_trajectory = True
    elements_are_node_pairs = True
    sampling_text = "nodes q_j = q(t + jh)"
    structure_check = True
    max_order = MAX_ORDER

    def __init__(self, coordinates: str | Sequence[str]):
        self.names = _names(coordinates)
        self.q = tuple(sp.Symbol(n, real=True) for n in self.names)
        self.qdot = tuple(sp.Symbol(f"{n}_dot", real=True) for n in self.names)
        self.qddot = tuple(sp.Symbol(f"{n}_ddot", real=True) for n in self.names)

    def __repr__(self) -> str:
        return f"PairGroupoid({list(self.names)!r})"

    @property
    def source_dim(self) -> int:
        return len(self.names)

    @property
    def fibre_dim(self) -> int:
        return len(self.names)

    def nodes(self, count: int) -> tuple[tuple[sp.Symbol, ...], ...]:
        """Node symbols q_0 … q_{count−1} for writing a discrete Lagrangian directly."""
        return tuple(tuple(sp.Symbol(f"{n}_{k}", real=True) for n in self.names)
                     for k in range(count))

    def window_nodes(self, xs, fs) -> list[tuple[sp.Expr, ...]]:
        """Nodes q_0, q_1, … of a window of consecutive elements (x_j, f_j)."""
        return [tuple(xs[0])] + [tuple(f) for f in fs]

    def derivative(self, j: int) -> tuple[sp.Symbol, ...]:
        """The symbols of q⁽ʲ⁾: ``q``, ``qdot``, ``qddot``, then ``<name>_dddot``,
        ``<name>_d4``, … (:func:`derivative_name`)."""
        j = _check_derivative(j, MAX_ORDER)
        known = (self.q, self.qdot, self.qddot)
        if j < len(known):
            return known[j]
        return tuple(sp.Symbol(derivative_name(n, j), real=True) for n in self.names)

    def continuous_symbols(self, order):
        return tuple(s for j in range(order + 1) for s in self.derivative(j))

    def leading_symbols(self, order):
        return self.derivative(order)

    def rules(self, order):
        if order >= 3:
            return (central(order),)
        return (THREE_POINT,) if order == 2 else (MIDPOINT, TRAPEZOID)

    def point(self, *derivatives) -> dict:
        """The substitution q, q̇, … → the given values: a quadrature point."""
        return {s: v for j, values in enumerate(derivatives)
                for s, v in zip(self.derivative(j), values)}

    def discrete_symbols(self, order):
        return tuple(s for node in self.nodes(order + 1) for s in node)

    def discrete_mapping(self, order, xs, fs):
        nodes = self.window_nodes(xs, fs)
        return {s: e for node, slot_node in zip(self.nodes(order + 1), nodes)
                for s, e in zip(node, slot_node)}

    def check_initial(self, initial, order):
        _shape(initial, (2 * order, self.fibre_dim), f"the first {2 * order} nodes (2·order)")

    def target(self, x, f, h):
        return tuple(f)

    def right(self, x, f, h):
        n = self.fibre_dim
        return sp.Matrix.vstack(sp.zeros(n, n), sp.eye(n))

    def left(self, x, f, h):
        n = self.fibre_dim
        return sp.Matrix.vstack(sp.eye(n), sp.zeros(n, n))

    # Structure maps (paper §2.1): ε(q) = (q, q), (q₀, q₁)(q₁, q₂) = (q₀, q₂),
    # (q₀, q₁)⁻¹ = (q₁, q₀); σ_a(ε) = (q, q + ε e_a).
    def identity(self, x):
        return tuple(x), tuple(x)

    def multiply(self, x, f, x2, f2, h):
        return tuple(x), tuple(f2)

    def inverse(self, x, f, h):
        return tuple(f), tuple(x)

    def basis_curve(self, x, a, eps, h):
        return tuple(x), tuple(v + eps if i == a else v for i, v in enumerate(x))

    def algebroid(self) -> Algebroid:
        """TQ: y = q̇, anchor the identity, no structure functions."""
        n = self.fibre_dim
        return Algebroid(self.q, self.qdot, self.qddot, sp.eye(n), (sp.zeros(n, n),) * n)

    def move(self, x, eta):
        return tuple(a + b for a, b in zip(x, eta))

    def c_context(self) -> CContext:
        """The fibre is the target node: one copy of all coordinates."""
        return CContext(node_copies=(NodeCopy(0, 0, self.fibre_dim),))

    def predictor(self, xs, fs):
        # Linear extrapolation of the nodes: q_{k+1} ≈ 2 q_k − q_{k−1}.
        previous = fs[-2] if len(fs) > 1 else xs[-1]
        return tuple(2 * a - b for a, b in zip(fs[-1], previous))

    def fingerprint(self) -> str:
        return f"pair:{','.join(self.names)}"

    def fibre_sampling(self):
        return tuple(range(self.fibre_dim))     # f is the target node q_{k+1}

    def component_names(self):
        return self.names

    def equation_setting(self, order):
        return "on TQ"

    def step_matrix_name(self, order):
        return step_matrix(order)

    def preserved_structure(self, order):
        if order > 2:
            return super().preserved_structure(order)
        if order == 1:
            return "canonical symplectic form of T*Q, (q_k, p_k) ↦ (q_{k+1}, p_{k+1})"
        return "canonical symplectic form of T*(Q×Q), (q_k, q_{k+1}, p_k, p_{k+1}) one node on"
