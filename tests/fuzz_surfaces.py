"""The child process of tests/test_fuzz_surfaces.py (issue 48): seeded fuzzing of the
batch calls (local and on Dask), continuation, States, order-k runs, declarations and
the command line, each SUCCESS verified against an independent solution.

Run as ``python fuzz_surfaces.py BUILD_DIR CASES SEED SCRATCH``. Each case prints one JSON
line before it runs (so that a crash names its case) and the last line is ``SUMMARY
{...}``. A case ends in a result or a refusal — ``ValueError``, ``TypeError`` or
``MemoryError`` with a message, or the command line's exit 2 with one line — and a
result that says SUCCESS must agree with the independent solution:

- harmonic_oscillator (midpoint rule, linear): each stepped node is the three-term
  recurrence of its discrete Euler–Lagrange equation from the two before it, the first
  from the discrete Legendre transform of the State, and a whole-trajectory solve is the
  solution of that tridiagonal linear system (numpy);
- minimum_jerk (central<3>): each stepped node is the sixth difference = 0 from the six
  before it;
- cubic_spline from States: the fourth difference = 0 makes the exact discrete solution
  the cubic whose two half-step samples around t = 0 and t = T have the States' mean and
  slope (four linear conditions per coordinate).
"""
from __future__ import annotations

import contextlib
import importlib
import io
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

BUILD, CASES, SEED, SCRATCH = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), Path(sys.argv[4])
sys.path.insert(0, BUILD)
rng = np.random.default_rng(SEED)
EPS = float(np.finfo(float).eps)
ODD = ["abc", None, True, 3 + 4j, object(), {}, [], 2.5, -1, 0, "3", np.nan, b"1"]
REFUSALS = (ValueError, TypeError, MemoryError)


def pick(values):
    return values[rng.integers(len(values))]


def per_case(value, count: int) -> np.ndarray:
    """A scalar or per-case argument that the call accepted, as ``count`` floats."""
    return np.broadcast_to(np.asarray(value, dtype=float), (count,))


class FalseSuccess(AssertionError):
    """A result said SUCCESS and the independent solution disagrees."""


def require(condition: bool, what: str) -> None:
    if not condition:
        raise FalseSuccess(what)


# --- independent solutions -------------------------------------------------------------

def oscillator_coefficients(m: float, k: float, h: float) -> tuple[float, float]:
    """a, b of the midpoint DEL  −a q_{j+1} + b q_j − a q_{j−1} = 0  of L = m v²/2 − k x²/2."""
    return m / h + h * k / 4, 2 * m / h - h * k / 2


def check_oscillator_path(x: np.ndarray, m: float, k: float, h: float, xtol: float,
                          state=None) -> None:
    """Every node from the two before it (and the first step from the State's Legendre
    transform), each to the step's tolerance xtol·(1 + |q|) plus rounding."""
    q = x[:, 0]
    a, b = oscillator_coefficients(m, k, h)
    predicted = (b * q[1:-1] - a * q[:-2]) / a
    slack = 10 * xtol * (1 + np.abs(q[2:])) + 1e3 * EPS * (np.abs(b / a * q[1:-1]) + np.abs(q[:-2]))
    require(bool(np.all(np.abs(predicted - q[2:]) <= slack)),
            f"oscillator path off its recurrence by {np.abs(predicted - q[2:]).max(initial=0.0):.3g}")
    if state is not None:
        x0, v0 = state
        q1 = (m * v0 + x0 * (m / h - h * k / 4)) / a
        require(abs(q[0] - x0) <= 1e3 * EPS * (1 + abs(x0)), "first node is not the State's")
        require(abs(q1 - q[1]) <= 10 * xtol * (1 + abs(q1)) + 1e3 * EPS * (abs(m * v0 / a) + abs(x0)),
                f"first step off the Legendre transform by {abs(q1 - q[1]):.3g}")


