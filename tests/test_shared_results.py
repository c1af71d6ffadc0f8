"""One result type for every generated package of a runtime (issue 19, item 5).

Each package carries a copy of ``_runtime/results.py``; the copies share the classes of
the first one imported, registered as ``symvi_runtime_results_<digest of the file>``
(see that module's docstring). So results of two packages are one class, they pickle
through that canonical module, and they unpickle in a fresh interpreter that has imported
any package of the runtime — without SymPy or symvi.
"""
from __future__ import annotations

import dataclasses
import importlib.util
import os
import pickle
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

import symvi
from symvi.models import get

RESULTS_SOURCE = Path(symvi.__file__).resolve().parent / "_runtime" / "results.py"


def step_result(compiled, name: str, n_steps: int = 20):
    example = get(name).example
    return compiled(name).integrate(example.initial, n_steps, example.h)


def spline_bvp(compiled):
    """The cubic through the ends: the whole-trajectory solve of ``cubic_spline``."""
    h, N = 0.1, 30
    q = np.array([[(k * h) ** 3 - k * h, 1 - 2 * (k * h) ** 2] for k in range(N + 1)])
    return compiled("cubic_spline").solve_bvp(start=q[:2], end=q[-2:], n_steps=N, h=h)


def assert_same(a, b) -> None:
    """Equal classes and equal fields, arrays bitwise."""
    assert type(a) is type(b)
    for field in dataclasses.fields(a):
        left, right = getattr(a, field.name), getattr(b, field.name)
        if isinstance(left, np.ndarray):
            np.testing.assert_array_equal(left, right)
            assert left.dtype == right.dtype and left.shape == right.shape
        else:
            assert left == right, field.name


def test_results_of_two_packages_are_one_class(compiled):
    pendulum, oscillator = compiled("pendulum"), compiled("harmonic_oscillator")
    a, b = step_result(compiled, "pendulum"), step_result(compiled, "harmonic_oscillator")
    assert type(a) is type(b) is pendulum.StepResult is oscillator.StepResult
    assert pendulum.BVPResult is oscillator.BVPResult
    assert pendulum.NewtonError is oscillator.NewtonError
    assert pendulum.Status is oscillator.Status
    assert a.status == b.status == oscillator.Status.SUCCESS
    assert type(spline_bvp(compiled)) is pendulum.BVPResult


def test_results_survive_a_pickle_round_trip(compiled):
    step, bvp = step_result(compiled, "pendulum"), spline_bvp(compiled)
    assert step.success and bvp.success, (step.message, bvp.message)
    for result in (step, bvp):
        assert_same(result, pickle.loads(pickle.dumps(result)))
    error = compiled("pendulum").NewtonError(step)
    again = pickle.loads(pickle.dumps(error))
    assert type(again) is type(error) and str(again) == step.message
    assert_same(again.result, step)


# A fresh interpreter where SymPy and symvi cannot be imported: unpickling first fails
# (no package of the runtime is loaded), then works once one package is imported.
CHILD = textwrap.dedent("""
    import pickle, sys
    sys.modules["sympy"] = None
    sys.modules["symvi"] = None
    folder, given, back = sys.argv[1:4]
    data = open(given, "rb").read()
    try:
        pickle.loads(data)
    except ModuleNotFoundError as exc:
        print("before import:", exc)
    else:
        raise SystemExit("unpickled before any package of the runtime was imported")
    sys.path.insert(0, folder)
    import harmonic_oscillator as package
    step, bvp = pickle.loads(data)
    assert type(step) is package.StepResult and type(bvp) is package.BVPResult
    assert step.status is package.Status.SUCCESS
    open(back, "wb").write(pickle.dumps((step, bvp)))
""")


