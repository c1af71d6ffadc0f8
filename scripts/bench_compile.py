"""Compile time and peak memory of ``compile_model`` as a model grows.

Models: the planar n-link pendulum chain in absolute angles (q_i is the angle of link i
from the downward vertical; point masses m_i at the link ends, rods l_i, gravity g, unit
defaults but g = 9.81; midpoint rule on the pair groupoid, declared like the bundled
``double_pendulum``, which is the chain with n = 2) for n = 2, 5, 10, 20, and ``se3_body``.

Each model is compiled by ``compile_model(model, tmp, force=True)`` in a fresh child
process (this script with ``--child``) and a fresh temporary folder, so that neither the
build cache nor the in-process derivation memo (the library's only derivation cache)
hides work and no model's memory counts against the next. Columns: wall time of the
call; its stages as the build's ``StageClock`` reports them (``verbose=True``); building
the ``Model`` (declare, outside the call); peak RSS of the Python process (py MB,
``getrusage``) and the largest ``VmHWM`` of its descendants, the C compile (cc MB, polled
from ``/proc``: ``RUSAGE_CHILDREN`` would include the parent's RSS at the child's exec).

Then the exponent p of a least-squares fit wall ∝ n^p (and derive ∝ n^p) over the chain
sizes, the issue's targets (20 links ≤ 30 s and ≤ 500 MB, 10 links ≤ 8 s, se3_body ≤ 6 s)
with PASS/FAIL, and last ``ratio: X``, X = (20-link wall time) / 30 s (≤ 1 meets the
target). A compile running past ``--timeout`` (900 s) is killed and shown as "> 900".
BLAS threads are pinned to 1 (by importing ``bench_step``).

Run from the repository root: ``python scripts/bench_compile.py`` (``--sizes 2,5,10`` for
a subset of chain sizes, ``--quick`` for 2 and 5).
"""
from __future__ import annotations

import bench_step  # noqa: F401  (first: pins BLAS threads and makes symvi importable)

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import os  # noqa: E402
import re  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import sympy as sp  # noqa: E402

from symvi import Example, Model, PairGroupoid, State  # noqa: E402
from symvi.build import compile_model  # noqa: E402
from symvi.models import get  # noqa: E402

SIZES = (2, 5, 10, 20)
QUICK = (2, 5)
SE3 = "se3_body"
STAGES = ("discretise", "derive", "emit", "C compile")
HEADERS = ("wall", "discret.", "derive", "emit", "C comp.", "declare", "py MB", "cc MB",
           "peak MB")
TARGETS = ((20, "wall", 30.0, "s"), (20, "peak", 500.0, "MB"), (10, "wall", 8.0, "s"),
           (SE3, "wall", 6.0, "s"))


def chain(n: int) -> Model:
    """The planar n-link pendulum chain in absolute angles, midpoint rule."""
    G = PairGroupoid(" ".join(f"theta{i}" for i in range(1, n + 1)))
    q, w = G.q, G.qdot
    m = sp.symbols(" ".join(f"m{i}" for i in range(1, n + 1)), positive=True, seq=True)
    l = sp.symbols(" ".join(f"l{i}" for i in range(1, n + 1)), positive=True, seq=True)
    g = sp.Symbol("g", positive=True)
    below = [sum(m[i:]) for i in range(n)]          # mass carried by link i
    kinetic = sum(below[i] * l[i]**2 * w[i]**2 / 2 for i in range(n)) \
        + sum(below[j] * l[i] * l[j] * w[i] * w[j] * sp.cos(q[i] - q[j])
              for i in range(n) for j in range(i + 1, n))
    potential = -sum(below[i] * g * l[i] * sp.cos(q[i]) for i in range(n))
    x0 = [0.5 * (-0.6) ** i for i in range(n)]
    return Model(
        name=f"chain{n}", groupoid=G, lagrangian=kinetic - potential,
        discretisation="midpoint",
        parameters={**{s: 1.0 for s in (*m, *l)}, g: 9.81},
        example=Example(initial=[x0, x0], h=0.005, n_steps=10_000,
                        state=State(v=[0.0] * n, x=x0)),
        description=f"{n}-link pendulum chain (absolute angles), midpoint rule.")


class DescendantPeak(threading.Thread):
    """Polls the largest VmHWM (MB) of this process's descendants until stopped."""

    def __init__(self) -> None:
        super().__init__(daemon=True)
        self.stop, self.mb = threading.Event(), 0.0

    def run(self) -> None:
        while not self.stop.wait(0.02):
            for pid in descendants(os.getpid()):
                self.mb = max(self.mb, hwm_mb(pid))


def descendants(pid: int) -> list[int]:
    """Process ids of every live descendant of ``pid``."""
    try:
        kids = [int(k) for t in Path(f"/proc/{pid}/task").iterdir()
                for k in (t / "children").read_text().split()]
    except OSError:
        return []
    return kids + [d for k in kids for d in descendants(k)]


