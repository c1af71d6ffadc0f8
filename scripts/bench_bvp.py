"""Whole-trajectory Newton at scale: cost per iteration, solve time and accuracy to N = 10⁶.

In one run, for two bundled problems at N = 10³, 10⁴, 10⁵, 10⁶ (T = 1, h = T/N), this
script compiles the model (cached; the symbolic compile is excluded from every timing) and
prints the time of one full Newton iteration (assemble R and its banded Jacobian in C,
factorise and solve by band LU in C, update the path in C, evaluate the new residual; best
of 3), the number of iterations and total time of the solve (best of as many as fit in
about a second when one solve is under 2 s),
its status and an error:

* ``rigid_body_oc``, the rigid-body optimal control of paper §3.3.4 (R_0 = R_1 = I,
  R_{N−1} = R_N a quarter-turn about (1,1,1)/√3, inertia diag(1, 2, 3)): the cost C(N)
  and C(N) − C_R, C_R Richardson-extrapolated from the two finest SUCCESS solves. The
  discrete cost converges at order 1 in h, not 2: ξ_0 = ξ_{N−1} = 0 hold at t = h/2 and
  T − h/2, so the turn takes T − h and C(N) ≈ C*(1 + 3h) (rest-to-rest cost ∝ T⁻³); the
  order observed at N = 1000, 2000, 4000 is printed with it.
* ``cubic_spline`` (L = ½|q̈|², three-point rule) between the ends of the cubic of
  tests/test_false_success.py: its discrete solution is that cubic at the nodes for every
  N, so the error is max|q − cubic| / max|cubic|.

Statuses are printed as returned, with the message of every solve that is not a
SUCCESS; where rounding limits the accuracy (ILL_CONDITIONED), the solve is repeated as
its message advises, warm-started with twice the attainable accuracy as xtol. From
N = 2000 on both are solved with the lifted system (κ ∝ N² instead of the node matrix's
N⁴, three times its unknowns: the step from 10³ to 10⁴ costs more than tenfold per
iteration; the targets apply from 10⁴ on). Each solve runs in a forked process, stopped
(and reported so) if it has not finished after TIME_LIMIT = 5 minutes.
Targets: t(10⁶)/t(10⁵) and t(10⁵)/t(10⁴) ≤ 12 per iteration (one iteration is O(N),
DESIGN.md §4); total solve of rigid_body_oc at N = 1000 ≤ 5 ms.

Baseline, when CasADi is importable (``pip install '.[bench]'``): the same discrete
problem of §3.3.4 in CasADi, solved by IPOPT (exact Hessian, MUMPS, tol 1e-10) from
symvi's initial path at N = 10³ (and 10⁴ when that solve should take under a minute):
set-up excluded, ``solver(...)`` timed likewise, its cost checked against symvi's. Without
CasADi, the baseline is the same Newton iteration with the Jacobian factorised by
SciPy's general sparse LU (``splu``) instead of the banded solver (N = 10³, 10⁴).

BLAS threads are pinned to 1 (by importing ``bench_step``). The last line printed is
``ratio: <value>``: symvi's total solve time over IPOPT's at N = 1000 (below 1: symvi is
faster), or without CasADi the sparse-LU time per iteration over symvi's at N = 10⁴.

Run: ``python scripts/bench_bvp.py`` (builds into the repository's ``generated/``).
"""
from __future__ import annotations

import bench_step  # noqa: F401  (first: pins BLAS threads and makes symvi importable)

import multiprocessing  # noqa: E402
import re  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.sparse import dia_matrix  # noqa: E402
from scipy.sparse.linalg import splu  # noqa: E402

from bench_step import best_time  # noqa: E402
from symvi.build import compile_model  # noqa: E402
from symvi.models import get  # noqa: E402

try:
    import casadi as ca
except ImportError:
    ca = None