def oscillator_bvp(q0: float, qN: float, N: int, m: float, k: float,
                   h: float) -> tuple[np.ndarray, float]:
    """The exact discrete path between q_0 and q_N, and its system's condition number."""
    a, b = oscillator_coefficients(m, k, h)
    A = np.diag(np.full(N - 1, b)) - a * (np.eye(N - 1, k=1) + np.eye(N - 1, k=-1))
    rhs = np.zeros(N - 1)
    rhs[0] += a * q0
    rhs[-1] += a * qN
    inner = np.linalg.lstsq(A, rhs, rcond=None)[0] if N > 1 else np.zeros(0)
    return np.concatenate([[q0], inner, [qN]]), float(np.linalg.cond(A)) if N > 1 else 1.0


def check_oscillator_solve(result, q0, qN, N, m, k, h, xtol) -> None:
    """Within xtol·(1 + |q|) of the exact discrete path, plus what the reference's own
    conditioning leaves of it."""
    exact, condition = oscillator_bvp(q0, qN, N, m, k, h)
    error = float(np.abs(result.x[:, 0] - exact).max())
    scale = 1 + np.abs(exact).max()
    require(error <= xtol * scale + 10 * condition * EPS * scale,
            f"solve {error:.3g} off the exact discrete path (xtol {xtol}, κ {condition:.3g})")


def check_jerk_path(x: np.ndarray, xtol: float) -> None:
    """Every node from the six before it: the sixth difference vanishes."""
    c = np.array([-1.0, 6.0, -15.0, 20.0, -15.0, 6.0])
    for j in range(6, len(x)):
        window = x[j - 6:j]
        predicted = c @ window
        slack = 10 * xtol * (1 + np.abs(x[j])) + 1e3 * EPS * (np.abs(c) @ np.abs(window))
        require(bool(np.all(np.abs(predicted - x[j]) <= slack)),
                f"jerk node {j} off its recurrence by {np.abs(predicted - x[j]).max():.3g}")


def spline_from_states(x0, v0, x1, v1, T, h):
    """Nodes at (j − ½)h, j = 0 … N + 1, of the cubic fixed by the boundary States."""
    def rows(t):
        lo, hi = t - h / 2, t + h / 2
        mean = [(lo**p + hi**p) / 2 for p in range(4)]
        slope = [(hi**p - lo**p) / h for p in range(4)]
        return [mean, slope]
    A = np.array(rows(0.0) + rows(T))
    coefficients = np.linalg.solve(A, np.stack([x0, v0, x1, v1]))
    t = (np.arange(round(T / h) + 2) - 0.5) * h
    return np.stack([t**p for p in range(4)], axis=1) @ coefficients


# --- the surfaces ----------------------------------------------------------------------

def oscillator_batch_args(B: int):
    """A valid batch for harmonic_oscillator: States, steps, stiffnesses."""
    state = dict(x=rng.uniform(-2, 2, (B, 1)), v=rng.uniform(-2, 2, (B, 1)))
    h = rng.uniform(0.01, 0.2, B) if rng.random() < 0.5 else float(rng.uniform(0.01, 0.2))
    k = rng.uniform(0.1, 5.0, B)
    return state, h, k


def mutate(args: dict, keys: list[str]) -> str:
    """Break one or two arguments; returns what was done."""
    done = []
    for _ in range(pick([0, 0, 1, 2])):
        key = pick(keys)
        value = args[key]
        choice = rng.integers(4)
        if choice == 0:
            args[key] = pick(ODD)
        elif choice == 1 and isinstance(value, np.ndarray) and value.size:
            value = value.copy()
            value.flat[rng.integers(value.size)] = pick([np.nan, np.inf, 1e300, -1e300, 0.0])
            args[key] = value
        elif choice == 2 and isinstance(value, np.ndarray) and value.ndim:
            args[key] = value[: max(len(value) - pick([1, 2]), 0)]      # a size mismatch
        else:
            args[key] = pick([0, -2, 2.5, "7", 10**9, np.int64(7), True])
        done.append(key)
    return ",".join(done) or "valid"