def test_results_unpickle_in_a_fresh_process_of_another_package(compiled, build_dir, tmp_path):
    compiled("harmonic_oscillator")    # the child imports it from the shared build folder
    step, bvp = step_result(compiled, "pendulum"), spline_bvp(compiled)
    given, back = tmp_path / "given.pickle", tmp_path / "back.pickle"
    given.write_bytes(pickle.dumps((step, bvp)))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    proc = subprocess.run([sys.executable, "-c", CHILD, str(build_dir), str(given), str(back)],
                          capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    assert proc.returncode == 0, proc.stderr
    canonical = type(step).__module__
    assert canonical.startswith("symvi_runtime_results_")
    assert f"No module named '{canonical}'" in proc.stdout
    step_back, bvp_back = pickle.loads(back.read_bytes())
    assert_same(step, step_back)
    assert_same(bvp, bvp_back)


def test_results_unpickle_in_a_fresh_process_with_symvi(compiled, tmp_path):
    """symvi's own copy of the runtime registers the canonical module when symvi is
    imported, so a process with symvi needs no generated package."""
    given = tmp_path / "given.pickle"
    given.write_bytes(pickle.dumps(step_result(compiled, "pendulum")))
    child = ("import pickle, sys, symvi\n"
             "r = pickle.loads(open(sys.argv[1], 'rb').read())\n"
             "print(type(r).__module__, r.status.name, r.x.shape)")
    proc = subprocess.run([sys.executable, "-c", child, str(given)], capture_output=True,
                          text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 0, proc.stderr
    step = step_result(compiled, "pendulum")
    assert proc.stdout.split() == [type(step).__module__, "SUCCESS", f"({len(step.x)},", "1)"]


def load_copy(tmp_path: Path, name: str, source: bytes):
    """Import ``source`` as a copy of results.py, as a package's ``_runtime`` would."""
    path = tmp_path / name / "results.py"
    path.parent.mkdir()
    path.write_bytes(source)
    spec = importlib.util.spec_from_file_location(f"{name}_results", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    try:
        spec.loader.exec_module(module)
    finally:
        del sys.modules[spec.name]
    return module


def test_only_identical_runtimes_share_their_classes(compiled, tmp_path):
    shared = compiled("pendulum").StepResult
    same = load_copy(tmp_path, "same", RESULTS_SOURCE.read_bytes())
    assert same.StepResult is shared and same.Status is compiled("pendulum").Status
    other = load_copy(tmp_path, "other", RESULTS_SOURCE.read_bytes() + b"\n# changed\n")
    try:
        assert other.CANONICAL != same.CANONICAL
        assert other.StepResult is not shared and other.StepResult.__module__ == other.CANONICAL
    finally:
        del sys.modules[other.CANONICAL]


def test_repr_is_a_short_summary(compiled):
    example = get("pendulum").example
    result = compiled("pendulum").integrate(example.initial, 10**5, example.h)
    text = repr(result)
    assert len(text) < 400, text
    final = np.array2string(result.x[-1], precision=6, separator=", ")
    assert text.startswith("<StepResult SUCCESS: 'integrated 100000 steps (the first "
                           "given)'; 100001 nodes, t = 1000; final x = ")
    assert f"x = {final}" in text
    bvp = repr(spline_bvp(compiled))
    assert bvp.startswith("<BVPResult SUCCESS: 'converged in ") and "30 steps, 31 nodes" in bvp
    assert len(bvp) < 400, bvp


def test_repr_of_a_failure_shortens_its_message(compiled):
    mod = compiled("pendulum")
    failed = mod.integrate([[0.0], [3.0]], 10, 5.0)     # a step of 5 s: no convergence
    assert failed.status == mod.Status.MAX_ITERATIONS and len(failed.message) > 100
    text = repr(failed)
    assert text.startswith(f"<StepResult MAX_ITERATIONS: {failed.message[:99]!r}"[:-1])
    assert "…" in text and "; 2 nodes, t = 5;" in text and len(text) < 400, text


def test_symvi_runtime_is_one_more_copy(compiled):
    """symvi's own ``_runtime.results`` shares the packages' classes too (a process with
    symvi can unpickle without importing a package)."""
    from symvi._runtime import results
    assert results.StepResult is compiled("pendulum").StepResult
    assert sys.modules[results.CANONICAL].StepResult is results.StepResult
