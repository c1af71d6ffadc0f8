"""The run time in parts (issue 49, item 5): ``_runtime/core/`` ← ``step/`` ← ``bvp/`` ←
``bounded/``, and a package imports what its model uses.

A package whose model is only stepped never loads the whole-trajectory Newton, the bounded
solve or SciPy — numpy and cffi are all it needs; a bounded model's package loads both
parts on its first solve. Each run in a fresh process, from the session's build, the way a
user imports a package (neither SymPy nor symvi importable).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np

from symvi.models import get

CHILD = textwrap.dedent("""
    import sys
    sys.modules["sympy"] = None
    sys.modules["symvi"] = None
    import importlib, json
    spec = json.loads(sys.argv[1])
    sys.path.insert(0, spec["dir"])
    mod = importlib.import_module(spec["name"])
    parts = lambda: sorted({m.split(".")[2] for m in sys.modules
                            if m.startswith(mod.__name__ + "._runtime.")} - {"compiled"})
    imported = parts()
    if "start" in spec:
        r = mod.solve_bvp(spec["start"], spec["end"], spec["n_steps"], spec["h"])
    else:
        r = mod.integrate(spec["initial"], spec["n_steps"], spec["h"])
    print(json.dumps({"success": bool(r.success), "status": str(r.status),
                      "imported": imported, "after": parts(),
                      "scipy": any(m.split(".")[0] == "scipy" for m in sys.modules),
                      "batch": mod.__name__ + "._runtime.step.batch" in sys.modules,
                      "threads": "concurrent.futures" in sys.modules}))
""")


def as_list(value):
    """Arrays (tuples of arrays for (x, g) data) as JSON lists; None as null."""
    if isinstance(value, tuple):
        return [as_list(v) for v in value]
    return None if value is None else np.asarray(value, dtype=float).tolist()


def run(build_dir, name: str, spec: dict) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    proc = subprocess.run([sys.executable, "-c", CHILD,
                           json.dumps({"dir": str(build_dir), "name": name} | spec)],
                          capture_output=True, text=True, env=env, cwd=str(build_dir),
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_a_stepped_model_loads_neither_bvp_bounded_nor_scipy(build_dir, compiled):
    """Pendulum (no whole-trajectory solve): imported and integrated, its package has
    loaded ``core/`` and ``step/`` only, and no SciPy."""
    name = "pendulum"
    compiled(name)
    example = get(name).example
    out = run(build_dir, name, {"initial": as_list(example.initial),
                                "n_steps": 200, "h": float(example.h)})
    assert out["success"], out
    assert out["imported"] == out["after"] == ["core", "step"], out
    assert not out["scipy"]
    # nor the batch calls and their thread pool (issue 54: the first integrate's imports)
    assert not out["batch"] and not out["threads"], out


def test_a_bounded_model_loads_its_parts_on_its_first_solve(build_dir, compiled):
    """A bounded optimal-control problem: its import loads no solver part; its first
    ``solve_bvp`` loads ``bvp/`` and ``bounded/`` (and SciPy), and succeeds."""
    name = "spacecraft_slew"
    compiled(name)
    example = get(name).example
    assert example.whole_trajectory
    out = run(build_dir, name, {"start": as_list(example.start), "end": as_list(example.end),
                                "n_steps": int(example.n_steps), "h": float(example.h)})
    assert out["success"], out
    assert out["imported"] == ["core", "step"], out
    assert out["after"] == ["bounded", "bvp", "core", "step"], out
    assert out["scipy"]
