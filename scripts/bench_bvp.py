"""Whole-trajectory Newton on the rigid-body optimal-control problem: cost per iteration.

For the bundled problem ``rigid_body_oc`` (paper §3.3.4; R_0 = I, R_N a quarter-turn about
(1,1,1)/√3, Ω = 0 at both ends, T = 1, inertia diag(1, 2, 3)) this script, in one run:

* compiles the model (cached; the symbolic compile is excluded from every timing);
* times one full Newton iteration (assemble R and its banded Jacobian in C, factorise
  with LAPACK, update the path in C, evaluate the new residual; best of 3) for
  N = 10³, 10⁴, 10⁵ and prints the ratio t(10⁵)/t(10⁴) (target ≤ 12: one iteration is
  O(N), DESIGN.md §4), with the outcome of the full solve at each N;
* prints the total solve time at N = 1000 (target < 20 ms; for scale, CasADi + IPOPT on the
  same discrete problem takes about 50 ms after 1.5 s of set-up);
* times a baseline in the same run: the same Newton iteration with the Jacobian
  factorised by SciPy's general sparse LU (``splu``) instead of the banded solver, at
  N = 10³ and 10⁴, and prints the per-iteration ratio.

BLAS threads are pinned to 1 (by importing ``bench_step``). The last line printed is
``ratio: <value>`` (sparse-LU baseline time per iteration over symvi's, N = 10⁴).

Run from the repository root: ``python scripts/bench_bvp.py``.
"""
from __future__ import annotations

import bench_step  # noqa: F401  (first: pins BLAS threads and makes symvi importable)

import numpy as np  # noqa: E402
from scipy.sparse import dia_matrix  # noqa: E402
from scipy.sparse.linalg import splu  # noqa: E402

from bench_step import best_time  # noqa: E402
from symvi.build import compile_model  # noqa: E402
from symvi.models import get  # noqa: E402

MODEL, T, REPEATS = "rigid_body_oc", 1.0, 3
SIZES = (1_000, 10_000, 100_000)


def newton_iteration(module, N: int, sparse: bool = False):
    """One full Newton iteration on the problem at N, from the default initial path:
    assemble R and J in C, factorise and solve (banded LAPACK, or the SuperLU baseline),
    update the path in C and evaluate the new residual. Returns a callable."""
    from symvi._runtime.bvp import _Problem
    from symvi._runtime.paths import initial_path

    model, ex = module.model, get(MODEL).example
    p, h = model.params(), T / N
    problem = _Problem(model, p, h)
    path = initial_path(model, ex.start, ex.end, N, None, p, h)

    def iterate():
        res, ab, bw, _ = problem.assemble(path, True)
        if sparse:
            n = res.size
            # band storage: ab[2 bw + row − col, col] = J[row, col] (rows bw … 3 bw)
            J = dia_matrix((ab[bw:], bw - np.arange(2 * bw + 1)), shape=(n, n)).tocsc()
            delta = splu(J).solve(-res)
        else:
            delta = problem.solve(ab, bw, -res)
        problem.assemble(problem.moved(path, delta, 1.0), False)
    return iterate


def main() -> None:
    module = compile_model(get(MODEL), "generated")
    ex = get(MODEL).example
    per_iteration, baseline = {}, {}
    for N in SIZES:
        per_iteration[N] = best_time(newton_iteration(module, N), REPEATS)
        result = module.solve_bvp(ex.start, ex.end, N, T / N)
        print(f"N = {N:>7,}: {per_iteration[N] * 1e3:8.3f} ms per Newton iteration; "
              f"solve: {result.status.name}, {result.message}, cost {result.cost:.10f}")
        if N <= 10_000:
            baseline[N] = best_time(newton_iteration(module, N, sparse=True), REPEATS)
            print(f"           baseline (same iteration, SuperLU instead of banded LU): "
                  f"{baseline[N] * 1e3:8.3f} ms, {baseline[N] / per_iteration[N]:.2f}× symvi's")
    total = best_time(lambda: module.solve_bvp(ex.start, ex.end, 1_000, T / 1_000), REPEATS)
    print(f"total solve N = 1,000: {total * 1e3:.2f} ms (target < 20 ms)")
    print(f"scaling t(1e5)/t(1e4) per iteration: "
          f"{per_iteration[100_000] / per_iteration[10_000]:.2f} (target ≤ 12)")
    print(f"ratio: {baseline[10_000] / per_iteration[10_000]:.2f}")


if __name__ == "__main__":
    main()
