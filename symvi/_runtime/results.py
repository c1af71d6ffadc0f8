"""Result objects of the step map and the whole-trajectory solve (cf. ``solve_ivp``)."""
from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from .errors import NewtonError


class Status(enum.IntEnum):
    """Outcome of a solve; the values match the C return codes."""

    SUCCESS = 0
    MAX_ITERATIONS = 1
    SINGULAR_JACOBIAN = 2
    NON_FINITE = 3
    STALLED = 4
    OUTSIDE_CHART = 5


class _Checkable:
    def raise_for_status(self):
        """Raise :class:`NewtonError` unless the solve succeeded; return self otherwise."""
        if not self.success:
            raise NewtonError(self)
        return self


@dataclass(frozen=True)
class StepResult(_Checkable):
    """Discrete path computed by the step map.

    Attributes
    ----------
    t : (E+1,) times of the base points (node k at k·h).
    x : (E+1, m) base points α(E_0), β(E_0), …, β(E_{E−1}); for the pair groupoid the
        nodes q_k (also available as ``q``).
    f : (E, n) fibre parts of the elements E_0, …, E_{E−1} (Lie groups: ξ_k).
    g : (E+1, d, d) reconstructed configurations g_{k+1} = g_k τ(hξ_k) on a matrix Lie
        group, else None.
    momenta : discrete Legendre transforms at each state: (E+1, n) for first order
        (p_0 from F⁻L_d, p_k for k ≥ 1 from F⁺L_d), (E, 2, n) for second order (state k
        is the node pair (ν_k, ν_{k+1}); states 0, 1 from F⁻L_d, the rest from F⁺L_d).
    energy : (E,) discrete energy −∂L_d/∂h per element (first-order models), else None.
    noether : (E−2r+2, s) conserved quantities F_Z of the model's declared symmetries at
        nodes r−1, r, … (paper §4.4), one column per symmetry, else None.
    newton_iterations : (steps,) Newton iterations of each computed step.
    status, success, message : outcome; on failure the arrays hold the path up to the
        failing step. Success means every step converged and every array is finite.

    With ``keep_every=k`` each array holds only the entries of the nodes 0, k, 2k, …
    (see :func:`stepping.integrate`).
    """

    t: np.ndarray
    x: np.ndarray
    f: np.ndarray
    g: np.ndarray | tuple | None
    newton_iterations: np.ndarray
    status: Status
    message: str
    momenta: np.ndarray | None = None
    energy: np.ndarray | None = None
    noether: np.ndarray | None = None

    @property
    def success(self) -> bool:
        return self.status == Status.SUCCESS

    @property
    def q(self) -> np.ndarray:
        """Alias of ``x`` (the nodes of a pair-groupoid path)."""
        return self.x


@dataclass(frozen=True)
class BVPResult(_Checkable):
    """Whole-trajectory solution with fixed end nodes.

    Attributes
    ----------
    t : (N+1,) times of the nodes.
    x : (N+1, m) base points of the nodes (pair groupoid: the nodes q; also ``q``), None
        on a Lie group.
    g : (N+1, d, d) configurations of the matrix-group factor (a tuple of such arrays with
        several factors), boundary ones included, else None.
    f : (N, n) fibres of the elements (Lie groups: ξ_k = τ⁻¹(g_k⁻¹g_{k+1})/h; pair
        factors: the next node).
    multipliers : (N−r+1, s) multipliers λ^k of the windows (constrained models), else None.
    controls : (N−r+1, c) controls u_k at each window's quadrature point (optimal-control
        problems: u = EL(L)_a of the discrete path), else None.
    cost : Σ_k L_d over the windows — the discrete cost J_d of an optimal-control problem,
        the action sum otherwise.
    iterations : Newton iterations taken.
    residual_norms : max-norm of the residual before each iteration and at the end.
    step_norms : max-norm of each Newton update actually taken (after line search).
    status, success, message : outcome; a failed solve keeps the last iterate.
    """

    t: np.ndarray
    iterations: int
    residual_norms: np.ndarray
    step_norms: np.ndarray
    status: Status
    message: str
    x: np.ndarray | None = None
    g: np.ndarray | tuple | None = None
    f: np.ndarray | None = None
    multipliers: np.ndarray | None = None
    controls: np.ndarray | None = None
    cost: float | None = None
    kind: str = ""

    @property
    def success(self) -> bool:
        return self.status == Status.SUCCESS

    @property
    def q(self) -> np.ndarray | None:
        """Alias of ``x`` (the nodes of a pair-groupoid path)."""
        return self.x
