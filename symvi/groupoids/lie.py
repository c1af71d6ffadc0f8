"""Matrix Lie groups G ⇉ {e}, declared by a basis of their Lie algebra (paper §2.2, DESIGN.md §2).

An element is w = τ(hξ) with τ a retraction g → G; its fibre coordinates are ξ ∈ Rⁿ in the
declared basis E_1, …, E_n and its source is the single point e (source_dim 0). With
dτ⁻¹ the right-trivialised inverse derivative of τ, the variations of DESIGN.md §2 are

    right(w, a) = (1/h)·dτ⁻¹_{−hξ}(E_a),      left(w, a) = −(1/h)·dτ⁻¹_{hξ}(E_a),

so the first-order residual is the discrete Euler–Poincaré equation
(dτ⁻¹_{−hξ_k})*μ_k − (dτ⁻¹_{hξ_{k+1}})*μ_{k+1} = 0, μ = ∂l/∂ξ (end of paper §2, with the
signs of ERRATA.md item 7).

Retraction (chosen per group object, :mod:`symvi.groupoids.retraction`): the Cayley map of
any quadratic matrix group (dcay⁻¹ polynomial), or the exponential map where X and ad_X have
a closed-form minimal polynomial (SO(3), SE(2), SE(3)). Results are projected onto the basis
with its dual basis.
"""
from __future__ import annotations

from functools import cached_property
from typing import Sequence

import numpy as np
import sympy as sp

from .._runtime.core.groups import TOLERANCE, group_defects
from ..errors import ModelError
from ..discretisation.rules import LIE, LIE_MIDPOINT, MAX_ORDER, lie_central, window_derivatives
from . import analytic
from . import retraction as _retraction
from .base import (Algebroid, CContext, GroupFactor, Groupoid, _check_derivative, _shape,
                   derivative_name)


def _symbol_names(names, n: int, default: str) -> tuple[str, ...]:
    if names is None:
        return tuple(f"{default}{i + 1}" for i in range(n))
    names = tuple(names.replace(",", " ").split() if isinstance(names, str) else names)
    if len(names) != n:
        raise ModelError(f"{len(names)} names given for a Lie algebra of dimension {n}")
    if len(set(names)) != n or not all(s.isidentifier() for s in names):
        raise ModelError(f"Lie algebra coordinate names must be distinct identifiers: {names}")
    return names


