"""Optimal control of nonholonomic mechanical systems (paper, "Conclusions and future
research"; issue 25, part 1).

A nonholonomic system on Q = Rᵐ moves with velocities in a distribution D ⊂ TQ spanned by
n vector fields ρ_α(q): q̇ = ρ(q) y, y ∈ Rⁿ the quasi-velocities. Its controlled
Lagrange–d'Alembert equations, for a Lagrangian L(q, q̇), are

    E_α(q, y, ẏ) = ρ^i_α(q) (d/dt ∂L/∂q̇^i − ∂L/∂q^i) = u_α    (α actuated),
    E_A(q, y, ẏ) = 0                                          (A unactuated),

with q̇ = ρ(q) y and q̈ = d/dt(ρ(q) y) inside d/dt ∂L/∂q̇. Minimising ∫ C(q, y, u) dt is
the second-order problem on D⁽²⁾ ⊂ TD with L̃(q, y, ẏ) = C(q, y, E_a) and the constraints
q̇ − ρ(q) y = 0 (the extended Lagrangian L̃ + λ_i(q̇^i − ρ^i_α y^α) of the paper) and
E_A = 0. As the paper proposes, D⁽²⁾ is discretised inside D × D, the pair groupoid of D
with nodes (q_k, y_k): the midpoint rule gives L̃_d = h L̃(q̄, ȳ, (y₁ − y₀)/h) and the
discrete space D_d⁽²⁾ of
    (q₁ − q₀)/h = ρ((q₀ + q₁)/2) (y₀ + y₁)/2,
one set of kinematic multipliers per element. :func:`nonholonomic_control` returns that
first-order constrained :class:`~symvi.declaration.model.Model`; the whole-trajectory
solve fixes (q, y) at both ends.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import sympy as sp

from ..errors import ModelError
from ..groupoids.pair import PairGroupoid
from .control import _actuated, _control_symbols
from .model import Example, Model, _sympify_parameters
from .rank import generic_rank
from .validation import scalar


@dataclass(frozen=True, eq=False)
class Distribution:
    """A distribution D ⊂ TQ on the coordinates of a pair groupoid, spanned by the columns
    ρ_α(q) of ``anchor`` (m × n), with quasi-velocities ``y`` along them.

    ``groupoid`` is the pair groupoid D × D of D itself, whose coordinates are (q, y):
    its ``qdot`` holds q̇ and ẏ, the symbols of :func:`nonholonomic_control`'s
    Lagrangian L̃(q, y, ẏ).
    """

    base: PairGroupoid
    anchor: sp.Matrix
    y: tuple[sp.Symbol, ...]
    groupoid: PairGroupoid

    @property
    def q(self) -> tuple[sp.Symbol, ...]:
        return self.base.q

    @property
    def ydot(self) -> tuple[sp.Symbol, ...]:
        """ẏ: the quasi-velocities' rates (``<name>_dot``)."""
        return self.groupoid.qdot[len(self.q):]


def distribution(base: PairGroupoid, fields: Any, velocities: str | Sequence[str],
                 parameters: Sequence[sp.Symbol] = ()) -> Distribution:
    """The distribution spanned by ``fields`` on the coordinates of ``base``.

    ``fields``: the n vector fields ρ_α, each m expressions in ``base.q`` and the
    parameters (or an m × n matrix whose columns they are); ``velocities``: the names of
    the quasi-velocities y_α along them. The fields must be linearly independent at a
    generic point.
    """
    if not isinstance(base, PairGroupoid):
        raise ModelError("a nonholonomic system lives on a PairGroupoid's coordinates, got "
                         f"{type(base).__name__}")
    m = base.source_dim
    anchor = _anchor(fields, m)
    names = velocities.replace(",", " ").split() if isinstance(velocities, str) \
        else [str(v) for v in velocities]
    if len(names) != anchor.cols:
        raise ModelError(f"{anchor.cols} vector fields need {anchor.cols} quasi-velocity "
                         f"names, got {names}")
    clash = set(names) & {str(s) for s in base.continuous_symbols(base.max_order)}
    if clash:
        raise ModelError(f"quasi-velocity names {sorted(clash)} clash with the coordinates' "
                         f"symbols")
    allowed = set(base.q) | set(parameters)
    unknown = anchor.free_symbols - allowed
    if unknown:
        raise ModelError(f"the vector fields use {sorted(map(str, unknown))}, which are "
                         f"neither coordinates {[str(s) for s in base.q]} nor parameters")
    rank = generic_rank(anchor, list(base.q), {p: 1.0 for p in parameters})
    if rank is not None and rank < anchor.cols:
        raise ModelError(f"the {anchor.cols} vector fields spanning the distribution are "
                         f"linearly dependent (rank {rank} at generic points)")
    groupoid = PairGroupoid(list(base.names) + names)
    y = groupoid.q[m:]
    return Distribution(base, anchor, y, groupoid)