RIGID, SPLINE = "rigid_body_oc", "cubic_spline"
BUILD = Path(__file__).resolve().parent.parent / "generated"   # from any working directory
T, REPEATS, TIME_LIMIT = 1.0, 3, 300.0      # TIME_LIMIT: seconds per solve, then stopped
SIZES = (1_000, 10_000, 100_000, 1_000_000)
SPLU_SIZES, IPOPT_SIZES = (1_000, 10_000), (1_000, 10_000)
COST_ORDER, ORDER_SIZES = 1, (1_000, 2_000, 4_000)   # C(N) − C* = O(h): see the docstring


def cubic(t: np.ndarray) -> np.ndarray:
    """The exact cubic of tests/test_false_success.py, one row per node."""
    return np.stack([t**3 - 0.5 * t**2 + 0.2 * t, -(t**3) + t], axis=1)


def boundary(name: str, N: int):
    """(start, end, exact nodes or None) for ``name`` at N."""
    if name == RIGID:
        ex = get(RIGID).example
        return ex.start, ex.end, None
    exact = cubic(T / N * np.arange(N + 1))
    return exact[:2], exact[-2:], exact


def newton_iteration(module, start, end, N: int, sparse: bool = False):
    """One full Newton iteration on the problem at N, from the default initial path:
    assemble R and J in C, factorise and solve (band LU in C, or the SuperLU baseline),
    update the path in C and evaluate the new residual. Returns a callable."""
    from symvi._runtime.bvp.assembly import Problem as _Problem
    from symvi._runtime.core.paths import initial_path

    model = module.model
    p, h = model.params(), T / N
    problem = _Problem(model, p, h)
    path = initial_path(model, start, end, N, None, p, h)

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


def repeats(seconds: float) -> int:
    """How often to repeat a call of ``seconds`` for its best time: for about a second, at
    least REPEATS and at most 100 times (the best of three 10-ms solves on a 2-core machine
    with other work varied by 50 %)."""
    return int(min(100, max(REPEATS, 1.0 / max(seconds, 1e-6))))


def solve_summary(module, start, end, N: int, exact, send) -> None:
    """In the child process of :func:`timed_solve`: solve at N (timed, best of
    :func:`repeats` when one solve is under 2 s) and send a summary of the result."""
    def run():
        return module.solve_bvp(start, end, N, T / N)
    began = time.perf_counter()
    result = run()
    seconds = time.perf_counter() - began
    if seconds < 2.0:
        seconds = min(seconds, best_time(run, repeats(seconds) - 1))
    summary = dict(status=result.status.name, success=result.success, cost=result.cost,
                   iterations=result.iterations, message=result.message, seconds=seconds,
                   error=error(result, exact))
    found = re.search(r"attainable accuracy to about ([0-9.e+-]+)", result.message)
    if found:       # what the message advises: that accuracy asked for, from this path
        xtol = 2 * float(found.group(1))
        accepted = module.solve_bvp(start, end, N, T / N, guess=result, xtol=xtol)
        summary["accepted"] = (f"warm-started with xtol = {xtol:.0e}: "
                               f"{accepted.status.name} in {accepted.iterations} iterations, "
                               f"{error(accepted, exact)}")
    send.send(summary)


def timed_solve(module, start, end, N: int, exact) -> dict | str:
    """The summary of :func:`solve_summary`, run in a forked process that is stopped after
    TIME_LIMIT; else why there is none."""
    context = multiprocessing.get_context("fork")
    receive, send = context.Pipe(duplex=False)
    child = context.Process(target=solve_summary, args=(module, start, end, N, exact, send))
    began = time.perf_counter()
    child.start()
    while not receive.poll(1.0) and child.is_alive():
        if time.perf_counter() - began > TIME_LIMIT:
            child.kill()
    summary = receive.recv() if receive.poll() else None
    child.join()
    if summary is not None:
        return summary
    if child.exitcode == -9:
        return f"solve stopped: not finished within {TIME_LIMIT:g} s"
    return f"solve failed: its process exited with code {child.exitcode}"


def power(N: int) -> str:
    """10⁵ as "1e5"; other N with separators."""
    e = round(np.log10(N))
    return f"1e{e}" if 10**e == N else f"{N:,}"