def hwm_mb(pid: int) -> float:
    """Peak RSS (VmHWM) of process ``pid`` in MB; 0 if it is gone."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return 0.0
    found = re.search(r"^VmHWM:\s+(\d+) kB", status, re.M)
    return int(found[1]) / 1024.0 if found else 0.0


def measure(name: str) -> dict:
    """Compile one model (``chain<n>`` or a bundled name) here; its measurements."""
    start = time.perf_counter()
    model = chain(int(name[5:])) if name.startswith("chain") else get(name)
    declared = time.perf_counter() - start
    lines: list[str] = []
    with tempfile.TemporaryDirectory(prefix="symvi-bench-compile-") as folder:
        watcher = DescendantPeak()
        watcher.start()
        start = time.perf_counter()
        compile_model(model, folder, force=True, verbose=True, progress=lines.append)
        wall = time.perf_counter() - start
        watcher.stop.set()
        watcher.join()
    stages = {m[1]: float(m[2]) for m in
              (re.search(r": (.+) took ([0-9.]+) s$", line) for line in lines) if m}
    return {"declare": declared, "wall": wall, **stages, "cc_mb": watcher.mb,
            "py_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


def run_child(name: str, timeout: float) -> dict | None:
    """Measure ``name`` in a fresh process; None if it ran out of time."""
    try:
        done = subprocess.run([sys.executable, __file__, "--child", name], timeout=timeout,
                              capture_output=True, text=True)
    except subprocess.TimeoutExpired:
        return None
    if done.returncode != 0:
        raise RuntimeError(f"{name}: child failed\n{done.stderr[-4000:]}")
    result = json.loads(done.stdout.strip().splitlines()[-1])
    result["peak"] = max(result["py_mb"], result["cc_mb"])
    return result


def row(label: str, n: str, r: dict | None, timeout: float) -> str:
    """One line of the table."""
    if r is None:
        return f"{label:<10}{n:>4}  {'> ' + format(timeout, 'g'):>8}  (timed out)"
    cells = [r["wall"], *(r.get(s, math.nan) for s in STAGES), r["declare"]]
    return (f"{label:<10}{n:>4}  " + "  ".join(f"{c:8.2f}" for c in cells)
            + f"  {r['py_mb']:8.0f}  {r['cc_mb']:8.0f}  {r['peak']:8.0f}")


def exponent(results: dict, key: str) -> float:
    """Least-squares slope of log(key) against log(n) over the finished chain sizes."""
    points = [(n, r[key]) for n, r in results.items() if isinstance(n, int) and r]
    if len(points) < 2:
        return math.nan
    x, y = np.log([p[0] for p in points]), np.log([p[1] for p in points])
    return float(np.polyfit(x, y, 1)[0])


def verdicts(results: dict, timeout: float) -> None:
    """Print each target of the issue with PASS/FAIL (or 'not run')."""
    print("targets:")
    for which, key, limit, unit in TARGETS:
        label = f"{which}-link" if isinstance(which, int) else which
        name = f"  {label} {key} <= {limit:g} {unit}:"
        if which not in results:
            print(f"{name} not run")
        elif results[which] is None:
            print(f"{name} > {timeout:g} s (timed out)  FAIL")
        else:
            value = results[which][key]
            print(f"{name} {value:.2f} {unit}  {'PASS' if value <= limit else 'FAIL'}")


def arguments() -> argparse.Namespace:
    """The command line."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", help="comma-separated chain sizes (default 2,5,10,20)")
    parser.add_argument("--quick", action="store_true", help="chain sizes 2 and 5 only")
    parser.add_argument("--timeout", type=float, default=900.0, help="seconds per model")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    return parser.parse_args()


def main() -> None:
    args = arguments()
    if args.child:
        print(json.dumps(measure(args.child)))
        return
    sizes = QUICK if args.quick else \
        tuple(int(s) for s in args.sizes.split(",")) if args.sizes else SIZES
    print(f"compile_model(force=True), one fresh process and folder per model; "
          f"timeout {args.timeout:g} s; BLAS threads = 1; times in s, memory in MB")
    print(f"{'model':<10}{'n':>4}" + "".join(f"  {h:>8}" for h in HEADERS))
    results: dict = {}
    for key, name, label, n in [*((s, f"chain{s}", "chain", str(s)) for s in sizes),
                                (SE3, SE3, SE3, "-")]:
        results[key] = run_child(name, args.timeout)
        print(row(label, n, results[key], args.timeout), flush=True)
    print(f"growth exponent (log-log fit over the chain sizes): "
          f"wall ~ n^{exponent(results, 'wall'):.2f}, "
          f"derive ~ n^{exponent(results, 'derive'):.2f}")
    verdicts(results, args.timeout)
    last = results.get(20, {})
    ratio = math.nan if 20 not in results else \
        (args.timeout if last is None else last["wall"]) / 30.0
    if last is None:
        print("(timed out: the ratio is a lower bound)")
    print(f"ratio: {ratio:.2f}")


if __name__ == "__main__":
    main()
