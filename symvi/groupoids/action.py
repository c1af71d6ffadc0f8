"""Action Lie groupoids Q×H ⇉ Q of a right action of a matrix Lie group (paper §2.1).

An element (q, w) goes from q to q·w = φ(q, w); (q, w)(q·w, w') = (q, ww'). In
coordinates (DESIGN.md §2) its source is q ∈ Rᵐ and its fibre part ξ = τ⁻¹(w)/h, so

* β(q, ξ) = φ(q, τ(hξ)) — the reconstruction q_{k+1} = φ(q_k, w_k) of DESIGN.md §3;
* right(g, a): q is unchanged, ξ moves as on the group;
* left(g, a): ξ moves as on the group and q by the infinitesimal action
  d/dε φ(q, τ(εE_a)) at ε = 0 (σ_a(ε)⁻¹·g starts at q·τ(εE_a)).

The heavy top is the standard example: Q = S² ∋ Γ (the direction of gravity in the body
frame), H = SO(3), Γ·R = RᵀΓ (paper §3.1, action-groupoid example).
"""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np
import sympy as sp

from ..errors import ModelError
from .base import Algebroid, CContext, Groupoid, _shape
from .lie import MatrixLieGroup, _symbol_names

Action = Callable[[sp.Matrix, sp.Matrix], Sequence[sp.Expr]]


