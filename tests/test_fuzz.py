"""Seeded fuzzing of the generated entry points (issue 18): extreme magnitudes and odd types
for ``integrate`` and ``solve_bvp`` of three bundled models (pair groupoid of first and
second order, an action groupoid with a group factor).

Every case must end in a result or a ``ValueError``/``MemoryError`` with a message — no
crash, no hang, no other exception — and a result that says SUCCESS must be finite
everywhere. The cases run in a child process, so that a crash names its case.
"""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

CASES = 300

CHILD = textwrap.dedent(r"""
    import json, sys, time
    import numpy as np
    sys.path.insert(0, sys.argv[1])
    import importlib
    CASES, SEED = int(sys.argv[2]), int(sys.argv[3])

    VALID = {
        "pendulum": dict(initial=[[1.0], [1.01]], start=[[0.0]], end=[[1.0]], h=0.01),
        "cubic_spline": dict(initial=[[0.0, 1.0], [-0.099, 0.98], [-0.192, 0.92],
                                      [-0.273, 0.82]],
                             start=[[0.0, 0.0], [0.1, 0.0]], end=[[1.0, 1.0], [1.1, 1.0]],
                             h=0.05),
        "heavy_top": dict(initial=([0.0, 0.6, 0.8], [[0.5, 0.3, 2.0]]),
                          start=([[0.0, 0.6, 0.8]], [np.eye(3)]),
                          end=([[0.0, 0.6, 0.8]], [np.eye(3)]), h=0.01),
    }
    MAGNITUDES = [0.0, 1e-300, 5e-324, 1e-150, 1e150, 1e300, 1.7e308, -1e300, -1e-300]
    ODD = ["abc", None, True, 3 + 4j, object(), {}, [], [[1.0], [1.0, 2.0]],
           np.array([["a"], ["b"]]), np.array([[True], [False]]), b"1.0", "1e3"]
    rng = np.random.default_rng(SEED)

    def pick(values):
        return values[rng.integers(len(values))]

    def scaled(value):
        # an extreme magnitude in one entry, or the whole array scaled
        if isinstance(value, tuple):
            parts = list(value)
            i = rng.integers(len(parts))
            parts[i] = scaled(parts[i])
            return tuple(parts)
        arr = np.array(value, dtype=float)
        if rng.random() < 0.5:
            arr.flat[rng.integers(arr.size)] = pick(MAGNITUDES)
        else:
            arr = arr * pick(MAGNITUDES)
        return arr

    def mutate(name, call):
        v = VALID[name]
        if call == "integrate":
            args = dict(initial=v["initial"], n_steps=int(rng.integers(0, 40)), h=v["h"])
        else:
            args = dict(start=v["start"], end=v["end"], n_steps=int(rng.integers(4, 30)),
                        h=v["h"])
        kwargs = {}
        for _ in range(rng.integers(1, 3)):
            what = pick(["array", "array", "odd", "h", "n_steps", "params", "option"])
            if what == "array":
                key = pick(["initial"] if call == "integrate" else ["start", "end"])
                args[key] = scaled(args[key])
            elif what == "odd":
                args[pick(list(args))] = pick(ODD)
            elif what == "h":
                args["h"] = pick(MAGNITUDES + [1e-3, 10.0, float("nan"), -1.0, "0.1", True])
            elif what == "n_steps":
                args["n_steps"] = pick([0, 1, 3, -1, 2.5, "10", np.int64(7), 10**12, True])
            elif what == "params":
                kwargs["params"] = pick([
                    {"__first__": pick(MAGNITUDES)}, {"__first__": pick(ODD)},
                    {"nope": 1.0}, [1.0], 7, "x", None])
            else:
                key, values = pick([
                    ("maxiter", [1, 2**31, 0, "5", 3.0, np.int32(3)]),
                    ("xtol", [0.0, 1e300, -1.0, float("nan"), "1e-3", 1e-300]),
                    ("ftol", [0.0, 1e300, float("inf"), None]),
                    ("keep_every", [1, 3, 10**6, 0, "2"]) if call == "integrate" else
                    ("guess", ["chord", "cubic", "xyz", np.zeros((1, 1)), 1e300, None])])
                kwargs[key] = pick(values)
        return args, kwargs

    def finite(result):
        fields = ("t", "x", "f", "g", "momenta", "energy", "noether", "multipliers",
                  "controls", "cost")
        for field in fields:
            value = getattr(result, field, None)
            for part in (value if isinstance(value, tuple) else (value,)):
                if part is not None and not np.all(np.isfinite(part)):
                    return field
        return None

    counts = {"success": 0, "failure": 0, "refused": 0}
    slowest = 0.0
    for case in range(CASES):
        name = pick(list(VALID))
        call = pick(["integrate", "solve_bvp"])
        mod = importlib.import_module(name)
        args, kwargs = mutate(name, call)
        params = kwargs.get("params")
        if isinstance(params, dict) and "__first__" in params:
            kwargs["params"] = {mod.model.parameter_names[0]: params["__first__"]} \
                if mod.model.parameter_names else {"nope": params["__first__"]}
        print(json.dumps({"case": case, "model": name, "call": call,
                          "args": repr(args)[:300], "kwargs": repr(kwargs)[:200]}), flush=True)
        began = time.perf_counter()
        try:
            result = getattr(mod, call)(*args.values(), **kwargs)
        except (ValueError, MemoryError) as exc:
            assert str(exc), f"case {case}: {type(exc).__name__} without a message"
            counts["refused"] += 1
        else:
            bad = finite(result) if result.success else None
            assert bad is None, f"case {case}: SUCCESS with non-finite {bad}: {result.message}"
            counts["success" if result.success else "failure"] += 1
        slowest = max(slowest, time.perf_counter() - began)
    print("SUMMARY " + json.dumps(counts | {"slowest": slowest}), flush=True)
""")


@pytest.mark.parametrize("seed", [20261125])
def test_fuzzed_arguments_never_crash_hang_or_succeed_non_finite(compiled, build_dir, seed):
    for name in ("pendulum", "cubic_spline", "heavy_top"):
        compiled(name)
    proc = subprocess.run([sys.executable, "-c", CHILD, str(build_dir), str(CASES), str(seed)],
                          capture_output=True, text=True, timeout=300)
    lines = proc.stdout.strip().splitlines()
    last = lines[-1] if lines else ""
    assert proc.returncode == 0, f"last case: {last}\n{proc.stderr[-3000:]}"
    summary = json.loads(last.removeprefix("SUMMARY "))
    print(f"\nfuzz: {summary}")
    # the mix exercises all three outcomes, and no case hangs
    assert min(summary["success"], summary["failure"], summary["refused"]) >= 10, summary
    assert summary["slowest"] < 10.0
    assert sum(np.array([summary[k] for k in ("success", "failure", "refused")])) == CASES
