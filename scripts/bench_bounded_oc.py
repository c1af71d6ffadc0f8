"""Torque-limited slew: symvi's interior-point whole-trajectory Newton against CasADi + IPOPT.

The bundled ``spacecraft_slew`` (rigid body on SO(3), rest to rest through a quarter turn
about (1,1,1)/√3 in T = 1, min ½∫|τ/I|², |τ_i| ≤ τ_max = 11 and the rate limit
|Ω_i| ≤ ω_max = 10, inactive, issue 21) at N = 1000, in one run:

* symvi: ``solve_bvp`` from its default guess (the model is compiled first, cached; the
  symbolic compile is excluded), best of as many solves as fit in about a second;
* IPOPT (when CasADi is importable: ``pip install '.[bench]'``): the same discrete
  problem — L_d(ξ_w, ξ_{w+1}) = h·½|τ_w/I|² with Ω = (ξ_w+ξ_{w+1})/2, Ω̇ = (ξ_{w+1}−ξ_w)/h,
  τ_w = IΩ̇ + Ω×IΩ, the Cayley reconstruction lifted to unknown configurations (the
  functions of ``bench_bvp.py``), and the bounds −τ_max ≤ τ_w ≤ τ_max and
  −ω_max ≤ (ξ_w+ξ_{w+1})/2 ≤ ω_max as constraint bounds — with exact Hessian, MUMPS,
  tol 1e-10 and no bound relaxation (IPOPT relaxes bounds by 1e-8 relative by default,
  which lowered its cost by 3e-9 relative), from symvi's initial path; set-up excluded,
  ``solver(...)`` timed likewise.

Printed: both costs (they must agree to 1e-8), iteration counts, solve times, the active
windows, and last ``ratio: <symvi / IPOPT solve time>`` (target ≤ 0.2; without CasADi
the line is ``ratio: nan``). BLAS threads are pinned to 1 (by importing ``bench_step``).

Run: ``python scripts/bench_bounded_oc.py`` (builds into the repository's ``generated/``).
"""
from __future__ import annotations

import bench_step  # noqa: F401  (first: pins BLAS threads and makes symvi importable)

import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from bench_bvp import casadi_functions, increment  # noqa: E402
from bench_step import best_time  # noqa: E402
from symvi.build import compile_model  # noqa: E402
from symvi.models import get  # noqa: E402

try:
    import casadi as ca
except ImportError:
    ca = None

NAME, N, T, TAU_MAX, OMEGA_MAX = "spacecraft_slew", 1000, 1.0, 11.0, 10.0
BUILD = Path(__file__).resolve().parent.parent / "generated"


def repeats(once: float, seconds: float = 1.0) -> int:
    return max(1, min(200, int(seconds / max(once, 1e-6))))


def symvi_solve(module, start, end):
    h, params = T / N, dict(tau_max=TAU_MAX, omega_max=OMEGA_MAX)
    result = module.solve_bvp(start, end, N, h, params=params)
    once = best_time(lambda: module.solve_bvp(start, end, N, h, params=params), 1)
    seconds = min(once, best_time(lambda: module.solve_bvp(start, end, N, h, params=params),
                                  repeats(once)))
    return result, seconds


def ipopt_problem(module, start, end, inertia):
    """(solver, x0, bounds of g) of the bounded discrete problem (module docstring)."""
    from symvi._runtime.core.paths import initial_path

    h = T / N
    L_d, step, end_defect, torque = casadi_functions(h, inertia, end[0])
    X, G = ca.SX.sym("xi", 3, N - 2), ca.SX.sym("g", 9, N - 3)
    xi = ca.horzcat(ca.DM(increment(*start, h)), X, ca.DM(increment(*end, h)))
    cost = ca.sum2(L_d.map(N - 1)(xi[:, :-1], xi[:, 1:]))
    torques = ca.vec(torque.map(N - 1)(xi[:, :-1], xi[:, 1:]))
    rates = ca.vec((xi[:, :-1] + xi[:, 1:]) / 2)
    following = step.map(N - 2)(ca.horzcat(ca.DM(start[1].flatten(order="F")), G), X)
    equalities = ca.vertcat(ca.vec(following[:, :-1] - G), end_defect(following[:, -1]))
    solver = ca.nlpsol("ipopt", "ipopt", dict(x=ca.vertcat(ca.vec(X), ca.vec(G)), f=cost,
                                              g=ca.vertcat(equalities, torques, rates)),
                       {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                        "ipopt.tol": 1e-10, "ipopt.bound_relax_factor": 0.0})
    count = equalities.shape[0]
    limits = np.r_[TAU_MAX * np.ones(torques.shape[0]), OMEGA_MAX * np.ones(rates.shape[0])]
    lbg, ubg = np.r_[np.zeros(count), -limits], np.r_[np.zeros(count), limits]
    path = initial_path(module.model, start, end, N, None,
                        module.model.params(dict(tau_max=TAU_MAX, omega_max=OMEGA_MAX)), h)
    g0 = path.g.reshape(-1, 3, 3)[2:-2].transpose(0, 2, 1).reshape(-1)   # column-major
    return solver, np.concatenate([path.f[1:-1].reshape(-1), g0]), lbg, ubg


def main() -> None:
    model = get(NAME)
    began = time.perf_counter()
    module = compile_model(model, BUILD)
    print(f"{NAME}: N = {N}, T = {T}, τ_max = {TAU_MAX}; compiled in "
          f"{time.perf_counter() - began:.1f} s (not timed below)")
    start, end = (np.asarray(a, float) for a in (model.example.start, model.example.end))
    result, seconds = symvi_solve(module, start, end)
    active = [f"{n}: {c}" for n, c in zip(result.inequalities, result.active.sum(axis=0)) if c]
    print(f"symvi  {result.status.name}: cost {result.cost:.12f}, {result.iterations} "
          f"iterations, solve {seconds * 1e3:.1f} ms; active windows {', '.join(active)}")
    if ca is None:
        print("IPOPT  skipped: casadi is not importable (pip install '.[bench]')")
        print("ratio: nan")
        return
    p = {str(s): v for s, v in model.parameters}
    began = time.perf_counter()
    solver, x0, lbg, ubg = ipopt_problem(module, start, end,
                                         np.array([p["I1"], p["I2"], p["I3"]]))
    build = time.perf_counter() - began
    run = lambda: solver(x0=x0, lbg=lbg, ubg=ubg)   # noqa: E731
    once = best_time(run, 1)
    ipopt_seconds = min(once, best_time(run, repeats(once) - 1 or 1))
    solution, stats = run(), solver.stats()
    cost = float(solution["f"])
    relative = (cost - result.cost) / result.cost
    print(f"IPOPT  {stats['return_status']}: cost {cost:.12f}, {stats['iter_count']} "
          f"iterations, solve {ipopt_seconds * 1e3:.1f} ms (set-up {build:.1f} s); relative "
          f"difference from symvi's cost {relative:+.1e}"
          f"{'' if abs(relative) <= 1e-8 else '  (DISAGREES beyond 1e-8)'}")
    print(f"ratio: {seconds / ipopt_seconds:.3f}")


if __name__ == "__main__":
    main()
