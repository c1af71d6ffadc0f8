"""The whole-trajectory solve of a constrained problem on an action groupoid at large N
(issue 20): the heavy top with two rotors, variational equations
(``heavy_top_rotors_oc_variational``: SO(3) acting on the direction of gravity × the
rotor angles, three constraints per window, one exactly dependent), rest to rest over
the example's horizon.

For N = 10³, 10⁴, 10⁵: the solve with the default tolerance (its status: where rounding
limits the accuracy, ILL_CONDITIONED with the attainable accuracy), then with a
tolerance above that floor (xtol = 1e-8, 1e-7, 1e-5), with iterations, seconds per
iteration and the optimal cost; the cost's observed order of convergence in h. At
N = 10⁴ the node formulation (κ ∝ N⁴) is timed on the same problem as the baseline;
the last line is ``ratio: <lifted / node solve time at N = 10⁴>`` (the node formulation
did not converge there before the lifted system existed: MAX_ITERATIONS).

Run from the repository root: ``python scripts/scale_constrained.py`` (some 4 minutes,
3.5 GB of memory at N = 10⁵).
"""
from __future__ import annotations

import bench_step  # noqa: F401  (first: pins BLAS threads and makes symvi importable)

import importlib  # noqa: E402
import re  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from symvi.build import compile_model  # noqa: E402
from symvi.models import get  # noqa: E402

NAME = "heavy_top_rotors_oc_variational"
LOOSE = {1_000: 1e-8, 10_000: 1e-7, 100_000: 1e-5}


def solve(module, N: int, **options):
    """(result, seconds) of one solve over the example's horizon with N steps."""
    ex = get(NAME).example
    began = time.perf_counter()
    result = module.solve_bvp(ex.start, ex.end, N, ex.h * ex.n_steps / N, **options)
    return result, time.perf_counter() - began


def attainable(result) -> str:
    found = re.search(r"attainable accuracy to about ([0-9.e+-]+)", result.message)
    return f", attainable {found.group(1)}" if found else ""


def main() -> None:
    module = compile_model(get(NAME), Path(tempfile.gettempdir()) / "symvi-scale")
    costs = {}
    for N, xtol in LOOSE.items():
        default, _ = solve(module, N)
        loose, seconds = solve(module, N, xtol=xtol)
        costs[N] = loose.cost
        print(f"N = {N:>7,}: default xtol {default.status.name} ({default.iterations} it"
              f"{attainable(default)}); xtol = {xtol:.0e} {loose.status.name} in "
              f"{loose.iterations} it, {seconds:.1f} s ({seconds / loose.iterations:.2f} s/it),"
              f" cost {loose.cost:.12f}", flush=True)
    (a, b, c) = costs.values()
    print(f"observed order of the cost in h: {np.log10(abs(a - b) / abs(b - c)):.2f}")
    node_module = importlib.import_module(f"{module.__name__}._runtime.bvp.assembly")
    lifted_result, lifted_time = solve(module, 10_000, xtol=LOOSE[10_000])
    node_module.LIFT_FROM = 10**9
    node_result, node_time = solve(module, 10_000, xtol=LOOSE[10_000])
    print(f"N = 10,000, node formulation: {node_result.status.name} in "
          f"{node_result.iterations} it, {node_time:.1f} s; lifted: "
          f"{lifted_result.status.name}, {lifted_time:.1f} s")
    print(f"ratio: {lifted_time / node_time:.3f}")


if __name__ == "__main__":
    main()
