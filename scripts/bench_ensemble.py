"""Throughput of a batch of trajectories (``integrate_many``, issue 24): 1 and 2 threads,
and a local Dask cluster of 2 worker processes.

The bundled ``double_pendulum`` compiled afresh; 10⁴ trajectories of 10³ steps each from
seeded random initial states (angles in [−1, 1], rates in [−1, 1]) and lengths l1 drawn
per trajectory, every 10th node stored (``keep_every=10``, as a Monte Carlo study would).
Times ``integrate_many(..., workers=1)`` and ``workers=2`` (best of 3 each) and, when
``distributed`` is installed (the ``dask`` extra), ``symvi.dask.integrate_many`` on a
``LocalCluster(n_workers=2, threads_per_worker=1)`` (chunks of 1000, best of 3, the
cluster started and the package loaded on its workers beforehand); checks that all are
the same numbers bit for bit and that trajectory 0 equals the single ``integrate`` call,
and prints trajectory-steps per second. Targets on a 2-core machine: 2 threads ≥ 1.8× one,
the cluster ≥ 1.5× one (measured over three runs: 2.7–3.3 million trajectory-steps/s on
one thread, 1.87–2.06× on two, 1.55–1.65× on the cluster). The last line is
``ratio: <2-thread throughput / 1-thread>``.
BLAS threads are pinned to 1.

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


#: The step of every trajectory.
H = 0.005


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
        options = dict(keep_every=10)
        runs = {f"{w} thread{'s' * (w > 1)}": (lambda w=w: module.integrate_many(
            state, args.steps, H, params, workers=w, **options)) for w in (1, 2)}
        rates, results = {}, {}
        for label, run in runs.items():
            _measure(label, run, args, rates, results)
        cluster = _cluster(module, state, params, args.steps, options)   # after: it idles
        if cluster is not None:
            _measure("Dask, 2 processes", cluster[0], args, rates, results)
            cluster[1]()
        reference = results["1 thread"]
        same = all(np.array_equal(getattr(r, name), getattr(reference, name), equal_nan=True)
                   for r in results.values() for name in ("x", "f", "momenta", "energy"))
        single = module.integrate(module.State(x=state.x[0], v=state.v[0]), args.steps, H,
                                  {"l1": params["l1"][0]}, **options)
        print(f"all bit for bit: {same}; trajectory 0 = the single call: "
              f"{np.array_equal(reference[0].x, single.x)}")
    print(f"ratio: {rates['2 threads'] / rates['1 thread']:.3f}")


def _measure(label: str, run, args, rates: dict, results: dict) -> None:
    seconds = best_time(lambda: results.__setitem__(label, run()), 3)
    rates[label] = args.batch * args.steps / seconds
    print(f"{label:<18} {seconds:7.3f} s  {rates[label]:>12,.0f} trajectory-steps/s  "
          f"({rates[label] / rates['1 thread']:.2f}×); {results[label].message}")


def _cluster(module, state, params, steps: int, options: dict):
    """(run on a local 2-process Dask cluster, close it), or None without ``distributed``."""
    try:
        import distributed
    except ImportError:
        print("Dask: not installed (pip install 'symvi[dask]'); skipped")
        return None
    import symvi.dask

    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       dashboard_address=None)
    client = distributed.Client(cluster)

    def run():
        return symvi.dask.integrate_many(client, module, state, steps, H, params,
                                         chunk=1000, **options)
    symvi.dask.integrate_many(client, module, state, 10, H, params, chunk=1000)   # warm up

    def close():
        client.close()
        cluster.close()
    return run, close


if __name__ == "__main__":
    main()
