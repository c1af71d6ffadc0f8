"""Steps per second of symvi's generated C stepping loop on a Lie group against a baseline.

For the bundled model ``rigid_body`` (free rigid body on SO(3), first-order discrete
Euler–Poincaré equations with the Cayley retraction) this script, in one run:

* compiles the model afresh into a temporary directory (``compile_model(..., force=True)``)
  and reports the compile time;
* times ``module.integrate`` (the whole public call: the C loop with Newton's method at
  every step and the reconstruction R_{k+1} = R_k·cay(hξ_k), plus the momenta and energy it
  returns) over 10⁶ steps, best of 3;
* times the baseline over 5,000 steps, best of 3: the same residual and Jacobian
  (``DerivedModel.kernel("step")``) turned into NumPy functions by ``sympy.lambdify`` and
  solved at every step by ``scipy.optimize.root(method="hybr", jac=True)`` with SciPy's
  default tolerances, from the same initial guess as symvi (ξ_{k−1}, the last known
  increment), followed by the same reconstruction R_{k+1} = R_k·cay(hξ_k) in NumPy;
* checks that both trajectories agree over the baseline's steps (max |Δξ| and max |ΔR|).

Target: the C loop at ≥ 300× the baseline's steps/s (a hand-written C loop reaches several
hundred times this baseline on the reference machine). The last line printed is
``ratio: <value>``. BLAS threads are pinned to 1 (by importing ``bench_step``, whose timing
helper and tolerances this script shares).

Run from the repository root: ``python scripts/bench_group.py``.
"""
from __future__ import annotations

import bench_step  # noqa: F401  (first: pins BLAS threads and makes symvi importable)

import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Callable  # noqa: E402

import numpy as np  # noqa: E402
from scipy.optimize import root  # noqa: E402

from bench_step import BASELINE_REPEATS, BASELINE_STEPS, C_REPEATS, C_STEPS  # noqa: E402
from bench_step import RESIDUAL_OK, best_time, lambdified_step, report  # noqa: E402
from symvi.build import compile_model  # noqa: E402
from symvi.declaration.model import Model  # noqa: E402
from symvi.models import get  # noqa: E402

MODEL = "rigid_body"

GroupStepper = Callable[[np.ndarray, np.ndarray, int, float], tuple[np.ndarray, np.ndarray]]


def cay(v: np.ndarray) -> np.ndarray:
    """Cayley map (I − X/2)⁻¹(I + X/2) of X = hat(v) ∈ so(3)."""
    X = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    eye = np.eye(3)
    return np.linalg.solve(eye - X / 2, eye + X / 2)


def baseline_stepper(model: Model) -> GroupStepper:
    """Step map from lambdified residual/Jacobian, solved by ``scipy.optimize.root``,
    with the reconstruction R_{k+1} = R_k·cay(hξ_k) in NumPy."""
    residual, jacobian, params, n = lambdified_step(model)

    def integrate(R0: np.ndarray, xi0: np.ndarray, n_steps: int,
                  h: float) -> tuple[np.ndarray, np.ndarray]:
        xi = np.empty((n_steps, n))        # the given element is the first step
        R = np.empty((n_steps + 1, 3, 3))
        xi[0], R[0] = xi0, R0
        R[1] = R[0] @ cay(h * xi[0])
        for k in range(1, n_steps):
            known = list(xi[k - 1])

            def fun(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
                values = [*known, *x, *params, h]
                return np.array(residual(*values)), np.array(jacobian(*values))

            sol = root(fun, xi[k - 1], jac=True, method="hybr")
            if not (sol.success or np.abs(sol.fun).max() <= RESIDUAL_OK):
                raise RuntimeError(f"baseline step {k} failed: {sol.message}")
            xi[k] = sol.x
            R[k + 1] = R[k] @ cay(h * xi[k])
        return xi, R

    return integrate


def bench(name: str, build_dir: Path) -> float:
    """Print the model's measurements and return its speed-up ratio."""
    model = get(name)
    R0, xi0 = model.example.initial
    R0, xi0, h = np.asarray(R0, dtype=float), np.asarray(xi0, dtype=float), model.example.h
    start = time.perf_counter()
    module = compile_model(model, build_dir, force=True)
    compile_time = time.perf_counter() - start

    result = module.integrate((R0, xi0), C_STEPS, h)
    if not result.success:
        raise RuntimeError(f"{name}: {result.message}")
    c_rate = C_STEPS / best_time(lambda: module.integrate((R0, xi0), C_STEPS, h), C_REPEATS)

    stepper = baseline_stepper(model)
    xi_baseline, R_baseline = stepper(R0, xi0[0], BASELINE_STEPS, h)
    base_rate = BASELINE_STEPS / best_time(
        lambda: stepper(R0, xi0[0], BASELINE_STEPS, h), BASELINE_REPEATS)
    diff_xi = float(np.abs(result.f[: BASELINE_STEPS] - xi_baseline).max())
    diff_R = float(np.abs(result.g[: BASELINE_STEPS + 1] - R_baseline).max())

    return report(name, compile_time, c_rate, base_rate, result.newton_iterations,
                  {"ξ": diff_xi, "R": diff_R})


def main() -> None:
    print("baseline: sympy.lambdify + scipy.optimize.root(method='hybr', jac=True), "
          "default SciPy tolerances, NumPy reconstruction R_k·cay(hξ_k); best of "
          f"{BASELINE_REPEATS} (baseline) and {C_REPEATS} (C loop); BLAS threads = 1")
    with tempfile.TemporaryDirectory(prefix="symvi-bench-") as build_dir:
        ratio = bench(MODEL, Path(build_dir))
    print(f"ratio: {ratio:.1f}")


if __name__ == "__main__":
    main()