class ActionGroupoid(Groupoid):
    """Q×H for a right action φ : Q×H → Q of a :class:`MatrixLieGroup` H.

    Parameters
    ----------
    group:
        The acting group H, with its retraction.
    base:
        Names of the coordinates q of Q ⊂ Rᵐ (list or space-separated string).
    action:
        ``action(q, W)`` → φ(q, W), m expressions, for q an m×1 matrix and W a d×d matrix
        of H. Checked at construction: φ(q, I) = q exactly, and φ(φ(q, A), B) = φ(q, AB)
        at random points and group elements (a right action).
    label:
        Name for messages and fingerprints.
    manifold:
        Optional ``manifold(q)`` → expressions F(q) whose zero set is the submanifold of
        Q the base points live on (S² ⊂ R³: ``lambda q: [q.dot(q) - 1]``). It must be
        invariant under the action (checked: F is constant along the action's generators).
        Base points passed at run time are then checked to lie on it.
    """

    kind = "action"
    whole_trajectory = True
    sampling_text = ("increments ξ_i = y(t + (i + ½)h), base points x_0 = q(t_0), "
                     "x_{j+1} = β(x_j, ξ_j)")
    structure_check = True

    def __init__(self, group: MatrixLieGroup, base: str | Sequence[str], action: Action,
                 label: str | None = None,
                 manifold: Callable[[sp.Matrix], Sequence[sp.Expr]] | None = None):
        if not isinstance(group, MatrixLieGroup):
            raise ModelError(f"the acting group must be a MatrixLieGroup, got {group!r}")
        self.group = group
        names = base.replace(",", " ").split() if isinstance(base, str) else list(base)
        if not names:
            raise ModelError("an action groupoid needs at least one base coordinate")
        self.names = _symbol_names(names, len(names), "q")
        clash = set(self.names) & set(group.names)
        if clash:
            raise ModelError(f"base coordinate names {sorted(clash)} clash with the group's")
        self.label = label or f"Q×{group.label}"
        self.q = tuple(sp.Symbol(n, real=True) for n in self.names)
        self._action = action
        self._W = sp.Matrix(group.matrix_dim, group.matrix_dim,
                            lambda i, j: sp.Symbol(f"W{i}{j}", real=True))
        self._phi = self._evaluate_action(sp.Matrix(self.q), self._W)
        self._check_identity()
        self._check_right_action()
        e = sp.Dummy("epsilon")
        self._generators = sp.Matrix.hstack(*[
            sp.diff(self._phi.xreplace(dict(zip(self._W, sp.eye(group.matrix_dim) + e * E))), e)
            .xreplace({e: 0}) for E in group.basis]).applyfunc(sp.expand)
        self._manifold = self._declared_manifold(manifold)

    #: Per base coordinate, the row-major index into the flat configuration g of the
    #: entry it equals (:meth:`on_itself`); empty for any other action.
    configuration_entries: tuple[int, ...] = ()

    @classmethod
    def on_itself(cls, group: MatrixLieGroup, names: str | Sequence[str] | None = None,
                  label: str | None = None) -> "ActionGroupoid":
        """The action groupoid G×G ⇉ G of the right multiplication of ``group`` on itself
        (paper §2.1 with Q = H = G; it is the pair groupoid of G's manifold): the base
        point of node k is its configuration g_k, so that path inequalities and costs may
        use the configuration — a world-frame box or obstacle, a pointing cone (issue 50,
        item 4) — with their derivatives along the group variation g ↦ g·τ(εη) from the
        action's generators, as for any base point.

        The base coordinates are the entries of g that vary over the group (those of the
        associative algebra its basis generates: SE(2)'s two top rows, SO(3)'s nine),
        named ``names`` (default ``g11 g12 …``, row and column from 1);
        :attr:`configuration` is g with them in place. At run time the nodes are the
        configurations alone (their base points are filled from them) or (x, g) pairs,
        whose base points must equal those entries.
        """
        d = group.matrix_dim
        entries = _varying_entries(group)
        default = [f"g{i // d + 1}{i % d + 1}" for i in entries]
        groupoid = cls(group, names or default, _right_multiplication(group, entries),
                       label or f"{group.label}×{group.label}")
        groupoid.configuration_entries = entries
        return groupoid

    @property
    def configuration(self) -> sp.Matrix:
        """g as a d×d matrix of the base coordinates (:meth:`on_itself`), the constant
        entries in place: ``G.configuration[0, 2]`` is SE(2)'s world x."""
        if not self.configuration_entries:
            raise ModelError(f"{self.label}: only the action of a group on itself "
                             f"(ActionGroupoid.on_itself) has a configuration among its "
                             f"base coordinates")
        return _filled(self.group, self.configuration_entries, self.q)

    def __repr__(self) -> str:
        return f"ActionGroupoid({self.label}: {list(self.names)} × {self.group!r})"

    def _declared_manifold(self, manifold) -> sp.Matrix:
        if manifold is None:
            return sp.zeros(0, 1)
        try:
            F = sp.Matrix(list(manifold(sp.Matrix(self.q))))
        except Exception as exc:
            raise ModelError(f"{self.label}: the manifold failed on symbolic input: {exc}") from None
        unknown = F.free_symbols - set(self.q)
        if unknown:
            raise ModelError(f"{self.label}: the manifold's equations may use the base "
                             f"coordinates only, not {sorted(map(str, unknown))}")
        drift = (F.jacobian(self.q) * self._generators).applyfunc(sp.simplify)
        if drift != sp.zeros(*drift.shape):
            raise ModelError(f"{self.label}: the manifold F = {list(F)} is not invariant "
                             f"under the action: its derivatives along the generators are "
                             f"{drift.tolist()}, not zero")
        return F

    def manifold(self, x):
        return tuple(self._manifold.xreplace(dict(zip(self.q, x))))

    # -- the action ---------------------------------------------------------------------
    def _evaluate_action(self, q: sp.Matrix, W: sp.Matrix) -> sp.Matrix:
        try:
            value = sp.Matrix(self._action(q, W))
        except Exception as exc:
            raise ModelError(f"{self.label}: the action failed on symbolic input: {exc}") from None
        value = value.reshape(len(value), 1)
        if value.shape[0] != len(self.names):
            raise ModelError(f"{self.label}: the action returns {value.shape[0]} coordinates, "
                             f"expected {len(self.names)} (one per base coordinate)")
        return value

    def act(self, q: Sequence[sp.Expr], W: sp.Matrix) -> sp.Matrix:
        """φ(q, W) for expressions q and a matrix W."""
        return self._phi.xreplace(dict(zip(self.q, q)) | dict(zip(self._W, W)))

    def _check_identity(self) -> None:
        moved = (self.act(self.q, sp.eye(self.group.matrix_dim)) - sp.Matrix(self.q))
        if moved.applyfunc(sp.simplify) != sp.zeros(len(self.q), 1):
            raise ModelError(f"{self.label}: the declared map is not an action: "
                             f"φ(q, I) = {list(self.act(self.q, sp.eye(self.group.matrix_dim)))} "
                             f"≠ q")

    def _check_right_action(self, samples: int = 3) -> None:
        from scipy.linalg import expm
        phi = sp.lambdify([self.q, list(self._W)], list(self._phi), "numpy")
        rng = np.random.default_rng(11)
        basis = [np.array(E, dtype=float) for E in self.group.basis]
        for _ in range(samples):
            q = rng.uniform(-1, 1, len(self.q))
            A, B = (expm(sum(c * E for c, E in zip(rng.uniform(-1, 1, len(basis)), basis)))
                    for _ in range(2))
            lhs = np.array(phi(phi(q, A.ravel()), B.ravel()), dtype=float)
            rhs = np.array(phi(q, (A @ B).ravel()), dtype=float)
            if not np.allclose(lhs, rhs, rtol=1e-9, atol=1e-12):
                left = np.allclose(lhs, np.array(phi(q, (B @ A).ravel()), dtype=float),
                                   rtol=1e-9, atol=1e-12)
                hint = (" (it is a left action: use φ(q, W⁻¹) to make it a right action)"
                        if left else "")
                raise ModelError(
                    f"{self.label}: the declared map is not a right action: φ(φ(q, A), B) = "
                    f"{np.round(lhs, 6).tolist()} but φ(q, AB) = {np.round(rhs, 6).tolist()} at "
                    f"q = {np.round(q, 6).tolist()}{hint}")

    # -- groupoid interface -------------------------------------------------------------
    @property
    def source_dim(self) -> int:
        return len(self.q)

    @property
    def fibre_dim(self) -> int:
        return self.group.fibre_dim

    @property
    def xi(self):
        return self.group.xi

    @property
    def xidot(self):
        return self.group.xidot

    def target(self, x, f, h):
        return tuple(self.act(x, self.group.tau([h * v for v in f])))

    def right(self, x, f, h):
        return sp.Matrix.vstack(sp.zeros(self.source_dim, self.fibre_dim),
                                self.group.right((), f, h))

    def left(self, x, f, h):
        return sp.Matrix.vstack(self._generators.xreplace(dict(zip(self.q, x))),
                                self.group.left((), f, h))

    def predictor(self, xs, fs):
        return self.group.predictor(xs, fs)

    # Structure maps (paper §2.1): ε(q) = (q, e), (q, w)(q·w, w') = (q, ww'),
    # (q, w)⁻¹ = (q·w, w⁻¹), with the group's own maps on ξ; σ_a(ε) = (q, τ(εE_a)).
    def identity(self, x):
        return tuple(x), self.group.identity(())[1]

    def multiply(self, x, f, x2, f2, h):
        return tuple(x), self.group.multiply((), f, (), f2, h)[1]

    def inverse(self, x, f, h):
        W = self.group.group_element([h * v for v in f])
        return tuple(self.act(x, W)), self.group.inverse((), f, h)[1]

    def basis_curve(self, x, a, eps, h):
        return tuple(x), self.group.basis_curve((), a, eps, h)[1]

    def algebroid(self) -> Algebroid:
        """The action algebroid Q×𝔥: anchor the infinitesimal action, structure
        functions the group's constants (paper §3.3.5)."""
        return Algebroid(self.q, self.xi, self.xidot, self._generators,
                         self.group.structure_functions())

    def move(self, x, eta):
        return tuple(self.act(x, self.group.tau(eta)))

    def continuous_symbols(self, order):
        return self.q + self.group.continuous_symbols(order)

    def leading_symbols(self, order):
        return self.group.leading_symbols(order)

    def rules(self, order):
        return self.group.rules(order)

    def step_scaled(self):
        return self.group.step_scaled()

    def algebra_point(self, fs, h) -> dict:
        """ξ (and ξ̇) of the group's rules, from the increments."""
        return self.group.algebra_point(fs, h)

    def matrix_groups(self):
        return (self.group,)

    def base_point(self, x) -> dict:
        """The substitution of the base coordinates q by the point ``x``."""
        return dict(zip(self.q, x))

    def discrete_symbols(self, order):
        return self.q + self.group.discrete_symbols(order)

    def discrete_mapping(self, order, xs, fs):
        return dict(zip(self.q, xs[0])) | self.group.discrete_mapping(order, xs, fs)

    def check_initial(self, initial, order):
        parts = list(initial)
        if len(parts) not in (2, 3):
            raise ModelError("initial data must be (q_0, xi) or (q_0, g_0, xi)")
        _shape(parts[0], (self.source_dim,), "initial base point q_0")
        if len(parts) == 3:
            d = self.group.matrix_dim
            _shape(parts[1], (d, d), "initial configuration g_0")
        _shape(parts[-1], (2 * order - 1, self.fibre_dim), "initial increments ξ")

    def fingerprint(self) -> str:
        return (f"action:{self.label}:{self.names}:{sp.srepr(self._phi)}:"
                f"{sp.srepr(self._manifold)}:{self.configuration_entries}:"
                f"{self.group.fingerprint()}")

    def configuration_base(self) -> tuple[int, ...]:
        if not self.configuration_entries:
            return super().configuration_base()
        return self.configuration_entries

    def fibre_sampling(self):
        return (None,) * self.fibre_dim          # ξ at the element's middle

    def equation_setting(self, order):
        return "on the action algebroid"

    def c_context(self) -> CContext:
        return CContext(self.group.matrix_dim ** 2, (self.group.group_context(0),))

    def coefficient_functions(self) -> list:
        return self.group.coefficient_functions()