class MatrixLieGroup(Groupoid):
    """A matrix Lie group with a retraction, as a groupoid over a point.

    Parameters
    ----------
    basis:
        Square matrices E_a spanning the Lie algebra; they must be linearly independent and
        close under the commutator (checked exactly).
    names:
        Names of the coordinates ξ_a (continuous symbols ``xi``; second-order models also
        use ``xidot``, a model of order k the derivatives ``derivative(j)`` = ξ⁽ʲ⁾ up to
        j = k − 1: ``<name>_ddot``, ``<name>_dddot``, ``<name>_d4``, …).
    label:
        Name of the group for messages and fingerprints.
    retraction:
        ``"cayley"`` (any quadratic group) or ``"exp"`` (closed forms where available).
    """

    kind = "lie"
    max_order = MAX_ORDER
    whole_trajectory = True
    sampling_text = "increments ξ_i = y(t + (i + ½)h) (element midpoints)"
    structure_check = True

    def __init__(self, basis: Sequence, names=None, label: str = "G",
                 retraction: str = "cayley"):
        self.label = label
        self.basis = tuple(sp.Matrix(E) for E in basis)
        if not self.basis:
            raise ModelError(f"{label}: empty Lie algebra basis")
        d = self.basis[0].shape[0]
        if any(E.shape != (d, d) for E in self.basis):
            raise ModelError(f"{label}: basis matrices must all be square of the same size")
        self.matrix_dim = d
        B = sp.Matrix.hstack(*[E.reshape(d * d, 1) for E in self.basis])
        if B.rank() < len(self.basis):
            raise ModelError(f"{label}: the basis matrices are linearly dependent")
        self._dual = (B.T * B).inv() * B.T
        self.structure_constants = self._closure()
        self.names = _symbol_names(names, len(self.basis), "xi")
        self.xi = tuple(sp.Symbol(n, real=True) for n in self.names)
        self.xidot = tuple(sp.Symbol(f"{n}_dot", real=True) for n in self.names)
        self.retraction = _retraction.make(retraction, self)

    def __repr__(self) -> str:
        return f"MatrixLieGroup({self.label}, dim {len(self.basis)}, {self.retraction.name})"

    # -- algebra --------------------------------------------------------------------------
    def coordinates(self, M: sp.Matrix) -> sp.Matrix:
        """Coordinates of an algebra element in the basis (dual-basis projection)."""
        return self._dual * sp.Matrix(M).reshape(self.matrix_dim ** 2, 1)

    def hat(self, v) -> sp.Matrix:
        """Σ v_a E_a."""
        return sum((vi * E for vi, E in zip(v, self.basis)), sp.zeros(self.matrix_dim))

    def invariants(self) -> dict[str, list]:
        """What the algebra fixes, as numbers: the conditions a configuration must meet to
        lie on the group, checked on the user's data at run time.

        ``quadratic`` J (gᵀJg = J: EᵀJ + JE = 0 for every basis E), ``coquadratic`` K
        (gKgᵀ = K: EK + KEᵀ = 0), ``fixed`` vectors (gv = v: Ev = 0) and ``cofixed``
        covectors (wᵀg = wᵀ: wᵀE = 0), each a basis of its solution space; and det g > 0,
        since the group is connected. SO(n): gᵀg = I; SE(n): the rotation block
        orthogonal and the last row (0, …, 0, 1). A group that these conditions do not
        cut out is checked only as far as they go.
        """
        d = self.matrix_dim
        S = [sp.Symbol(f"s_{i}_{j}") for i in range(d) for j in range(i, d)]
        M = sp.zeros(d)
        for (i, j), s in zip(((i, j) for i in range(d) for j in range(i, d)), S):
            M[i, j] = M[j, i] = s

        def symmetric_solutions(condition) -> list:
            equations = [e for E in self.basis for e in condition(E, M)]
            A = sp.Matrix([[sp.diff(e, s) for s in S] for e in equations])
            return [[[float(v) for v in row] for row in M.subs(dict(zip(S, vec))).tolist()]
                    for vec in A.nullspace()]

        def kernel(rows) -> list:
            return [[float(v) for v in vec] for vec in sp.Matrix.vstack(*rows).nullspace()]

        return {"quadratic": symmetric_solutions(lambda E, J: E.T * J + J * E),
                "coquadratic": symmetric_solutions(lambda E, K: E * K + K * E.T),
                "fixed": kernel(self.basis),
                "cofixed": kernel([E.T for E in self.basis])}

    def check_configurations(self, gs: np.ndarray, what: str) -> None:
        """Raise ModelError unless every matrix of ``gs`` (K, d, d) is finite and on the
        group: the run time's own test of the same data (``_runtime/core/groups.py``,
        the conditions of :meth:`invariants` within its relative tolerance)."""
        d = self.matrix_dim
        _shape(gs, (len(gs), d, d), what)
        defects, conditions = group_defects(gs, self.invariants())
        for k, row in enumerate(defects):
            worst = int(np.argmax(row)) if len(conditions) else 0
            if len(conditions) and not row[worst] <= TOLERANCE:
                node = f" (node {k})" if len(gs) > 1 else ""
                raise ModelError(f"{what}{node} is not on {self.label}: {conditions[worst]} "
                                 f"fails by {row[worst]:.3e} (tolerance {TOLERANCE:g}, "
                                 f"relative)")

    def _closure(self):
        n, constants = len(self.basis), {}
        for a in range(n):
            for b in range(a + 1, n):
                bracket = self.basis[a] * self.basis[b] - self.basis[b] * self.basis[a]
                c = self.coordinates(bracket)
                if (self.hat(c) - bracket).applyfunc(sp.simplify) != sp.zeros(self.matrix_dim):
                    raise ModelError(
                        f"{self.label}: the basis does not close under the bracket: "
                        f"[E{a + 1}, E{b + 1}] = {bracket.tolist()} is not in its span")
                constants[(a, b)] = tuple(c)
        return constants

    def ad(self, x) -> sp.Matrix:
        """Matrix of ad_X = [X, ·], X = Σ x_a E_a, in the basis."""
        X = self.hat(x)
        return sp.Matrix.hstack(*[self.coordinates(X * E - E * X) for E in self.basis])

    @cached_property
    def minimal_structure(self) -> dict | None:
        """The closed-form structure of X and ad_X, or None (see :mod:`.analytic`).

        ``matrix``, ``adjoint``: (a, b) with M^a (M² + θ²)^b = 0; ``theta_squared(x)``: θ²
        as a function of the coordinates; ``quadratic_form``: its matrix (θ² = xᵀQx).
        """
        x = sp.symbols(f"x0:{self.fibre_dim}", real=True)
        matrix = analytic.minimal_structure(self.hat(x))
        adjoint = analytic.minimal_structure(self.ad(x))
        if matrix is None or adjoint is None or sp.expand(matrix[2] - adjoint[2]) != 0:
            return None
        s = matrix[2]
        Q = sp.hessian(s, x) / 2
        if np.linalg.eigvalsh(np.array(Q, dtype=float)).min() < -1e-14:
            return None
        return {"matrix": matrix[:2], "adjoint": adjoint[:2], "quadratic_form": Q,
                "theta_squared": lambda v: s.xreplace(dict(zip(x, v)))}

    def dtau_inv(self, x) -> sp.Matrix:
        """Matrix of the retraction's right-trivialised dτ⁻¹_X, X = Σ x_a E_a."""
        return self.retraction.inverse_derivative(x)

    def structure_functions(self) -> tuple[sp.Matrix, ...]:
        """C^γ_{αβ} of [E_α, E_β] = C^γ_{αβ} E_γ, as ``result[γ][α, β]``."""
        n = self.fibre_dim
        out = [sp.zeros(n, n) for _ in range(n)]
        for (a, b), c in self.structure_constants.items():
            for g in range(n):
                out[g][a, b], out[g][b, a] = c[g], -c[g]
        return tuple(out)

    def algebroid(self) -> Algebroid:
        """The Lie algebra over a point: no base, zero anchor (paper §3.3.4)."""
        return Algebroid((), self.xi, self.xidot, sp.zeros(0, self.fibre_dim),
                         self.structure_functions())

    def move(self, x, eta):
        return ()

    def tau(self, x) -> sp.Matrix:
        """τ(X) as a matrix."""
        return self.retraction.matrix(x)

    # -- structure maps (paper §2.1), for ``symvi check`` ---------------------------------
    # Computed from the definition of the retraction (:meth:`.Retraction.element`,
    # :meth:`.Retraction.logarithm`), not from its closed forms or dτ⁻¹: Cayley by a
    # linear solve (any entries, meant for numbers: symbolic entries give large
    # expressions), the exponential numerically with mpmath's expm and a series of the
    # logarithm at the current ``mpmath.mp.dps`` (numeric entries only).
    def group_element(self, x) -> sp.Matrix:
        """τ(X), X = Σ x_a E_a: (I − X/2)⁻¹(I + X/2) or exp(X)."""
        return self.retraction.element(x)

    def algebra_coordinates(self, W) -> tuple:
        """Coordinates of τ⁻¹(W) in the basis: 2(W + I)⁻¹(W − I) or log(W) (principal)."""
        return tuple(self.coordinates(self.retraction.logarithm(W)))

    def identity(self, x):
        return (), (sp.S.Zero,) * self.fibre_dim

    def multiply(self, x, f, x2, f2, h):
        W = self.group_element([h * v for v in f]) * self.group_element([h * v for v in f2])
        return (), tuple(v / h for v in self.algebra_coordinates(W))

    def inverse(self, x, f, h):
        """τ(hξ)⁻¹ = τ(−hξ), a property of every retraction (paper §2.1, after its
        definition), so i(ξ) = −ξ; ``multiply`` computes products from τ and τ⁻¹
        themselves, and the routes check confirms m(g, i(g)) = ε numerically."""
        return (), tuple(-v for v in f)

    def basis_curve(self, x, a, eps, h):
        """σ_a(ε) = τ(εE_a), whose coordinate is ξ = τ⁻¹(τ(εE_a))/h = ε e_a / h."""
        return (), tuple(eps / h if i == a else sp.S.Zero for i in range(self.fibre_dim))

    # -- groupoid interface ---------------------------------------------------------------
    @property
    def source_dim(self) -> int:
        return 0

    @property
    def fibre_dim(self) -> int:
        return len(self.basis)

    def target(self, x, f, h):
        return ()

    def right(self, x, f, h):
        return self.dtau_inv([-h * v for v in f]) / h

    def left(self, x, f, h):
        return -self.dtau_inv([h * v for v in f]) / h

    def predictor(self, xs, fs):
        return tuple(2 * a - b for a, b in zip(fs[-1], fs[-2])) if len(fs) > 1 else tuple(fs[-1])

    def derivative(self, j: int) -> tuple[sp.Symbol, ...]:
        """The symbols of ξ⁽ʲ⁾: ``xi``, ``xidot``, then ``<name>_ddot``, ``<name>_dddot``,
        ``<name>_d4``, … (:func:`derivative_name`)."""
        j = _check_derivative(j, MAX_ORDER - 1)
        if j < 2:
            return (self.xi, self.xidot)[j]
        return tuple(sp.Symbol(derivative_name(n, j), real=True) for n in self.names)

    def continuous_symbols(self, order):
        return tuple(s for j in range(order) for s in self.derivative(j))

    def leading_symbols(self, order):
        return self.derivative(order - 1)

    def rules(self, order):
        if order >= 3:
            return (lie_central(order),)
        return (LIE_MIDPOINT,) if order == 2 else (LIE,)

    def step_scaled(self):
        return (True,) * self.fibre_dim

    def algebra_point(self, fs, h) -> dict:
        """ξ, ξ̇, …, ξ⁽ᵏ⁻¹⁾ of the rules ``lie``, ``lie_midpoint`` and ``lie_central<k>`` on
        k slots: the polynomial through the increments ξ_j, at the elements' middles
        (j + ½)h, at the window's centre kh/2 (k = 2: (ξ₀ + ξ₁)/2, (ξ₁ − ξ₀)/h)."""
        if len(fs) == 1:
            return dict(zip(self.xi, fs[0]))
        if len(fs) == 2:
            x0, x1 = sp.Matrix(fs[0]), sp.Matrix(fs[1])
            return dict(zip(self.xi, (x0 + x1) / 2)) | dict(zip(self.xidot, (x1 - x0) / h))
        values = window_derivatives([sp.Matrix(f) for f in fs], sp.S.Half, h)
        return {s: v for j, column in enumerate(values) for s, v in zip(self.derivative(j), column)}

    def matrix_groups(self):
        return (self,)

    def base_point(self, x) -> dict:
        """A Lie group has no base coordinates."""
        return {}

    def base_quadrature(self, xs, fs, h):
        """No base to average over: one point."""
        return [(sp.Integer(1), {})]

    def discrete_symbols(self, order):
        return tuple(sp.Symbol(f"{n}_{k}", real=True) for k in range(order) for n in self.names)

    def discrete_mapping(self, order, xs, fs):
        return dict(zip(self.discrete_symbols(order), [v for f in fs for v in f]))

    def check_initial(self, initial, order):
        g0, fibres = initial
        d = self.matrix_dim
        _shape(g0, (d, d), "initial configuration g_0")
        _shape(fibres, (2 * order - 1, self.fibre_dim), "initial increments ξ")

    def fingerprint(self) -> str:
        return (f"lie:{self.label}:{self.retraction.name}:{[E.tolist() for E in self.basis]}:"
                f"{self.names}")

    def fibre_sampling(self):
        return (None,) * self.fibre_dim          # ξ at the element's middle

    def equation_setting(self, order):
        return {1: "Euler–Poincaré", 2: "second-order Euler–Poincaré"}.get(
            order, f"order-{order} Euler–Poincaré")

    def preserved_structure(self, order):
        if order > 2:
            return super().preserved_structure(order)
        if order == 1:
            return "Lie–Poisson structure of 𝔤*, μ_k ↦ μ_{k+1}"
        return "Poisson structure of A*(P^αG) = 𝔤* × T*G, (ν, w_k, p) one element on"

    def group_context(self, offset: int = 0) -> GroupFactor:
        """One matrix-group factor for ``templates/group.c.j2``; ξ starts at f[offset]."""
        return GroupFactor(label=self.label, matrix_dim=self.matrix_dim, dim=self.fibre_dim,
                           offset=offset, invariants=self.invariants(),
                           basis=[[float(v) for v in E] for E in self.basis],
                           dual=[[float(v) for v in row] for row in self._dual.tolist()],
                           retraction=self.retraction.c_context())

    def coefficient_functions(self) -> list:
        return self.retraction.coefficient_functions()

    def c_context(self) -> CContext:
        return CContext(self.matrix_dim ** 2, (self.group_context(),))


