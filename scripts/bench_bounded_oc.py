"""Bounded optimal control: symvi's ``solve_bvp`` against CasADi + IPOPT and CasADi + FATROP.

Issue 50's benchmark. Four bundled bounded problems at N = 100, 1000 and 10⁴ steps, in
one run, each solver on the same discrete problem from the same initial path:

* ``spacecraft_slew`` (T = 1): the rigid body on SO(3) rest to rest through a quarter turn,
  min Σ_w L_d with L_d(ξ_w, ξ_{w+1}) = h·½|τ_w/I|², Ω = (ξ_w+ξ_{w+1})/2,
  Ω̇ = (ξ_{w+1}−ξ_w)/h, τ_w = IΩ̇ + Ω×IΩ (``bench_bvp.casadi_functions``), the Cayley
  reconstruction, |τ_w,i| ≤ τ_max = 11 and |Ω_w,i| ≤ ω_max = 10 per window;
* ``cart_pole_swing_up`` (T = 2.5, the example's h = 0.01 × 250 steps): nodes q_0 … q_N =
  (x, θ), q_0, q_1, q_{N−1}, q_N fixed, the three-point rule per window, cost Σ_w h·½u_w²
  with u = EL_x, the pole's equation Φ = EL_θ = 0 per window, |u_w| ≤ 14 and
  |x̄_w| ≤ 0.8 with x̄_w = (x_w + x_{w+1} + x_{w+2})/3 (the NumPy problem of
  tests/test_independent_optimum.py and tests/test_bounded_cart_pole.py);
* ``minimum_time_slew`` (first guess T = 1): the slew's torque limits (no rate bound) with
  a free horizon, min Σ_w L_d + ρT, ρ = 100, over the increments and T (h = T/N), rest to
  rest (``casadi_problems.timed_slew_compact``, ``timed_slew_stagewise``: for FATROP T is
  a state of every stage, T_{k+1} = T_k); symvi's cost printed is Σ L_d + ρT too;
* ``minimum_time_double_integrator`` (first guess T = 1, half T*): pure minimum time, |u|
  ≤ 1, from nodes at rest (x_0 = x_1 = 0, x_{N−1} = x_N = 1), min T over the nodes and T
  (``casadi_problems.pure_time_compact``, ``pure_time_stagewise``).

Solvers (CasADi formulations in ``casadi_problems.py``):

* symvi: ``module.solve_bvp(start, end, N, T/N)``, its default (cubic) guess; models
  compiled first with ``compile_model(get(name), generated/)`` (cached, not timed);
* IPOPT: the compact form (symvi's unknowns; the slew's configurations lifted as in
  multiple shooting), exact Hessian, MUMPS, tol 1e-10, ``bound_relax_factor`` 0 (IPOPT
  relaxes bounds by 1e-8 relative by default), ``max_cpu_time`` 120 s, print_level 0;
* FATROP: the stage-wise form (variables and constraints per stage in time order: state
  = the last nodes or (ξ_k, g_{k+1}), control = the next node or increment, gap-closing
  rows x_{k+1} − F(x_k, u_k) first; fixed ends as bounds lbx = ubx) with
  ``structure_detection="auto"``, tol 1e-10, max_iter 1000, print_level 0. FATROP does no
  automatic scaling: the cart-pole's rows u and Φ are multiplied by h² there (same
  feasible set); unscaled, FATROP hangs inside an iteration at N = 1000. FATROP returns
  flag 0 on convergence and flag 1 otherwise — at max_iter, at an acceptable point (it
  stops after 15 iterations at dual infeasibility ≤ 1e-6, like IPOPT's
  ``Solved_To_Acceptable_Level``, which CasADi counts as success) and after a failed
  restoration alike: flag 1 is printed ``acceptable (flag 1)``, and counted as converged,
  only where the point returned is feasible and stationary to 1e-6 when evaluated
  independently (below), else ``not converged (flag 1)``. Should structure detection
  fail, the row says why and FATROP runs with ``structure_detection="none"`` (dense;
  skipped above N = 1000).

Both peers start from symvi's initial path (``symvi._runtime.core.paths.initial_path``
with the default guess). For each (problem, N) the script first checks the CasADi
formulations against symvi: CasADi's cost at symvi's result equals ``result.cost`` to
1e-10 relative (printed), and its constraint violation there is printed.

Timing: CPU time (``time.process_time``) of the solve call alone (CasADi's set-up, which
for FATROP grows like N², is not timed but printed), each solve in a forked child so that
a hang or a solve over 120 s is killed and reported; rounds interleaved (symvi, IPOPT,
FATROP, symvi, …), best of 5 rounds at N = 100, 3 at 1000, 2 at 10⁴ (a solver whose single
solve took over 30 s is not repeated). BLAS threads pinned to 1 (``bench_step`` is
imported first). FATROP is skipped at a size where its set-up, extrapolated like N²,
would exceed 600 s (the slew's at N = 10⁴ takes about 330 s). The whole run takes about
15 minutes (858 s on a loaded 2-core machine).

Printed per row: problem, N, solver, status, iterations, cost, CPU seconds, and for the
peers the largest violation of constraints and bounds and the dual infeasibility
|∇f + Jᵀλ_g + λ_x|_∞ / max(1, |∇f|_∞) at the point and multipliers they return, both
evaluated independently of the solver; where two converged solvers' costs differ by more than
1e-6 relative, both are printed as different local optima. Per (problem, N) the ratio
symvi / min(IPOPT, FATROP) over the peers that converged (inf where symvi did not
succeed, its failure printed). Last line: ``ratio: <worst ratio over problems and N>``
(``nan`` without CasADi). Targets (issue 50): ratio ≤ 0.3, and symvi's cost never worse
than both peers' from the same start (the summary lists the rows where it is).

Run: ``python scripts/bench_bounded_oc.py`` (CasADi from ``pip install '.[bench]'``);
``--sizes 100 1000`` and ``--problems spacecraft_slew`` select a subset.
"""
from __future__ import annotations