def case_integrate_many(mod, client):
    B = int(pick([1, 2, 5]))
    state, h, k = oscillator_batch_args(B)
    args = dict(x=state["x"], v=state["v"], n_steps=int(rng.integers(1, 60)), h=h, k=k,
                xtol=pick([1e-12, 1e-9, 1e-6]), workers=pick([1, 2]))
    if client is not None:
        args["chunk"] = pick([1, 2, 3])
    what = mutate(args, list(args))
    kwargs = dict(params={"k": args["k"]}, xtol=args["xtol"])
    if client is None:
        kwargs["workers"] = args["workers"]
        call = lambda: mod.integrate_many(mod.State(x=args["x"], v=args["v"]),  # noqa: E731
                                          args["n_steps"], args["h"], **kwargs)
    else:
        import symvi.dask
        call = lambda: symvi.dask.integrate_many(  # noqa: E731
            client, mod, mod.State(x=args["x"], v=args["v"]), args["n_steps"], args["h"],
            chunk=args["chunk"], **kwargs)
    return what, call, lambda result: verify_integrate_many(result, args)


def verify_integrate_many(result, args) -> None:
    B = len(result)
    require(B >= 1, "a batch result of no trajectory")
    H, K = per_case(args["h"], B), per_case(args["k"], B)
    for b in range(B):
        if result.statuses[b] != 0:
            continue
        run = result[b]
        check_oscillator_path(run.x, 1.0, K[b], H[b], args["xtol"],
                              (float(args["x"][b, 0]), float(args["v"][b, 0])))
    if result.success:
        require(bool(result.succeeded.all()), "batch SUCCESS with a failed trajectory")


def case_solve_bvp_many(mod, client):
    B = int(pick([1, 2, 4]))
    N = int(rng.integers(2, 80))
    args = dict(starts=rng.uniform(-2, 2, (B, 1, 1)), ends=rng.uniform(-2, 2, (B, 1, 1)),
                n_steps=N, h=rng.uniform(0.01, 0.3, B), k=rng.uniform(0.1, 30.0, B),
                xtol=pick([1e-9, 1e-6, 1e-12]), maxiter=pick([1, 2, 100]))
    if client is not None:
        args["chunk"] = pick([1, 2, 5])
    what = mutate(args, list(args))
    options = dict(params={"k": args["k"]}, xtol=args["xtol"], maxiter=args["maxiter"])
    if client is None:
        call = lambda: mod.solve_bvp_many(args["starts"], args["ends"], args["n_steps"],  # noqa: E731
                                          args["h"], **options)
    else:
        import symvi.dask
        call = lambda: symvi.dask.solve_bvp_many(  # noqa: E731
            client, mod, args["starts"], args["ends"], args["n_steps"], args["h"],
            chunk=args["chunk"], **options)

    def verify(result):
        require(len(result) >= 1, "a batch of no solve")
        H, K = per_case(args["h"], len(result)), per_case(args["k"], len(result))
        for b, solve in enumerate(result.results):
            if solve.success:
                check_oscillator_solve(solve, float(args["starts"][b, 0, 0]),
                                       float(args["ends"][b, 0, 0]), args["n_steps"], 1.0,
                                       K[b], H[b], args["xtol"])
        if result.success:
            require(bool(result.succeeded.all()), "batch SUCCESS with a failed solve")
    return what, call, verify


def case_continuation(mod, client):
    K = int(pick([1, 3, 6]))
    args = dict(start=rng.uniform(-2, 2, (1, 1)), end=rng.uniform(-2, 2, (1, 1)),
                n_steps=int(rng.integers(2, 60)), h=float(rng.uniform(0.01, 0.3)),
                k=np.linspace(rng.uniform(0.1, 2), rng.uniform(0.1, 40), K),
                xtol=pick([1e-9, 1e-7]), maxiter=pick([1, 100]))
    what = mutate(args, list(args))
    call = lambda: mod.continuation(args["start"], args["end"], args["n_steps"], args["h"],  # noqa: E731
                                    {"k": args["k"]}, xtol=args["xtol"],
                                    maxiter=args["maxiter"])

    def verify(result):
        require(len(result) >= 1, "a continuation of no point")
        K = per_case(args["k"], len(result))
        for j, solve in enumerate(result.results):
            if solve.success:
                check_oscillator_solve(solve, float(args["start"][0, 0]),
                                       float(args["end"][0, 0]), args["n_steps"], 1.0,
                                       K[j], float(args["h"]), args["xtol"])
    return what, call, verify