def error(result, exact) -> str:
    """The cubic's relative error, or the rigid body's cost."""
    if exact is None:
        return f"cost {result.cost:.12f}"
    relative = np.abs(result.q - exact).max() / np.abs(exact).max()
    return f"max|q − cubic|/max|cubic| {relative:.1e}"


def scale_run(name: str) -> dict:
    """Print the table for one model; returns {N: (per iteration, solve summary or why
    there is none)}."""
    module, rows = compile_model(get(name), BUILD), {}
    print(f"\n{name} (T = {T:g}, h = T/N): ms per iteration | iterations | solve | status")
    for N in SIZES:
        start, end, exact = boundary(name, N)
        per_iteration = best_time(newton_iteration(module, start, end, N), REPEATS)
        rows[N] = per_iteration, timed_solve(module, start, end, N, exact)
        head = f"  N = {N:>9,}: {per_iteration * 1e3:9.3f} ms | "
        if isinstance(r := rows[N][1], str):
            print(head + r)
            continue
        print(f"{head}{r['iterations']:3d} | {r['seconds']:9.4f} s | {r['status']}, "
              f"{r['error']}")
        if not r["success"]:
            print(f"      {r['message']}")
        if "accepted" in r:
            print(f"      {r['accepted']}")
    print("  per-iteration scaling (target ≤ 12): " + ", ".join(
        f"t({power(b)})/t({power(a)}) {rows[b][0] / rows[a][0]:.2f}"
        for a, b in zip(SIZES, SIZES[1:])))
    return rows


def richardson(rows: dict) -> None:
    """Print C(N) − C_R, C_R extrapolated at COST_ORDER from the two finest SUCCESS solves,
    and the order of C(N) observed at N = 1000, 2000, 4000."""
    module, ex = compile_model(get(RIGID), BUILD), get(RIGID).example
    c1, c2, c4 = (module.solve_bvp(ex.start, ex.end, N, T / N).cost for N in ORDER_SIZES)
    print(f"  observed order of C(N) from N = {', '.join(f'{N:,}' for N in ORDER_SIZES)}: "
          f"{np.log2((c1 - c2) / (c2 - c4)):.3f}")
    cost = {N: r["cost"] for N, (_, r) in rows.items() if isinstance(r, dict) and r["success"]}
    if len(cost) < 2:
        print(f"  cost: fewer than two SUCCESS solves ({sorted(cost)}), no extrapolation")
        return
    (N1, N2), p = sorted(cost)[-2:], COST_ORDER
    limit = (N2**p * cost[N2] - N1**p * cost[N1]) / (N2**p - N1**p)
    print(f"  cost extrapolated at order {p} from N = {N1:,} and {N2:,}: C_R = {limit:.12f}")
    for N, (_, r) in rows.items():
        if isinstance(r, dict):
            print(f"  N = {N:>9,}: C(N) − C_R = {r['cost'] - limit:+.3e} ({r['status']})")


# ---------------------------------------------------------------------------------------
# Baseline: the discrete problem of §3.3.4 in CasADi, solved by IPOPT
# ---------------------------------------------------------------------------------------
def increment(g0: np.ndarray, g1: np.ndarray, h: float) -> np.ndarray:
    """ξ with g1 = g0 cay(hξ̂): vee of cay⁻¹(W) = 2(W − I)(W + I)⁻¹ over h."""
    W = g0.T @ g1
    C = np.linalg.solve(W + np.eye(3), 2 * (W - np.eye(3)))
    return np.array([C[2, 1], C[0, 2], C[1, 0]]) / h