import bench_step  # noqa: F401  (first: pins BLAS threads and makes symvi importable)

import argparse  # noqa: E402
import gc  # noqa: E402
import multiprocessing  # noqa: E402
import os  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from contextlib import contextmanager  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Callable  # noqa: E402

import numpy as np  # noqa: E402

from symvi.build import compile_model  # noqa: E402
from symvi.models import get  # noqa: E402

try:
    import casadi as ca
    import casadi_problems as cp
except ImportError:
    ca = cp = None

BUILD = Path(__file__).resolve().parent.parent / "generated"
#: T, or a free horizon's first guess
HORIZON = {"spacecraft_slew": 1.0, "cart_pole_swing_up": 2.5, "minimum_time_slew": 1.0,
           "minimum_time_double_integrator": 1.0}
#: Boundary nodes where the example's are States (the CasADi forms take nodes)
NODES = {"minimum_time_double_integrator": (np.zeros((2, 1)), np.ones((2, 1)))}
SIZES = (100, 1000, 10_000)
ROUNDS = {100: 5, 1000: 3}          # 2 beyond
SOLVE_LIMIT = 120.0                 # s: a single solve beyond is killed
REPEAT_LIMIT = 30.0                 # s: a single solve beyond is not repeated
SETUP_LIMIT = 600.0                 # s: FATROP's set-up predicted beyond: skipped
SAME = 1e-6                         # relative cost difference: different local optima
COST_CHECK = 1e-10
ACCEPTABLE = 1e-6                   # FATROP's flag 1: violation and dual infeasibility
FATROP_MAX_ITER = 1000
IPOPT_OPTIONS = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                 "ipopt.tol": 1e-10, "ipopt.bound_relax_factor": 0.0,
                 "ipopt.hessian_approximation": "exact",
                 "ipopt.max_cpu_time": SOLVE_LIMIT}
FATROP_OPTIONS = {"print_level": 0, "tol": 1e-10, "max_iter": FATROP_MAX_ITER}


@dataclass
class Row:
    """One solver on one (problem, N): its first solve's outcome and its best time."""

    solver: str
    status: str = ""
    success: bool = False
    iterations: int = 0
    cost: float = float("nan")
    seconds: float = float("inf")
    note: str = ""
    skip: str = ""
    x: np.ndarray | None = None
    lam: tuple | None = None
    message: str = ""
    call: Callable | None = field(default=None, repr=False)


@contextmanager
def captured(sink: list):
    """Redirect file descriptors 1 and 2 (CasADi's C++ warnings) into ``sink[0]``."""
    sys.stdout.flush(), sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        os.dup2(tmp.fileno(), 1), os.dup2(tmp.fileno(), 2)
        try:
            yield
        finally:
            sys.stdout.flush(), sys.stderr.flush()
            os.dup2(saved[0], 1), os.dup2(saved[1], 2)
            os.close(saved[0]), os.close(saved[1])
            tmp.seek(0)
            sink.append(tmp.read().decode(errors="replace"))