def case_order_k(mod, client):
    t = np.arange(6) * 0.1
    coefficients = rng.standard_normal((6, 3))
    args = dict(initial=np.stack([np.polyval(c, t) for c in coefficients.T], axis=1),
                n_steps=int(rng.integers(5, 30)), h=0.1, xtol=pick([1e-12, 1e-8]),
                quantities=pick([True, False]))
    what = mutate(args, list(args))
    call = lambda: mod.integrate(args["initial"], args["n_steps"], args["h"],  # noqa: E731
                                 xtol=args["xtol"], quantities=args["quantities"])

    def verify(result):
        check_jerk_path(result.x, args["xtol"])
        E = len(result.f)
        if args["quantities"] is True:
            states = E - 1 if E >= 7 else E - 4
            require(result.momenta is not None and len(result.momenta) == states,
                    f"{E} elements but {None if result.momenta is None else len(result.momenta)} states")
    return what, call, verify


def case_states(mod, client):
    N = int(rng.integers(3, 60))
    T = float(rng.uniform(0.2, 3.0))
    x0, v0, x1, v1 = rng.uniform(-2, 2, (4, 2))
    args = dict(x0=x0, v0=v0, x1=x1, v1=v1, n_steps=N, T=T, xtol=pick([1e-9, 1e-6]),
                maxiter=pick([1, 100]))
    what = mutate(args, list(args))
    call = lambda: mod.solve_bvp(mod.State(x=args["x0"], v=args["v0"]),  # noqa: E731
                                 mod.State(x=args["x1"], v=args["v1"]), args["n_steps"],
                                 T=args["T"], xtol=args["xtol"], maxiter=args["maxiter"])

    def verify(result):
        h = float(args["T"]) / int(args["n_steps"])
        ends = [per_case(args[key], 2) for key in ("x0", "v0", "x1", "v1")]
        exact = spline_from_states(*ends, float(args["T"]), h)
        error = float(np.abs(result.x - exact).max())
        require(error <= args["xtol"] * (1 + np.abs(exact).max()) + 1e-12,
                f"States solve {error:.3g} off the exact cubic")
    return what, call, verify


SURFACES = {"integrate_many": ("harmonic_oscillator", case_integrate_many, False),
            "dask_integrate_many": ("harmonic_oscillator", case_integrate_many, True),
            "solve_bvp_many": ("harmonic_oscillator", case_solve_bvp_many, False),
            "dask_solve_bvp_many": ("harmonic_oscillator", case_solve_bvp_many, True),
            "continuation": ("harmonic_oscillator", case_continuation, False),
            "order_k": ("minimum_jerk", case_order_k, False),
            "states": ("cubic_spline", case_states, False)}


def refused_at_run_time(value) -> bool:
    """What a run-time number argument refuses: text, truth values, complex numbers,
    containers and other objects (sympy and numpy reals are numbers)."""
    import sympy as sp
    if isinstance(value, (bool, np.bool_, str, bytes, complex)) or value is None:
        return True
    return not isinstance(value, (int, float, np.integer, np.floating, sp.Number)) \
        or not np.isfinite(float(value))


