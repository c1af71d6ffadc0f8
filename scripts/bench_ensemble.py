"""Throughput of a batch of trajectories (``integrate_many``, issue 24) on 1 and 2 threads.

The bundled ``double_pendulum`` compiled afresh; 10⁴ trajectories of 10³ steps each from
seeded random initial states (angles in [−1, 1], rates in [−1, 1]) and lengths l1 drawn
per trajectory, stored in full. Times ``integrate_many(..., workers=1)`` and
``workers=2`` (best of 3 each), checks that both batches are the same numbers bit for bit
and that trajectory 0 equals the single ``integrate`` call, and prints trajectory-steps
per second. Target: 2 workers ≥ 1.8× one worker on a 2-core machine (measured 1.82×,
2.9 million trajectory-steps/s on one worker, 5.3 million on two). Not yet measured
here: the same batch on a local Dask cluster (issue 24, item 3). The last line is
``ratio: <2-worker throughput / 1-worker throughput>``. BLAS threads are pinned to 1.

Run from the repository root: ``python scripts/bench_ensemble.py [--batch B] [--steps N]``.
"""
from __future__ import annotations

import bench_step  # noqa: F401  (first: pins BLAS threads and makes symvi importable)

import argparse  # noqa: E402
import tempfile  # noqa: E402

import numpy as np  # noqa: E402

from bench_step import best_time  # noqa: E402
from symvi.build import compile_model  # noqa: E402
from symvi.models import get  # noqa: E402


def batch(module, B: int, seed: int = 24):
    """Seeded initial states and per-trajectory lengths l1."""
    rng = np.random.default_rng(seed)
    state = module.State(x=rng.uniform(-1, 1, (B, 2)), v=rng.uniform(-1, 1, (B, 2)))
    return state, {"l1": rng.uniform(0.5, 2.0, B)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=10_000)
    parser.add_argument("--steps", type=int, default=1_000)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        module = compile_model(get("double_pendulum"), folder, force=True)
        state, params = batch(module, args.batch)
        h, rates, results = 0.005, {}, {}
        for workers in (1, 2):
            def run(workers=workers):
                results[workers] = module.integrate_many(state, args.steps, h, params,
                                                         workers=workers)
            seconds = best_time(run, 3)
            rates[workers] = args.batch * args.steps / seconds
            print(f"workers = {workers}: {seconds:.3f} s, {rates[workers]:,.0f} "
                  f"trajectory-steps/s; {results[workers].message}")
        same = all(np.array_equal(getattr(results[1], name), getattr(results[2], name),
                                  equal_nan=True) for name in ("x", "f", "momenta", "energy"))
        single = module.integrate(module.State(x=state.x[0], v=state.v[0]), args.steps, h,
                                  {"l1": params["l1"][0]})
        print(f"1 and 2 workers bit for bit: {same}; trajectory 0 = the single call: "
              f"{np.array_equal(results[2][0].x, single.x)}")
    print(f"ratio: {rates[2] / rates[1]:.3f}")


if __name__ == "__main__":
    main()