def isolated(call: Callable, limit: float):
    """(value, CPU seconds of ``call()``) run in a forked child; TimeoutError after
    ``limit`` s (the child killed), RuntimeError with the child's exception."""
    context = multiprocessing.get_context("fork")
    receive, send = context.Pipe(duplex=False)

    def child():
        try:
            began = time.process_time()
            value = call()
            send.send(("ok", value, time.process_time() - began))
        except BaseException as error:  # noqa: BLE001 — reported by the parent
            send.send(("error", f"{type(error).__name__}: {error}", 0.0))

    process = context.Process(target=child, daemon=True)
    sys.stdout.flush(), sys.stderr.flush()      # the child must not repeat buffered output
    process.start()
    send.close()
    try:
        if not receive.poll(limit):
            raise TimeoutError
        kind, value, seconds = receive.recv()
    except EOFError:
        kind, value, seconds = "error", f"the child died (exit code {process.exitcode})", 0.0
    finally:
        if process.is_alive() and not receive.closed:
            process.kill()
        process.join()
        receive.close()
    if kind == "error":
        raise RuntimeError(value)
    return value, seconds


# ---------------------------------------------------------------------------------------
# Solvers
# ---------------------------------------------------------------------------------------
def objective(module, result) -> float:
    """The cost minimised: Σ L_d, and ρT with a free horizon (T alone in pure minimum
    time, whose bundled problem has ρ = 1)."""
    if not module.INFO.free_horizon:
        return float(result.cost)
    if module.INFO.pure_minimum_time:
        return float(result.T)
    return float(result.cost) + module.model.params()[module.INFO.parameters.index("rho")] \
        * result.T


def symvi_row(module, start, end, N, h) -> Row:
    def call():
        r = module.solve_bvp(start, end, N, h)
        return dict(status=r.status.name, success=bool(r.success), iterations=r.iterations,
                    cost=objective(module, r), message=r.message or "")
    return Row("symvi", call=call)


def casadi_call(solver, nlp):
    def call():
        solution = solver(x0=nlp.x0, lbx=nlp.lbx, ubx=nlp.ubx, lbg=nlp.lbg, ubg=nlp.ubg)
        stats = solver.stats()
        return dict(status=stats["return_status"], success=bool(stats["success"]),
                    iterations=int(stats["iter_count"]), cost=float(solution["f"]),
                    x=np.asarray(solution["x"], float).ravel(),
                    lam_g=np.asarray(solution["lam_g"], float).ravel(),
                    lam_x=np.asarray(solution["lam_x"], float).ravel())
    return call


def ipopt_row(nlp) -> Row:
    began = time.process_time()
    solver = ca.nlpsol("ipopt", "ipopt", dict(x=nlp.x, f=nlp.f, g=nlp.g), IPOPT_OPTIONS)
    setup = time.process_time() - began
    return Row("IPOPT", call=casadi_call(solver, nlp), note=f"{nlp.form}, set-up {setup:.1f} s")


def fatrop_solver(nlp, detection: str):
    options = {"print_time": False, "structure_detection": detection, "fatrop": FATROP_OPTIONS}
    if detection == "auto":
        options["equality"] = nlp.equality
    sink: list = []
    try:
        with captured(sink):
            solver = ca.nlpsol("fatrop", "fatrop", dict(x=nlp.x, f=nlp.f, g=nlp.g), options)
    except RuntimeError as error:
        rows = sink[0].count("Structure detection error") if sink else 0
        reason = str(error).strip().splitlines()
        reason = next((line for line in reason if "Fatrop" in line), reason[-1])
        raise RuntimeError(f"{reason.strip()[:160]} ({rows} rows reported)") from None
    return solver


def fatrop_row(nlp, N, setups: dict, name: str) -> tuple[Row, float]:
    """(row, set-up seconds) for FATROP, with structure detection "auto", else "none"."""
    row = Row("FATROP")
    previous = max((n for n in setups if n < N), default=None)
    if previous is not None:
        predicted = setups[previous] * (N / previous) ** 2
        if predicted > SETUP_LIMIT:
            row.skip = (f"skipped: CasADi's FATROP set-up grows like N² ({setups[previous]:.1f} s "
                        f"at N = {previous}, {predicted:.0f} s predicted > {SETUP_LIMIT:.0f} s)")
            return row, float("nan")
    began = time.process_time()
    try:
        solver, detection = fatrop_solver(nlp, "auto"), "auto"
    except RuntimeError as error:
        print(f"  {name} N = {N}: FATROP's structure detection failed: {error}")
        if N > 1000:
            row.skip = f"skipped: structure detection failed ({error}); dense above N = 1000"
            return row, float("nan")
        solver, detection = fatrop_solver(nlp, "none"), "none"
    setup = time.process_time() - began
    structure = "auto" if detection == "auto" else "none (auto failed)"
    row.call = casadi_call(solver, nlp)
    row.note = f"{nlp.form}, structure {structure}, set-up {setup:.1f} s"
    return row, setup


