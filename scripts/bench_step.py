"""Steps per second of symvi's generated C stepping loop against a SymPy + SciPy baseline.

For the bundled models ``pendulum`` and ``double_pendulum`` this script, in one run:

* compiles the model afresh into a temporary directory (``compile_model(..., force=True)``)
  and reports the compile time;
* times ``module.integrate`` (the whole public call: the C loop with Newton's method at
  every step, plus the momenta and energy it returns) over 10⁶ steps, best of 3;
* times the baseline over 5,000 steps, best of 3: the same residual and Jacobian
  (``DerivedModel.kernel("step")``) turned into NumPy functions by ``sympy.lambdify`` and
  solved at every step by ``scipy.optimize.root(method="hybr", jac=True)`` with SciPy's
  default tolerances, from the same initial guess as symvi (2 q_k − q_{k−1});
* checks that both trajectories agree over the baseline's steps (max |Δq|).

Target: the C loop at ≥ 300× the baseline's steps/s. For comparison, a hand-written C loop
reaches ~450× (double pendulum) to ~1000× (pendulum), about 7 and 17 million steps/s on
the reference machine. The last line printed is ``ratio: <minimum over the models>``.
BLAS threads are pinned to 1.

Run from the repository root: ``python scripts/bench_step.py``.
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Callable  # noqa: E402

import numpy as np  # noqa: E402
import sympy as sp  # noqa: E402
from scipy.optimize import root  # noqa: E402

try:
    import symvi  # noqa: F401
except ImportError:
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from symvi.build import compile_model  # noqa: E402
from symvi.derivation.derive import derive  # noqa: E402
from symvi.discretisation.discretise import discretise  # noqa: E402
from symvi.declaration.model import Model  # noqa: E402
from symvi.models import get  # noqa: E402

MODELS = ("pendulum", "double_pendulum")
C_STEPS, C_REPEATS = 1_000_000, 3
BASELINE_STEPS, BASELINE_REPEATS = 5_000, 3
# hybr occasionally stops with "not making good progress" when its start is already
# within rounding error of the root; such a step is accepted if its residual is this small.
RESIDUAL_OK = 1e-10

Stepper = Callable[[np.ndarray, int, float], np.ndarray]


def best_time(run: Callable[[], object], repeats: int) -> float:
    """Shortest wall-clock time of ``repeats`` calls of ``run``."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return min(times)


def lambdified_step(model: Model):
    """The ``step`` kernel's residual and Jacobian as NumPy functions of (z, p, h).

    Returns (residual, jacobian, default parameters, fibre dimension n).
    """
    dm = derive(discretise(model))
    kernel = dm.kernel("step")
    outputs = dict(kernel.outputs)
    args = [*kernel.z, *dm.parameters, dm.step]
    residual = sp.lambdify(args, list(outputs["residual"]), modules="numpy")
    jacobian = sp.lambdify(args, outputs["jacobian"].tolist(), modules="numpy")
    return residual, jacobian, list(dm.defaults), outputs["residual"].shape[0]


def baseline_stepper(model: Model) -> Stepper:
    """Step map from lambdified residual/Jacobian, solved by ``scipy.optimize.root``."""
    residual, jacobian, params, n = lambdified_step(model)

    def integrate(initial: np.ndarray, n_steps: int, h: float) -> np.ndarray:
        q = np.empty((n_steps + 1, n))     # the given element is the first step
        q[:2] = initial
        for k in range(1, n_steps):
            known = [*q[k - 1], *q[k]]

            def fun(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
                values = [*known, *x, *params, h]
                return np.array(residual(*values)), np.array(jacobian(*values))

            sol = root(fun, 2 * q[k] - q[k - 1], jac=True, method="hybr")
            if not (sol.success or np.abs(sol.fun).max() <= RESIDUAL_OK):
                raise RuntimeError(f"baseline step {k} failed: {sol.message}")
            q[k + 1] = sol.x
        return q

    return integrate


def bench(name: str, build_dir: Path) -> float:
    """Print one model's measurements and return its speed-up ratio."""
    model = get(name)
    initial, h = np.asarray(model.example.initial, dtype=float), model.example.h
    start = time.perf_counter()
    module = compile_model(model, build_dir, force=True)
    compile_time = time.perf_counter() - start

    result = module.integrate(initial, C_STEPS, h)
    if not result.success:
        raise RuntimeError(f"{name}: {result.message}")
    c_rate = C_STEPS / best_time(lambda: module.integrate(initial, C_STEPS, h), C_REPEATS)

    stepper = baseline_stepper(model)
    q_baseline = stepper(initial, BASELINE_STEPS, h)
    base_rate = BASELINE_STEPS / best_time(
        lambda: stepper(initial, BASELINE_STEPS, h), BASELINE_REPEATS)
    diff = float(np.abs(result.q[: BASELINE_STEPS + 1] - q_baseline).max())

    return report(name, compile_time, c_rate, base_rate, result.newton_iterations,
                  {"q": diff})


def report(name: str, compile_time: float, c_rate: float, base_rate: float,
           iterations: np.ndarray, differences: dict[str, float]) -> float:
    """Print one model's timings and trajectory differences; return the speed ratio."""
    ratio = c_rate / base_rate
    print(f"{name}:")
    print(f"  compile (force=True)  {compile_time:8.2f} s")
    print(f"  C loop                {c_rate:12,.0f} steps/s  ({C_STEPS:,} steps, "
          f"mean {iterations.mean():.2f} Newton iterations)")
    print(f"  baseline              {base_rate:12,.0f} steps/s  ({BASELINE_STEPS:,} steps)")
    print(f"  ratio                 {ratio:12.1f}")
    for label, diff in differences.items():
        print(f"  max |{label}_C - {label}_base|{' ' * (4 - len(label))}{diff:12.2e}  "
              f"(over {BASELINE_STEPS:,} steps)")
    return ratio


def main() -> None:
    print("baseline: sympy.lambdify + scipy.optimize.root(method='hybr', jac=True), "
          "default SciPy tolerances; best of "
          f"{BASELINE_REPEATS} (baseline) and {C_REPEATS} (C loop); BLAS threads = 1")
    with tempfile.TemporaryDirectory(prefix="symvi-bench-") as build_dir:
        ratios = [bench(name, Path(build_dir)) for name in MODELS]
    print(f"ratio: {min(ratios):.1f}")


if __name__ == "__main__":
    main()