def timed_casadi_functions(inertia: np.ndarray, g_last: np.ndarray):
    """(L_d, step, end, torque) as CasADi SX functions with the step h an input:
    L_d(ξ_w, ξ_{w+1}, h) = h·½|τ/I|² with Ω = (ξ_w+ξ_{w+1})/2, Ω̇ = (ξ_{w+1}−ξ_w)/h,
    τ = IΩ̇ + Ω×IΩ (paper eq. ``sdfinal``, ERRATA 1–3); step(g, ξ, h) = g cay(hξ̂) (g as 9
    column-major entries); end(g) = vee cay⁻¹(g_{N−1}ᵀ g); torque(ξ_w, ξ_{w+1}, h) = τ."""
    a, b, g, h = ca.SX.sym("a", 3), ca.SX.sym("b", 3), ca.SX.sym("g", 9), ca.SX.sym("h")
    omega, rate = (a + b) / 2, (b - a) / h
    tau = inertia * rate + ca.cross(omega, inertia * omega)
    w = h * a
    w_hat = ca.vertcat(ca.horzcat(0, -w[2], w[1]), ca.horzcat(w[2], 0, -w[0]),
                       ca.horzcat(-w[1], w[0], 0))
    cay = ca.SX.eye(3) + 4 / (4 + ca.sumsqr(w)) * (w_hat + w_hat @ w_hat / 2)
    W = ca.DM(g_last).T @ ca.reshape(g, 3, 3)
    C = ca.solve(W + ca.SX.eye(3), 2 * (W - ca.SX.eye(3)))
    return (ca.Function("L_d", [a, b, h], [h * ca.sumsqr(tau / inertia) / 2]),
            ca.Function("step", [g, a, h], [ca.vec(ca.reshape(g, 3, 3) @ cay)]),
            ca.Function("end", [g], [ca.vertcat(C[2, 1], C[0, 2], C[1, 0])]),
            ca.Function("torque", [a, b, h], [tau]))


def casadi_functions(h: float, inertia: np.ndarray, g_last: np.ndarray):
    """:func:`timed_casadi_functions` at the step ``h``: (L_d(ξ_w, ξ_{w+1}), step(g, ξ),
    end(g), torque(ξ_w, ξ_{w+1})), the expressions inlined (SX)."""
    L_d, step, end, torque = timed_casadi_functions(inertia, g_last)
    a, b, g = ca.SX.sym("a", 3), ca.SX.sym("b", 3), ca.SX.sym("g", 9)
    return (ca.Function("L_d", [a, b], [L_d(a, b, h)]),
            ca.Function("step", [g, a], [step(g, a, h)]), end,
            ca.Function("torque", [a, b], [torque(a, b, h)]))


def ipopt_solver(N: int):
    """The discrete problem of §3.3.4 as an NLP for IPOPT (the formulation of
    tests/test_independent_optimum.py): minimise Σ_{w=0}^{N−2} L_d(ξ_w, ξ_{w+1}) over
    ξ_1 … ξ_{N−2} (ξ_0, ξ_{N−1} fixed by g_0, g_1 and g_{N−1}, g_N) subject to
    vee cay⁻¹(g_{N−1}ᵀ g_1 cay(hξ̂_1)⋯cay(hξ̂_{N−2})) = 0. The product is lifted, as in
    multiple shooting, to unknowns g_2 … g_{N−2} with g_{k+1} = g_k cay(hξ̂_k): these fix
    the g_k uniquely from the ξ (same feasible ξ, same cost, same discrete problem) and
    keep the KKT matrix sparse. Returns (solver, x0 from symvi's initial path)."""
    from symvi._runtime.core.paths import initial_path

    model, h = get(RIGID), T / N
    start, end = (np.asarray(a, float) for a in (model.example.start, model.example.end))
    p = {str(s): v for s, v in model.parameters}
    L_d, step, end_defect, _ = casadi_functions(h, np.array([p["I1"], p["I2"], p["I3"]]), end[0])
    X, G = ca.SX.sym("xi", 3, N - 2), ca.SX.sym("g", 9, N - 3)
    xi = ca.horzcat(ca.DM(increment(*start, h)), X, ca.DM(increment(*end, h)))
    cost = ca.sum2(L_d.map(N - 1)(xi[:, :-1], xi[:, 1:]))
    following = step.map(N - 2)(ca.horzcat(ca.DM(start[1].flatten(order="F")), G), X)
    constraints = ca.vertcat(ca.vec(following[:, :-1] - G), end_defect(following[:, -1]))
    solver = ca.nlpsol("ipopt", "ipopt", dict(x=ca.vertcat(ca.vec(X), ca.vec(G)), f=cost,
                                              g=constraints),
                       {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                        "ipopt.tol": 1e-10})
    module = compile_model(model, BUILD)
    path = initial_path(module.model, start, end, N, None, module.model.params(), h)
    g = path.g.reshape(-1, 3, 3)[2:-2].transpose(0, 2, 1).reshape(-1)   # column-major
    return solver, np.concatenate([path.f[1:-1].reshape(-1), g])


