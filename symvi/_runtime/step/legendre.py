"""The first element of a run started from a state (issue 22): the discrete Legendre
transform.

A first-order variational integrator advances elements, so its initial data are the first
two nodes q₀, q₁ (a pair groupoid) or a configuration and the first increment (a group).
From a state (q₀, v₀) the first element is the one whose discrete momentum matches the
continuous one (Marsden & West 2001, §1.5):

    F⁻L_d(x₀, f₀) = −D₁L_d(q₀, q₁) = ∂L/∂v (x₀, v₀),

solved for f₀ by Newton's method on the compiled ``momentum_minus`` kernel and its
Jacobian, from the explicit guess f₀ = q₀ + h v₀ (nodes) or f₀ = ξ₀ (increments), per
fibre coordinate as the package records (``INFO.fibre_nodes``). The path
from there is the discrete flow of the momentum-matched initial condition, so it
approximates the solution from (q₀, v₀) at the method's order whatever h is, which a
fixed pair of nodes does not (it fixes the velocity at h/2 to (q₁ − q₀)/h).
"""
from __future__ import annotations

import numpy as np

from ..core import arguments
from ..core.geometry import check_base_points
from ..core.model_info import Kernel
from ..core.paths import initial_layout

#: Newton iterations of the transform, and the relative size of a converged correction.
MAXITER, XTOL = 30, 1e-14


class TransformError(ValueError):
    """The transform failed for the ``index``-th state of a batch."""

    def __init__(self, message: str, index: int):
        super().__init__(message)
        self.index = index


def state_arrays(model, state) -> tuple[np.ndarray, np.ndarray]:
    """The position x and velocity v of ``state``, checked (x on its manifold)."""
    if model.order != 1 or not model.info.has_kernel(Kernel.LEGENDRE):
        what = initial_layout(model).describe(model.stencil_elements, model.n)
        raise ValueError(f"model {model.name!r}: a State starts first-order models only "
                         f"(this one is of order {model.order}); give {what} instead")
    if not ((_fibre_nodes(model) >= 0) | model.step_scaled).all():
        raise ValueError(f"model {model.name!r}: a State needs every fibre coordinate to be "
                         f"a node (pair groupoid) or an increment (groups); give the first "
                         f"element instead")
    v = arguments.finite_array(state.v, (model.n,), "the state's velocity v")
    x = arguments.finite_array(state.x if model.m else [], (model.m,), "the state's position x")
    if model.m:
        check_base_points(model, x[None, :], "the state's position x")
    return x, v


def first_fibres(model, X: np.ndarray, V: np.ndarray, H: np.ndarray,
                 P: np.ndarray) -> np.ndarray:
    """The first fibres f₀ of c states at once (positions X (c, m), velocities V (c, n),
    steps H (c,), parameter rows P (c, np)): Newton on all of them together, each state's
    iterates the same as alone (it stops when its own correction is small);
    :class:`TransformError` names the first state that fails."""
    c, n = len(X), model.n
    P = np.ascontiguousarray(P)
    momentum = _points(model, Kernel.LEGENDRE, np.hstack([X, V]), P, H)[0]
    F = guess(model, X, V, H)
    active = np.arange(c)
    for _ in range(MAXITER):
        value, jacobian = _points(model, Kernel.MOMENTUM_MINUS, np.hstack([X[active], F[active]]),
                                  P[active], H[active])
        J = jacobian.reshape(len(active), n, n)
        delta = _solve(J, momentum[active] - value, active, H)
        F[active] = F[active] + delta
        bad = ~np.isfinite(F[active]).all(axis=1)
        if bad.any():
            break
        small = np.abs(delta).max(axis=1) <= XTOL * (1.0 + np.abs(F[active]).max(axis=1))
        active = active[~small]
        if not active.size:
            return F
    j = int(active[np.flatnonzero(bad)[0]] if bad.any() else active[0])
    raise TransformError(f"the discrete Legendre transform from this state did not converge "
                         f"in {MAXITER} Newton iterations at h = {H[j]:g} (the velocity too "
                         f"large for the step?); take a smaller h or give the first element", j)


def _fibre_nodes(model) -> np.ndarray:
    """``INFO.fibre_nodes``: per fibre coordinate the base coordinate it copies at the
    target node, or −1."""
    return np.asarray(model.info.fibre_nodes, dtype=int)


def guess(model, X: np.ndarray, V: np.ndarray, H: np.ndarray) -> np.ndarray:
    """The explicit first fibres of the states (X, V) at steps H: f_a = x_j + h v_a where
    the fibre copies base coordinate j of the target node (the next node q₀ + h v₀),
    f_a = v_a where it is an increment (ξ₀ = v₀)."""
    nodes = _fibre_nodes(model)
    copies = nodes >= 0
    F = np.array(V, dtype=float, copy=True)
    F[:, copies] = X[:, nodes[copies]] + H[:, None] * V[:, copies]
    return F


def _solve(J: np.ndarray, rhs: np.ndarray, active: np.ndarray, H: np.ndarray) -> np.ndarray:
    """The Newton corrections of the active states; a singular J names its state."""
    try:
        return np.linalg.solve(J, rhs[:, :, None])[:, :, 0]
    except np.linalg.LinAlgError:
        for i, matrix in enumerate(J):
            try:
                np.linalg.solve(matrix, rhs[i])
            except np.linalg.LinAlgError:
                j = int(active[i])
                raise TransformError(f"the discrete Legendre transform at this state is "
                                     f"singular (∂F⁻L_d/∂f₀ is not invertible at h = "
                                     f"{H[j]:g})", j) from None
        raise


def _points(model, kernel: Kernel, Z: np.ndarray, P: np.ndarray, H: np.ndarray) -> list:
    """The outputs of ``kernel`` at the rows of Z, each with its parameters and step."""
    Z, H = np.ascontiguousarray(Z), np.ascontiguousarray(H, dtype=float)
    outs = [np.zeros((len(Z), size)) for size in model.info.kernel(kernel).outputs]
    getattr(model.lib, f"symvi_{kernel.value}_points")(len(Z), model.ptr(Z), model.ptr(P), P.shape[1],
                                                 model.ptr(H), *[model.ptr(o) for o in outs])
    return outs
