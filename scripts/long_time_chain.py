"""Long-time run of the 10-link pendulum chain (issue 23): unit masses and lengths,
h = 10⁻³, 10⁵ steps, every link released from rest at 0.5 rad. Prints the energy error
(max |E − E₀| and relative to the energy's range of motion scale), its growth (the first
and the last tenth of the run), mean Newton iterations per step, and the wall time.

    python scripts/long_time_chain.py [--links 10] [--steps 100000] [--h 1e-3]
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_compile import chain  # noqa: E402

from symvi import State  # noqa: E402
from symvi.build import compile_model  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--links", type=int, default=10)
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--h", type=float, default=1e-3)
    args = parser.parse_args()
    n = args.links
    with tempfile.TemporaryDirectory(prefix="symvi-chain-") as folder:
        start = time.perf_counter()
        module = compile_model(chain(n), folder)
        built = time.perf_counter() - start
        start = time.perf_counter()
        result = module.integrate(State(x=[0.5] * n, v=[0.0] * n), args.steps, args.h)
        ran = time.perf_counter() - start
    print(f"{n}-link chain: compile {built:.1f} s; {args.steps:,} steps at h = {args.h:g} in "
          f"{ran:.2f} s ({args.steps / ran:,.0f} steps/s)")
    print(f"status     {result.status.name}: {result.message}")
    error = np.abs(result.energy - result.energy[0])
    tenth = max(len(error) // 10, 1)
    scale = float(np.abs(result.energy).max())
    print(f"energy     E₀ = {result.energy[0]:.6f}; max |E − E₀| = {error.max():.3e} "
          f"({error.max() / scale:.2e} of max |E|); first tenth {error[:tenth].max():.3e}, "
          f"last tenth {error[-tenth:].max():.3e}")
    print(f"newton     mean {result.newton_iterations.mean():.2f} iterations per step, "
          f"max {result.newton_iterations.max()}")


if __name__ == "__main__":
    main()
