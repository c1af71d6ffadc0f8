"""The step map: one call into the C loop integrates every step (Newton per step in C)."""
from __future__ import annotations

import numpy as np

from . import arguments
from .results import Status, StepResult

_FAILURE = {
    Status.MAX_ITERATIONS: "Newton's method did not converge in {maxiter} iterations",
    Status.SINGULAR_JACOBIAN: "the step Jacobian is singular",
    Status.NON_FINITE: "the residual or the update became non-finite (NaN or inf)",
    Status.OUTSIDE_CHART: ("the increment hξ left the retraction's chart (Cayley: I − hξ/2 "
                           "singular; exp: θ(hξ) ≥ π)"),
}


def integrate(model, initial, n_steps: int, h: float, params=None, *, maxiter: int = 50,
              xtol: float = 1e-12, ftol: float = 0.0,
              raise_on_failure: bool = False) -> StepResult:
    """Integrate ``n_steps`` steps of the discrete Euler–Lagrange equations.

    Parameters
    ----------
    model : the :class:`CompiledModel`.
    initial : the first K−1 elements. Pair groupoid: the first 2r nodes q_0, …, q_{2r−1}
        as an array (2r, n) (r the order). Matrix Lie group: ``(g_0, xi)`` with g_0 the
        initial configuration (d, d) and xi the first 2r−1 increments ξ_k (2r−1, n).
        Action groupoids and products: ``(x_0, f)`` or ``(x_0, g_0, f)`` (see
        :meth:`CompiledModel.initial_state`).
    n_steps : number of new elements to compute.
    h : time step (> 0). params : parameter overrides (mapping name → value).
    maxiter, xtol, ftol : Newton stops when ‖Δf‖∞ ≤ xtol·(1 + ‖f‖∞) or ‖R‖∞ ≤ ftol.
    raise_on_failure : raise :class:`NewtonError` instead of returning a failed result.
    """
    n_steps = arguments.count(n_steps, "n_steps")
    h = arguments.step_size(h)
    maxiter = arguments.count(maxiter, "maxiter", 1)
    xtol, ftol = arguments.tolerance(xtol, "xtol"), arguments.tolerance(ftol, "ftol")
    (z0, g0), p = model.initial_state(initial), model.params(params)
    K, m, n = model.stencil_elements, model.m, model.n
    elements = K - 1 + n_steps
    x = np.zeros((elements + 1, m))
    f = np.zeros((elements, n))
    G = model.info["configuration_dim"]
    g = np.zeros((elements + 1, G) if G else 1)
    iters = np.zeros(max(n_steps, 1), dtype=np.intc)
    done, rnorm = model.ffi.new("long *"), model.ffi.new("double *")
    code = model.lib.symvi_integrate(model.ptr(z0), model.ptr(g0), n_steps, model.ptr(p), h,
                                     maxiter, xtol, ftol, model.ptr(x), model.ptr(f),
                                     model.ptr(g), model.ffi.from_buffer("int[]", iters),
                                     done, rnorm)
    status, steps = Status(code), int(done[0])
    if status == Status.SUCCESS:
        message = f"integrated {n_steps} steps"
    else:
        reason = _FAILURE[status].format(maxiter=maxiter)
        message = (f"step {steps} (to t = {(K + steps) * h:.6g}) failed: {reason}; "
                   f"residual norm {rnorm[0]:.3e}")
        x, f, g = x[: K + steps], f[: K - 1 + steps], g[: K + steps]

    def along(quantity: str):
        if quantity == "momenta":
            return model.momenta(x, f, h, params)
        if quantity == "noether":
            return model.noether(x, f, h, params)
        if model.info["has_energy"]:
            return model.along("energy", x, f, h, params)[:, 0]
        return None

    result = StepResult(t=h * np.arange(x.shape[0]), x=x, f=f,
                        g=model.configurations(g.reshape(x.shape[0], -1)) if G else None,
                        newton_iterations=iters[:steps].copy(), status=status, message=message,
                        along=along)
    return result.raise_for_status() if raise_on_failure else result
