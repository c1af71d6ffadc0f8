"""Whole-trajectory minimum snap on SE(3) (issue 25, part 2): iterations and time per
Newton iteration at N = 10², 10³, 10⁴, and whether each solve reached its tolerance.

The bundled ``se3_snap`` (L = ½ ξ⃛ᵀ diag(J, m) ξ⃛, order 4, rule ``lie_central4``) between
the first and last four poses of an exact solution: the increments ξ_k sample a random
quintic (degree 2k − 3 = 5, an exact discrete solution), the poses g_{k+1} = g_k cay(hξ_k)
are reconstructed here in NumPy, and the solve starts from symvi's default interpolation
of the end poses. Printed per N: status, Newton iterations, seconds per iteration, the
distance of the solved increments from the exact ones, and the solver's message.

The Newton matrix is banded (n(k + 1) − 1 = 29 diagonals on either side), so an iteration
costs O(N); its condition number grows like N^{2k} = N⁸, so from N ≈ 10³ rounding limits
the attainable accuracy and the solve says so (the trust-at-scale rules) rather than
reporting a path it cannot vouch for. One Newton iteration (assemble R and its banded
Jacobian in C, factorise and solve, update the path, evaluate the new residual:
``scripts/bench_bvp.py``'s ``newton_iteration``, from the default initial path) is timed
apart, best of 3, and against the baseline of the same iteration with the Jacobian
factorised by SciPy's general sparse LU (``splu``). The last line is ``ratio: <splu
iteration> / <symvi iteration>`` at N = 10⁴; the growth of symvi's iteration from 10³
to 10⁴ is printed before it (10 for a cost linear in N).

Run from the repository root: ``python scripts/bench_order_k.py``.
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

try:
    import symvi  # noqa: F401
except ImportError:
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_bvp import newton_iteration  # noqa: E402
from bench_step import best_time  # noqa: E402
from symvi.build import compile_model  # noqa: E402
from symvi.models import get  # noqa: E402

SIZES = (100, 1_000, 10_000)


def exact_path(model, n_steps: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(poses (N+1, 4, 4), increments (N, 6)): ξ a random quintic at the elements'
    middles, the poses by the Cayley map."""
    basis = np.array([np.array(E.tolist(), dtype=float) for E in model.groupoid.basis])
    coefficients = 0.4 * np.random.default_rng(seed).standard_normal((6, basis.shape[0]))
    h = 1.0 / n_steps
    middles = (np.arange(n_steps) + 0.5) * h
    xi = np.stack([np.polyval(c, middles) for c in coefficients.T], axis=1)
    eye = np.eye(basis.shape[1])
    poses = [eye]
    for row in xi:
        X = h * np.einsum("a,aij->ij", row, basis)
        poses.append(poses[-1] @ np.linalg.solve(eye - X / 2, eye + X / 2))
    return np.array(poses), xi


def main() -> None:
    model = get("se3_snap")
    with tempfile.TemporaryDirectory(prefix="symvi-bench-") as build_dir:
        start = time.perf_counter()
        module = compile_model(model, build_dir, force=True)
        print(f"se3_snap (order {model.order}): compile {time.perf_counter() - start:.1f} s, "
              f"band {module.model.lib.symvi_bvp_bandwidth()} diagonals either side")
        iteration, baseline = {}, {}
        for n in SIZES:
            poses, xi = exact_path(model, n)
            k = model.order
            start = time.perf_counter()
            result = module.solve_bvp(poses[:k], poses[-k:], n, 1.0 / n)
            seconds = time.perf_counter() - start
            iteration[n] = best_time(newton_iteration(module, poses[:k], poses[-k:], n), 3)
            error = float(np.abs(result.f - xi).max())
            print(f"N = {n:>6}: {result.status.name:<16} {result.iterations:3d} iterations "
                  f"in {seconds:6.2f} s; one iteration {iteration[n] * 1e3:8.2f} ms; "
                  f"max |ξ − ξ_exact| = {error:.1e}")
            print(f"    {result.message}")
            if n >= 1_000:
                baseline[n] = best_time(newton_iteration(module, poses[:k], poses[-k:], n,
                                                         sparse=True), 3)
                print(f"    baseline (splu) iteration {baseline[n] * 1e3:8.2f} ms")
    print(f"growth of one iteration from N = 10³ to 10⁴: "
          f"{iteration[10_000] / iteration[1_000]:.1f} (10 if linear)")
    print(f"ratio: {baseline[10_000] / iteration[10_000]:.2f}")


if __name__ == "__main__":
    main()
