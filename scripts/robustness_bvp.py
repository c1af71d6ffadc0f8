"""The robustness battery of the whole-trajectory solve, on every bundled optimal-control
problem, bounded ones included (issue 20, item 3; issue 21).

For each problem at N = 100 and N = 1000 (the example's horizon): the chord guess, the
zero guess (every free node at the last start node) and 20 seeded smooth random
perturbations of the default guess (``tests/battery.py``). Prints, per problem and N, the
success rate, the statuses of the failures, the spread of the optimal cost over the
successes (one minimum, or several local ones) and the wall time. Every SUCCESS has passed
the solver's second-order test (a minimum, not a saddle: ``symvi/_runtime/bvp/optimality.py``).

Run from the repository root: ``python scripts/robustness_bvp.py [problem ...]``.
"""
from __future__ import annotations

import bench_step  # noqa: F401  (first: pins BLAS threads and makes symvi importable)

import collections  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

import battery  # noqa: E402
from symvi.build import compile_model  # noqa: E402
from symvi.models import BOUNDED, CONTROL, get  # noqa: E402

SIZES = (100, 1000)


def report(name: str, N: int, module) -> float:
    """Run the battery for one problem at N; print one line; return the success rate."""
    began = time.perf_counter()
    outcomes = battery.run(module, name, N)
    elapsed = time.perf_counter() - began
    costs = [r.cost for r in outcomes.values() if r.success]
    failures = collections.Counter(r.status.name for r in outcomes.values() if not r.success)
    rate = len(costs) / len(outcomes)
    spread = f"cost {min(costs):.10g} … {max(costs):.10g}" if costs else "no success"
    print(f"{name:<34} N = {N:>5}: {rate:6.1%} of {len(outcomes)}  {spread}  "
          f"failures {dict(failures) or '-'}  {elapsed:.1f} s", flush=True)
    return rate


def main(names: list[str]) -> None:
    for name in names or CONTROL + BOUNDED:
        module = compile_model(get(name), Path(__file__).resolve().parent.parent / "generated")
        for N in SIZES:
            report(name, N, module)


if __name__ == "__main__":
    main(sys.argv[1:])