def _anchor(fields: Any, m: int) -> sp.Matrix:
    """The m × n matrix of the fields (columns)."""
    if isinstance(fields, sp.MatrixBase):
        anchor = sp.Matrix(fields)
    else:
        columns = [sp.Matrix([sp.sympify(c) for c in field]) for field in fields]
        if not columns or any(c.shape != (m, 1) for c in columns):
            raise ModelError(f"each vector field needs {m} components (one per coordinate)")
        anchor = sp.Matrix.hstack(*columns)
    if anchor.rows != m or not 1 <= anchor.cols <= m:
        raise ModelError(f"the distribution's anchor must be {m} × n with 1 ≤ n ≤ {m}, got "
                         f"{anchor.shape}")
    return anchor


def lagrange_dalembert(D: Distribution, lagrangian: sp.Expr) -> sp.Matrix:
    """E_α(q, y, ẏ) = ρ^i_α (d/dt ∂L/∂q̇^i − ∂L/∂q^i) along q̇ = ρ(q) y (n rows): the
    left-hand sides of the controlled Lagrange–d'Alembert equations in quasi-velocities."""
    base, rho = D.base, D.anchor
    qdot = rho * sp.Matrix(D.y)
    # q̈ = (∂(ρ y)/∂q) q̇ + ρ ẏ
    qddot = qdot.jacobian(base.q) * qdot + rho * sp.Matrix(D.ydot)
    on_d = dict(zip(base.qdot, qdot))
    p = sp.Matrix([sp.diff(lagrangian, v) for v in base.qdot])
    dp = (p.jacobian(base.q) * qdot + p.jacobian(base.qdot) * qddot).xreplace(on_d)
    force = sp.Matrix([sp.diff(lagrangian, s) for s in base.q]).xreplace(on_d)
    return (rho.T * (dp - force)).applyfunc(sp.expand)


def nonholonomic_control(name: str, D: Distribution, lagrangian: Any, cost: Any,
                         controls: Sequence[Any] | str,
                         actuated: Sequence[int] | None = None,
                         parameters: Mapping[Any, float] | None = None,
                         example: Example | None = None, description: str = "") -> Model:
    """The optimal-control problem min ∫ C(q, y, u) dt of the nonholonomic system on
    ``D`` with Lagrangian L(q, q̇) (in ``D.base``'s symbols), as a first-order constrained
    :class:`Model` on D × D (module docstring).

    ``cost``: C in ``D.q``, ``D.y`` and the control symbols; ``controls``: one symbol per
    actuated direction, u_a = E_a; ``actuated``: the indices a of the actuated fields
    (default: all), the others giving the constraints E_A = 0. The model's constraints
    are the kinematic q̇ − ρ(q) y = 0, one per coordinate, then E_A; its controls are u_a
    at each element's midpoint. ``solve_bvp`` takes the first and last
    nodes (q, y) as arrays of shape (1, m + n).
    """
    params = _sympify_parameters(dict(parameters or {}))
    symbols = tuple(s for s, _ in params)
    L = scalar(lagrangian, "Lagrangian")
    allowed = set(D.base.continuous_symbols(1)) | set(symbols)
    if not L.free_symbols <= allowed:
        raise ModelError(f"the Lagrangian of {name!r} uses "
                         f"{sorted(map(str, L.free_symbols - allowed))}: write it in "
                         f"q, q̇ ({', '.join(map(str, D.base.continuous_symbols(1)))}) and "
                         f"the parameters")
    n = len(D.y)
    actuated = _actuated(actuated, n)
    u = _control_symbols(controls, len(actuated))
    E = lagrange_dalembert(D, L)
    C = scalar(cost, "cost")
    # a control is known by its name, whatever assumptions the cost's symbol carries
    by_name = {c.name: c for c in u}
    C = C.xreplace({s: by_name[s.name] for s in C.free_symbols
                    if isinstance(s, sp.Symbol) and s.name in by_name})
    known = set(D.q) | set(D.y) | set(u) | set(symbols)
    if not C.free_symbols <= known:
        raise ModelError(f"the cost of {name!r} uses {sorted(map(str, C.free_symbols - known))}"
                         f": write it in q, y and the controls {[str(c) for c in u]}")
    cost_on_d2 = C.xreplace({c: E[a] for c, a in zip(u, actuated)})
    qdot = D.groupoid.qdot[:len(D.q)]
    kinematic = list(sp.Matrix(qdot) - D.anchor * sp.Matrix(D.y))
    unactuated = [E[A] for A in range(n) if A not in actuated]
    return Model(name=name, groupoid=D.groupoid, lagrangian=cost_on_d2,
                 discretisation="midpoint", parameters=dict(params),
                 constraints=kinematic + unactuated,
                 controls=[E[a] for a in actuated], example=example,
                 description=description)

