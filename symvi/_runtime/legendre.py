"""The first element of a run started from a state (issue 22): the discrete Legendre
transform.

A first-order variational integrator advances elements, so its initial data are the first
two nodes q₀, q₁ (a pair groupoid) or a configuration and the first increment (a group).
From a state (q₀, v₀) the first element is the one whose discrete momentum matches the
continuous one (Marsden & West 2001, §1.5):

    F⁻L_d(x₀, f₀) = −D₁L_d(q₀, q₁) = ∂L/∂v (x₀, v₀),

solved for f₀ by Newton's method on the compiled ``momentum_minus`` kernel and its
Jacobian, from the explicit guess f₀ = q₀ + h v₀ (nodes) or f₀ = ξ₀ (increments). The path
from there is the discrete flow of the momentum-matched initial condition, so it
approximates the solution from (q₀, v₀) at the method's order whatever h is, which a
fixed pair of nodes does not (it fixes the velocity at h/2 to (q₁ − q₀)/h).
"""
from __future__ import annotations

import numpy as np

from . import arguments
from .geometry import check_base_points

#: Newton iterations of the transform, and the relative size of a converged correction.
MAXITER, XTOL = 30, 1e-14


def first_element(model, state, h: float, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x₀, f₀): the base point and the first element's fibre of the run from ``state`` (a
    :class:`.results.State`) at step ``h`` and parameter vector ``p``."""
    if model.order != 1 or "legendre" not in model.info["kernels"]:
        raise ValueError(f"model {model.name!r}: a State starts first-order models only "
                         f"(this one is of order {model.order}); give its first "
                         f"{model.stencil_elements - 1} elements instead")
    if not (model.info["node_pairs"] or model.step_scaled.all()):
        raise ValueError(f"model {model.name!r}: a State needs every fibre coordinate to be "
                         f"a node (pair groupoid) or an increment (groups); give the first "
                         f"element instead")
    v = arguments.finite_array(state.v, (model.n,), "the state's velocity v")
    x = arguments.finite_array(state.x if model.m else [], (model.m,), "the state's position x")
    if model.m:
        check_base_points(model, x[None, :], "the state's position x")
    momentum = model.kernel_outputs("legendre", np.concatenate([x, v]), p, h)[0]
    f = x + h * v if model.info["node_pairs"] else v.copy()
    for _ in range(MAXITER):
        value, jacobian = model.kernel_outputs("momentum_minus", np.concatenate([x, f]), p, h)
        J = jacobian.reshape(model.n, model.m + model.n)[:, model.m:]
        try:
            delta = np.linalg.solve(J, momentum - value)
        except np.linalg.LinAlgError:
            raise ValueError(f"the discrete Legendre transform at this state is singular "
                             f"(∂F⁻L_d/∂f₀ is not invertible at h = {h:g})") from None
        f = f + delta
        if not np.isfinite(f).all():
            break
        if np.abs(delta).max() <= XTOL * (1.0 + np.abs(f).max()):
            return x, f
    raise ValueError(f"the discrete Legendre transform from this state did not converge in "
                     f"{MAXITER} Newton iterations at h = {h:g} (the velocity too large for "
                     f"the step?); take a smaller h or give the first element")