def declaration_case():
    """A declaration with one odd input: refused with a message, or a Model — and a value
    the run time refuses is refused here too."""
    import sympy as sp
    from symvi import Model, PairGroupoid
    from symvi.mechanics import from_lagrangian
    G = PairGroupoid("x")
    (x,), (v,) = G.q, G.qdot
    m = sp.Symbol("m", positive=True)
    which = pick(["default", "derivative", "from_lagrangian", "time_cost"])
    value = pick(ODD + ["1.0", sp.Integer(3), np.int64(2), 1.5, sp.Rational(1, 2)])
    if which == "default":
        return which, value, lambda: Model(name="d", groupoid=G, lagrangian=m * v**2 / 2,
                                           discretisation="midpoint", parameters={m: value})
    if which == "derivative":
        return which, value, lambda: G.derivative(value)
    if which == "from_lagrangian":
        return which, value, lambda: from_lagrangian(value, [], name="fl", parameters={})
    from symvi import SO3, optimal_control
    S = SO3()
    u = sp.symbols("u1:4", real=True)
    return which, value, lambda: optimal_control(
        name="tc", groupoid=S, lagrangian=sum(w**2 for w in S.xi) / 2,
        cost=sum(w**2 for w in u) / 2, controls=u, time_cost=value)


def cli_case():
    """A command line with one bad argument: exit 2 with one line, before any compile."""
    from symvi.cli import main
    out = SCRATCH / f"cli{rng.integers(10**9)}"
    out.mkdir()
    model = pick(["harmonic_oscillator", "no_such_model", "pendulum"])
    bad = pick([["--steps", "0"], ["--steps", "-3"], ["--h", "-1"], ["--h", "nan"],
                ["--output", str(out / "missing" / "r.npz")], ["--output", str(out)],
                ["--output", str(out / "r.xyz")], ["--plot", str(out / "missing" / "p.png")],
                ["--plot", str(out / "p.unknown")]])
    argv = ["run", model, "--build-dir", str(out / "gen")] + bad
    return argv, out, lambda: main(argv)


def run_cli(argv, out, call) -> str:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = call()
        except SystemExit as exc:
            code = exc.code
    lines = [line for line in err.getvalue().splitlines() if line.strip()]
    assert code == 2, f"{argv}: exit {code}, stderr {err.getvalue()[-500:]}"
    assert len(lines) == 1 and "Traceback" not in err.getvalue(), err.getvalue()[-500:]
    assert not (out / "gen").exists(), f"{argv}: compiled before refusing"
    return "refused"


def main() -> None:
    client = None
    counts = {"success": 0, "failure": 0, "refused": 0, "verified": 0}
    slowest = 0.0
    for case in range(CASES):
        kind = pick(list(SURFACES) + ["declaration", "cli"])
        began = time.perf_counter()
        if kind == "cli":
            argv, out, call = cli_case()
            print(json.dumps({"case": case, "surface": kind, "argv": argv}), flush=True)
            counts[run_cli(argv, out, call)] += 1
            continue
        if kind == "declaration":
            which, value, call = declaration_case()
            print(json.dumps({"case": case, "surface": kind, "which": which,
                              "value": repr(value)}), flush=True)
            try:
                call()
                assert which == "derivative" or not refused_at_run_time(value), \
                    f"case {case}: {which} = {value!r} accepted"
                counts["success"] += 1
            except REFUSALS as exc:
                assert str(exc), f"case {case}: {type(exc).__name__} without a message"
                counts["refused"] += 1
            continue
        name, make, on_dask = SURFACES[kind]
        if on_dask and client is None:
            import distributed
            cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=2,
                                               processes=False, dashboard_address=None)
            client = distributed.Client(cluster)
        mod = importlib.import_module(name)
        what, call, verify = make(mod, client if on_dask else None)
        print(json.dumps({"case": case, "surface": kind, "mutated": what}), flush=True)
        try:
            result = call()
        except REFUSALS as exc:
            assert str(exc), f"case {case}: {type(exc).__name__} without a message"
            assert what != "valid", f"case {case}: valid arguments refused: {exc}"
            counts["refused"] += 1
        else:
            if result.success:
                verify(result)
                counts["verified"] += 1
            elif hasattr(result, "results") or hasattr(result, "statuses"):
                verify(result)      # the successes inside a failed batch
            counts["success" if result.success else "failure"] += 1
        slowest = max(slowest, time.perf_counter() - began)
    if client is not None:
        client.close()
    print("SUMMARY " + json.dumps(counts | {"slowest": slowest}), flush=True)


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    main()