def ipopt_baseline(symvi_rows: dict) -> dict:
    """Time IPOPT at IPOPT_SIZES; print its cost against symvi's. {N: solve seconds}."""
    print(f"\nbaseline: CasADi {ca.__version__} + IPOPT (MUMPS), the same discrete problem "
          f"(§3.3.4), exact Hessian, tol 1e-10, from symvi's initial path; set-up not timed")
    seconds = {}
    for N in IPOPT_SIZES:
        if seconds and 10 * max(seconds.values()) > 60.0:
            print(f"  N = {N:>9,}: skipped (predicted over a minute)")
            continue
        began = time.perf_counter()
        solver, x0 = ipopt_solver(N)
        build = time.perf_counter() - began
        once = best_time(lambda: solver(x0=x0, lbg=0, ubg=0), 1)
        seconds[N] = min(once, best_time(lambda: solver(x0=x0, lbg=0, ubg=0),
                                         repeats(once) - 1))
        solution, stats = solver(x0=x0, lbg=0, ubg=0), solver.stats()
        symvi, cost = symvi_rows[N][1], float(solution["f"])
        if isinstance(symvi, str):
            print(f"  N = {N:>9,}: IPOPT cost {cost:.12f}; symvi's {symvi}")
            continue
        relative = (cost - symvi["cost"]) / abs(symvi["cost"])
        print(f"  N = {N:>9,}: set-up {build:6.1f} s; solve {seconds[N] * 1e3:9.2f} ms, "
              f"{stats['iter_count']} iterations, {stats['return_status']}; cost "
              f"{cost:.12f}, relative difference from symvi's {relative:+.1e}"
              f"{'' if abs(relative) <= 1e-8 else '  (DISAGREES beyond 1e-8)'}")
        print(f"      symvi's total solve {symvi['seconds'] * 1e3:.2f} ms; IPOPT's over "
              f"symvi's: {seconds[N] / symvi['seconds']:.1f}")
    return seconds


def splu_baseline(per_iteration: dict) -> dict:
    """The SuperLU baseline's time per iteration on rigid_body_oc over symvi's."""
    module, ratios = compile_model(get(RIGID), BUILD), {}
    print("\nbaseline: the same Newton iteration, SuperLU instead of banded LU (rigid_body_oc)")
    for N in SPLU_SIZES:
        start, end, _ = boundary(RIGID, N)
        t = best_time(newton_iteration(module, start, end, N, sparse=True), REPEATS)
        ratios[N] = t / per_iteration[N]
        print(f"  N = {N:>9,}: {t * 1e3:9.3f} ms per iteration, {ratios[N]:.2f}× symvi's")
    return ratios


def main() -> None:
    rigid = scale_run(RIGID)
    richardson(rigid)
    scale_run(SPLINE)
    splu = splu_baseline({N: row[0] for N, row in rigid.items()})
    ipopt = ipopt_baseline(rigid) if ca is not None else None
    if ipopt is None:
        print("\nbaseline CasADi + IPOPT skipped: casadi is not importable "
              "(install it with pip install '.[bench]')")
    module = compile_model(get(RIGID), BUILD)
    start, end, _ = boundary(RIGID, 1_000)
    total = best_time(lambda: module.solve_bvp(start, end, 1_000, T / 1_000), repeats(0.01))
    print(f"\ntotal solve N = 1,000: {total * 1e3:.2f} ms (target ≤ 5 ms)")
    if ipopt is None:
        print(f"ratio: {splu[SPLU_SIZES[-1]]:.2f}")
    else:
        print(f"ratio: {total / ipopt[1_000]:.3f}")


if __name__ == "__main__":
    main()