def _varying_entries(group: MatrixLieGroup) -> tuple[int, ...]:
    """Row-major indices of the entries of g that vary over the group: those where some
    element of the associative algebra generated by its basis is nonzero (g = τ(ξ) is I
    plus such an element; the rest of g is the identity's)."""
    d = group.matrix_dim
    span = [E.reshape(d * d, 1) for E in group.basis]
    frontier = list(group.basis)
    while frontier:
        grown = []
        for A in frontier:
            for E in group.basis:
                candidate = (A * E).reshape(d * d, 1)
                if sp.Matrix.hstack(*span, candidate).rank() > len(span):
                    span.append(candidate)
                    grown.append(A * E)
        frontier = grown
    support = sp.Matrix.hstack(*span)
    return tuple(i for i in range(d * d) if any(support.row(i)))


def _filled(group: MatrixLieGroup, entries: Sequence[int], values) -> sp.Matrix:
    """The identity with ``values`` at the row-major ``entries``."""
    d = group.matrix_dim
    g = sp.eye(d)
    for i, v in zip(entries, values):
        g[i // d, i % d] = v
    return g


def _right_multiplication(group: MatrixLieGroup, entries: Sequence[int]) -> Action:
    """φ(q, W) = the ``entries`` of g(q)·W, for :meth:`ActionGroupoid.on_itself`."""
    def action(q: sp.Matrix, W: sp.Matrix) -> list:
        product = _filled(group, entries, list(q)) * W
        return [product[i // group.matrix_dim, i % group.matrix_dim] for i in entries]
    return action