def fatrop_status(row: Row, violation: float, dual: float) -> None:
    """FATROP's flag 1 (module docstring): acceptable where the point returned is, in
    independent evaluation, feasible and stationary to ACCEPTABLE."""
    if row.status == "0":
        row.status = "Success (flag 0)"
    elif row.status == "1" and row.iterations < FATROP_MAX_ITER \
            and max(violation, dual) <= ACCEPTABLE:
        row.status, row.success = "acceptable (flag 1)", True
    elif row.status == "1":
        row.status = "not converged (flag 1)"
    else:
        row.status = f"flag {row.status}"


# ---------------------------------------------------------------------------------------
# One (problem, N)
# ---------------------------------------------------------------------------------------
def formulations(name, module, model, start, end, N, h):
    from symvi._runtime.core.paths import initial_path

    p = {str(s): v for s, v in model.parameters}
    path = initial_path(module.model, start, end, N, None, module.model.params(), h)
    if name == "spacecraft_slew":
        args = (path, start, end, N, h, np.array([p["I1"], p["I2"], p["I3"]]),
                p["tau_max"], p["omega_max"])
        return cp.slew_compact(*args), cp.slew_stagewise(*args)
    if name == "minimum_time_slew":
        args = (path, start, end, N, h, np.array([p["I1"], p["I2"], p["I3"]]),
                p["tau_max"], p["rho"])
        return cp.timed_slew_compact(*args), cp.timed_slew_stagewise(*args)
    if name == "minimum_time_double_integrator":
        args = (path, start, end, N, h, p["u_max"])
        return cp.pure_time_compact(*args), cp.pure_time_stagewise(*args)
    args = (path, start, end, N, h, p, p["u_max"], p["d"])
    return cp.cart_pole_compact(*args), cp.cart_pole_stagewise(*args)


def run_rounds(rows: list[Row], rounds: int) -> None:
    for round_ in range(rounds):
        for row in rows:
            if row.skip or row.call is None or (round_ and row.seconds > REPEAT_LIMIT):
                continue
            try:
                value, seconds = isolated(row.call, SOLVE_LIMIT)
            except TimeoutError:
                row.skip = (f"skipped: a single solve ran over {SOLVE_LIMIT:.0f} s "
                            f"(killed{'' if round_ == 0 else f' in round {round_ + 1}'})")
                continue
            except RuntimeError as error:
                row.skip = f"failed: {str(error).strip().splitlines()[0][:200]}"
                continue
            if round_ == 0:
                row.status, row.success = str(value["status"]), value["success"]
                row.iterations, row.cost = value["iterations"], value["cost"]
                row.x, row.message = value.get("x"), value.get("message", "")
                row.lam = (value["lam_g"], value["lam_x"]) if "lam_g" in value else None
            row.seconds = min(row.seconds, seconds)


