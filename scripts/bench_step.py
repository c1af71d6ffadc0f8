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

and against a hand-written C loop of the same scheme (``scripts/hand_step.c``: the closed-
form 1×1 and 2×2 Newton a careful person would write, compiled in the same run through
cffi with -O2, the same stopping rule |Δx| ≤ xtol(1 + |x|)), over the same 10⁶ steps,
checking that both paths agree over the first 1,000 steps to 1e-12 relative, and printing
how far each is from a 25-digit solution of the same discrete equations (the double
pendulum is chaotic: a one-ulp change of its start moves it by 6e-14 after 1,000 steps,
so two loops that round differently can drift apart by more than either is from the exact
path).

Targets: the C loop at ≥ 300× the SymPy + SciPy baseline, and at ≥ 1.0× the hand-written
loop (issue 23), both computing the path alone (``integrate(..., quantities=False)``; the
default call also returns the momenta and energies, printed too). The last line printed
is ``ratio: <minimum over the models of symvi / hand C>``. BLAS threads are pinned to 1.

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

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from midpoint_reference import reference_path  # noqa: E402
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


HAND_AGREEMENT_STEPS = 1_000


def hand_loops(build_dir: Path):
    """The hand-written loops of ``scripts/hand_step.c``, compiled through cffi (-O2)."""
    import importlib.util
    from cffi import FFI
    ffi = FFI()
    ffi.cdef("""
        long hand_pendulum(const double *start, long n_steps, double h, double m, double l,
                           double g, double xtol, int maxiter, double *q);
        long hand_double_pendulum(const double *start, long n_steps, double h, double m1,
                                  double m2, double l1, double l2, double g, double xtol,
                                  int maxiter, double *q);""")
    source = (Path(__file__).resolve().parent / "hand_step.c").read_text()
    ffi.set_source("_hand_step", source, extra_compile_args=["-O2"], libraries=["m"])
    library = ffi.compile(tmpdir=str(build_dir), verbose=False)
    spec = importlib.util.spec_from_file_location("_hand_step", library)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return ffi, module.lib


def hand_run(hand, name: str, model: Model, initial: np.ndarray, n_steps: int, h: float,
             xtol: float = 1e-12) -> tuple[np.ndarray, float]:
    """The hand loop's path (n_steps + 1 nodes) and mean Newton iterations per step."""
    ffi, lib = hand
    values = {str(s): v for s, v in model.parameters}
    q = np.empty((n_steps + 1, initial.shape[1]))
    start = np.ascontiguousarray(initial, dtype=float)
    pointer = ffi.cast("double *", start.ctypes.data)
    out = ffi.cast("double *", q.ctypes.data)
    if name == "pendulum":
        total = lib.hand_pendulum(pointer, n_steps, h, values["m"], values["l"], values["g"],
                                  xtol, 50, out)
    else:
        total = lib.hand_double_pendulum(pointer, n_steps, h, values["m1"], values["m2"],
                                         values["l1"], values["l2"], values["g"], xtol, 50,
                                         out)
    if total < 0:
        raise RuntimeError(f"{name}: the hand-written loop did not converge")
    return q, total / (n_steps - 1)


def bench(name: str, build_dir: Path, hand) -> float:
    """Print one model's measurements and return symvi's speed over the hand loop's."""
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

    report(name, compile_time, c_rate, base_rate, result.newton_iterations, {"q": diff})
    path_rate = C_STEPS / best_time(
        lambda: module.integrate(initial, C_STEPS, h, quantities=False), C_REPEATS)
    q_hand, hand_iterations = hand_run(hand, name, model, initial, C_STEPS, h)
    hand_rate = C_STEPS / best_time(lambda: hand_run(hand, name, model, initial, C_STEPS, h),
                                    C_REPEATS)
    span = slice(0, HAND_AGREEMENT_STEPS + 1)
    agreement = float(np.abs(result.q[span] - q_hand[span]).max()
                      / np.abs(q_hand[span]).max())
    exact = reference_path(model, initial, h, HAND_AGREEMENT_STEPS)
    scale = np.abs(exact).max()
    errors = (float(np.abs(result.q[span] - exact).max() / scale),
              float(np.abs(q_hand[span] - exact).max() / scale))
    ratio = path_rate / hand_rate
    print(f"  C loop, path alone    {path_rate:12,.0f} steps/s  (integrate(..., "
          f"quantities=False): no momenta or energies, as the hand loop)")
    print(f"  hand-written C        {hand_rate:12,.0f} steps/s  (mean {hand_iterations:.2f} "
          f"Newton iterations)")
    print(f"  symvi with its momenta and energies / hand C  {c_rate / hand_rate:.2f}")
    print(f"  max |q_C - q_hand| / max |q|  {agreement:.2e}  (over "
          f"{HAND_AGREEMENT_STEPS:,} steps; target 1e-12)")
    print(f"  from a 25-digit solution of the same equations (tests/midpoint_reference.py), "
          f"max |q - q_exact| / max |q|: symvi {errors[0]:.1e}, hand {errors[1]:.1e}")
    print(f"  symvi path / hand C   {ratio:12.2f}")
    return ratio


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
        hand = hand_loops(Path(build_dir))
        ratios = [bench(name, Path(build_dir), hand) for name in MODELS]
    print(f"ratio: {min(ratios):.2f}")


if __name__ == "__main__":
    main()