def _hat3(v):
    return sp.Matrix([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def SO3(names="Omega1 Omega2 Omega3", retraction: str = "cayley") -> MatrixLieGroup:
    """SO(3) with the hat basis of so(3) ≅ R³ (ξ = body angular velocity Ω)."""
    return MatrixLieGroup([_hat3(sp.eye(3)[:, i]) for i in range(3)], names, "SO3", retraction)


def SE2(names="omega v1 v2", retraction: str = "cayley") -> MatrixLieGroup:
    """SE(2) as 3×3 homogeneous matrices: rotation rate ω and body velocity (v1, v2)."""
    E = [sp.Matrix([[0, -1, 0], [1, 0, 0], [0, 0, 0]]),
         sp.Matrix([[0, 0, 1], [0, 0, 0], [0, 0, 0]]),
         sp.Matrix([[0, 0, 0], [0, 0, 1], [0, 0, 0]])]
    return MatrixLieGroup(E, names, "SE2", retraction)


def SE3(names="Omega1 Omega2 Omega3 V1 V2 V3", retraction: str = "cayley") -> MatrixLieGroup:
    """SE(3) as 4×4 homogeneous matrices: body angular velocity Ω and linear velocity V."""
    def twist(w, v):
        M = sp.zeros(4)
        M[:3, :3], M[:3, 3] = _hat3(w), sp.Matrix(v)
        return M
    e = [list(sp.eye(3)[:, i]) for i in range(3)]
    return MatrixLieGroup([twist(ei, [0, 0, 0]) for ei in e] + [twist([0, 0, 0], ei) for ei in e],
                          names, "SE3", retraction)
