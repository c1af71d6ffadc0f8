"""Wall time of ``symvi check`` on every bundled model and on a planar Kepler model with
its rotation symmetry (issue 26: each within 60 s with the default budget), one fresh
process per model, and the parts each check skipped for the budget.

    python scripts/check_times.py [--budget SECONDS] [MODEL ...]

Prints one line per model, then the slowest (``max: X s``).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

KEPLER = '''
import sympy as sp
from symvi import Example, Model, PairGroupoid, State, Symmetry
G = PairGroupoid("x y")
x, y = G.q
mu = sp.Symbol("mu", positive=True)
model = Model(name="kepler", groupoid=G, parameters={mu: 1.0},
              lagrangian=sum(v**2 for v in G.qdot) / 2 + mu / sp.sqrt(x**2 + y**2),
              symmetries=[Symmetry("angular_momentum", [-y, x])],
              example=Example(state=State(x=[1.0, 0.0], v=[0.0, 1.0]), h=0.01,
                              n_steps=1000))
'''


def timed(spec: str, budget: str) -> tuple[float, int, list[str]]:
    """(seconds, exit code, parts skipped for the budget) of one ``symvi check --json``."""
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "symvi.cli", "check", spec, "--json",
                           "--budget", budget], capture_output=True, text=True, env=env)
    elapsed = time.perf_counter() - start
    try:
        results = json.loads(done.stdout)["results"]
    except (ValueError, KeyError):
        return elapsed, done.returncode, [f"(no report: {done.stderr.strip()[-200:]})"]
    skipped = [f"{r['name']}: {', '.join(r['data']['skipped_for_budget'])}"
               for r in results if r["data"].get("skipped_for_budget")]
    return elapsed, done.returncode, skipped


def main() -> None:
    from symvi.models import BUNDLED
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="*", help="bundled names or model files "
                                                  "(default: all bundled and Kepler)")
    parser.add_argument("--budget", default="20")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        kepler = Path(folder) / "kepler.py"
        kepler.write_text(KEPLER)
        specs = args.models or [*BUNDLED, str(kepler)]
        slowest = 0.0
        for spec in specs:
            elapsed, code, skipped = timed(spec, args.budget)
            slowest = max(slowest, elapsed)
            name = Path(spec).stem if spec.endswith(".py") else spec
            print(f"{name:34s} {elapsed:6.1f} s  exit {code}"
                  + (f"  skipped for the budget: {'; '.join(skipped)}" if skipped else ""),
                  flush=True)
    print(f"max: {slowest:.1f} s")


if __name__ == "__main__":
    main()