def bench(name: str, module, model, N: int, setups: dict) -> tuple[float, list[Row]]:
    """Print one (problem, N) block; return (ratio, rows)."""
    T = HORIZON[name]
    h = T / N
    start, end = NODES.get(name) or (np.asarray(a, float)
                                     for a in (model.example.start, model.example.end))
    print(f"\n{name}, N = {N}, T = {T}, h = {h:g}")
    result = module.solve_bvp(start, end, N, h)            # untimed: the cost check
    rows = [symvi_row(module, start, end, N, h)]
    nlps = {}
    if ca is not None:
        began = time.process_time()
        compact, stagewise = formulations(name, module, model, start, end, N, h)
        built = time.process_time() - began
        nlps = {"IPOPT": compact, "FATROP": stagewise}
        checks = []
        for nlp in (compact, stagewise):
            cost, violation = nlp.cost_and_violation(nlp.at(result))
            relative = (cost - objective(module, result)) / abs(objective(module, result))
            checks.append(f"{nlp.form} {relative:+.1e} (violation there {violation:.1e})")
            ok = abs(relative) <= COST_CHECK
            if not ok:
                checks[-1] += "  MISMATCH"
        print(f"  cost check at symvi's result ({result.status.name}, cost {result.cost:.12f}): "
              f"CasADi's cost − symvi's, relative: {'; '.join(checks)} "
              f"[{'OK' if all('MISMATCH' not in c for c in checks) else 'FAILED'}: ≤ "
              f"{COST_CHECK:g}]; formulations built in {built:.1f} s")
        rows.append(ipopt_row(compact))
        fatrop, setup = fatrop_row(stagewise, N, setups.setdefault(name, {}), name)
        if setup == setup:
            setups[name][N] = setup
        rows.append(fatrop)
    run_rounds(rows, ROUNDS.get(N, 2))
    for row in rows:
        if row.x is not None:
            _, violation = nlps[row.solver].cost_and_violation(row.x)
            dual = nlps[row.solver].dual_infeasibility(row.x, *row.lam)
            row.note = f"violation {violation:.1e}, dual inf. {dual:.1e}; {row.note}"
            if row.solver == "FATROP":
                fatrop_status(row, violation, dual)
        if row.skip:
            print(f"  {name:<19} {N:>6} {row.solver:<7} {row.skip}"
                  f"{'' if not row.note else f' ({row.note})'}")
            continue
        print(f"  {name:<19} {N:>6} {row.solver:<7} {row.status:<28} {row.iterations:>5} "
              f"{row.cost:>18.12f} {row.seconds:>9.4f} s  {row.note}")
    converged = [r for r in rows if not r.skip and r.success]
    for i, a in enumerate(converged):
        for b in converged[i + 1:]:
            if abs(a.cost - b.cost) > SAME * max(abs(a.cost), abs(b.cost)):
                print(f"  different local optima: {a.solver} {a.cost:.12f} vs {b.solver} "
                      f"{b.cost:.12f} (relative {(a.cost - b.cost) / b.cost:+.2e})")
    symvi = rows[0]
    peers = [r for r in rows[1:] if not r.skip and r.success]
    if symvi.skip or not symvi.success:
        print(f"  symvi failed: {symvi.skip or symvi.status}: {symvi.message}")
        ratio = float("inf")
    elif not peers:
        print("  no peer converged: no ratio for this row")
        ratio = float("nan")
    else:
        best = min(peers, key=lambda r: r.seconds)
        ratio = symvi.seconds / best.seconds
        print(f"  symvi / min(IPOPT, FATROP) = {symvi.seconds:.4f} / {best.seconds:.4f} "
              f"({best.solver}) = {ratio:.3f}")
    del nlps
    gc.collect()
    return ratio, rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    parser.add_argument("--problems", nargs="+", default=list(HORIZON), choices=list(HORIZON))
    arguments = parser.parse_args()
    began_wall = time.perf_counter()
    if ca is None:
        print("CasADi is not importable (pip install '.[bench]'): symvi alone")
    else:
        print(f"CasADi {ca.__version__}; FATROP available: {ca.has_nlpsol('fatrop')}; "
              f"CPU seconds of the solve call, best of interleaved rounds")
    ratios, summary = {}, []
    setups: dict = {}
    for name in arguments.problems:
        model = get(name)
        began = time.perf_counter()
        module = compile_model(model, BUILD)
        print(f"\n{name}: compiled in {time.perf_counter() - began:.1f} s (cached; not timed)")
        for N in sorted(arguments.sizes):
            ratios[name, N], rows = bench(name, module, model, N, setups)
            summary.append((name, N, rows))
    print("\nsummary (symvi / min(converged peers), CPU time):")
    for (name, N), ratio in ratios.items():
        print(f"  {name:<19} N = {N:>6}: {ratio:.3f}")
    worse_both, worse_one = [], []
    for name, N, rows in summary:
        symvi, peers = rows[0], [r for r in rows[1:] if not r.skip and r.success]
        if symvi.skip or not peers or symvi.cost != symvi.cost:
            continue
        worse = [r for r in peers if symvi.cost > r.cost * (1 + SAME)]
        label = f"{name} N = {N} (symvi {symvi.cost:.6f}: " + \
            ", ".join(f"{r.solver} {r.cost:.6f}" for r in peers) + ")"
        if len(worse) == len(peers):
            worse_both.append(label)
        elif worse:
            worse_one.append(label)
    print(f"symvi's cost worse than every converged peer's: {'; '.join(worse_both) or 'nowhere'}")
    print(f"symvi's cost worse than one peer's: {'; '.join(worse_one) or 'nowhere'}")
    print(f"wall time {time.perf_counter() - began_wall:.0f} s")
    finite = [r for r in ratios.values() if r == r]
    print(f"ratio: {max(finite) if ca is not None and finite else float('nan'):.3f}")


if __name__ == "__main__":
    main()
