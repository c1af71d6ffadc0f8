"""Results pickle by name, from symvi, without import side effects (issue 19 item 5,
issue 49 item 6).

Each generated package carries a copy of ``_runtime/core/results.py`` in a private module no
other process can import. Every class of that file pickles, through ``__reduce__``, as a
call of ``symvi._runtime.core.results``' own, which loading imports by name: so a result
loads in a fresh interpreter that runs ``import pickle`` alone (symvi installed), as
symvi's class, whatever package made it and without it. Importing a package or the file
registers nothing in ``sys.modules``; the copies' classes are distinct, and each copy
takes another's objects (the same name and fields) for its own in ``isinstance``.
"""
from __future__ import annotations

import copy
import dataclasses
import enum
import importlib.util
import json
import os
import pickle
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import symvi
from symvi._runtime.core import results as home
from symvi.models import get

RESULTS_SOURCE = Path(symvi.__file__).resolve().parent / "_runtime" / "core" / "results.py"


def step_result(compiled, name: str, n_steps: int = 20):
    example = get(name).example
    return compiled(name).integrate(example.initial, n_steps, example.h)


def spline_bvp(compiled):
    """The cubic through the ends: the whole-trajectory solve of ``cubic_spline``."""
    h, N = 0.1, 30
    q = np.array([[(k * h) ** 3 - k * h, 1 - 2 * (k * h) ** 2] for k in range(N + 1)])
    return compiled("cubic_spline").solve_bvp(start=q[:2], end=q[-2:], n_steps=N, h=h)


def states_bvp(compiled):
    """``cubic_spline`` between two States: a BVPResult holding a State of arrays."""
    mod = compiled("cubic_spline")
    return mod.solve_bvp(mod.State(x=[0.0, 0.0], v=[0.0, 1.0]),
                         mod.State(x=[1.0, 0.0], v=[0.0, 0.0]), 20, T=1.0)


def batch_result(compiled):
    """Three pendulum runs, the last stopped by a step of 5 s (no convergence): NaN
    padding and unequal lengths."""
    start = np.array([[[0.0], [0.1]], [[0.5], [0.5]], [[0.0], [3.0]]])
    return compiled("pendulum").integrate_many(start, 30, np.array([0.1, 0.1, 5.0]),
                                               workers=1, progress=False)


def states_batch(compiled):
    mod = compiled("cubic_spline")
    starts = mod.State(x=np.zeros((2, 2)), v=np.array([[0.0, 1.0], [1.0, 0.0]]))
    ends = mod.State(x=np.array([[1.0, 0.0], [0.0, 2.0]]), v=np.zeros((2, 2)))
    return mod.solve_bvp_many(starts, ends, 20, T=1.0, workers=1, progress=False)


def assert_same(original, back) -> None:
    """``back`` is ``original`` as symvi's own classes (``symvi._runtime.core.results``) at
    every level — results, States, Statuses, nested results — with equal fields, arrays
    bitwise (NaN where NaN), of the same dtype and shape."""
    if isinstance(original, (home._Result, home.State, home.Status, home.NewtonError)):
        assert type(back) is getattr(home, type(original).__name__), type(back)
    if isinstance(original, np.ndarray):
        assert isinstance(back, np.ndarray)
        assert original.dtype == back.dtype and original.shape == back.shape
        np.testing.assert_array_equal(original, back)
    elif isinstance(original, enum.Enum):
        assert int(original) == int(back) and original.name == back.name
    elif dataclasses.is_dataclass(original):
        for field in dataclasses.fields(original):
            assert_same(getattr(original, field.name), getattr(back, field.name))
    elif isinstance(original, BaseException):
        assert str(original) == str(back)
        assert_same(original.result, back.result)
    elif isinstance(original, (tuple, list)):
        assert type(original) is type(back) and len(original) == len(back)
        for a, b in zip(original, back):
            assert_same(a, b)
    elif isinstance(original, dict):
        assert original.keys() == back.keys()
        for key in original:
            assert_same(original[key], back[key])
    else:
        assert type(original) is type(back) and original == back


def fresh_python(code: str, *args, cwd: Path) -> subprocess.CompletedProcess:
    """``code`` in a new interpreter run from ``cwd``, whose path holds the symvi these
    tests import (as installed) and nothing else of theirs: not the build folder."""
    # the folder holding the symvi package under test (results.py's parents: core,
    # _runtime, symvi, then it), ahead of an installed one
    env = os.environ | {"PYTHONPATH": str(RESULTS_SOURCE.parents[3])}
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code), *map(str, args)],
                          capture_output=True, text=True, env=env, cwd=cwd, timeout=300)


# The loading child runs `import pickle` alone; only then does it look at what it got.
LOADER = """
    import pickle, sys
    given, back = sys.argv[1:3]
    objects = pickle.loads(open(given, "rb").read())
    loaded = sorted(sys.modules)
    open(back, "wb").write(pickle.dumps(objects))

    import dataclasses, json
    def walk(o):
        yield o
        if dataclasses.is_dataclass(o):
            for f in dataclasses.fields(o):
                yield from walk(getattr(o, f.name))
        elif isinstance(o, (tuple, list)):
            for v in o:
                yield from walk(v)
        elif isinstance(o, dict):
            for v in o.values():
                yield from walk(v)
        elif hasattr(o, "result"):
            yield from walk(o.result)
    print(json.dumps({
        "classes": sorted({type(o).__module__ + "." + type(o).__qualname__ for o in walk(objects)
                           if type(o).__module__ not in ("builtins", "numpy")}),
        "packages": [m for m in loaded if m.startswith(("_symvi_", "symvi_runtime_results"))],
        "path": sys.path}))
"""


def test_results_load_in_a_fresh_process_with_import_pickle_alone(compiled, build_dir,
                                                                  tmp_path):
    """Every class a user may pickle — a StepResult, a BVPResult holding States, a
    BatchResult, a BVPBatch of States solves, a State, a Status, a NewtonError — loads in
    a new interpreter that imports nothing but pickle, with the build folder not on its
    path: as symvi's classes, all the way down, and back here equal to what was pickled."""
    pendulum = compiled("pendulum")
    step = step_result(compiled, "pendulum")
    objects = (step, states_bvp(compiled), batch_result(compiled), states_batch(compiled),
               pendulum.State(x=[0.0], v=[1.0]), pendulum.Status.SADDLE,
               pendulum.NewtonError(step))
    assert objects[1].states is not None and objects[3][0].states is not None
    assert not objects[2].success and len(set(objects[2].lengths["x"])) == 2
    given, back = tmp_path / "given.pickle", tmp_path / "back.pickle"
    data = pickle.dumps(objects)
    assert b"_symvi_" not in data and pendulum.__name__.encode() not in data
    given.write_bytes(data)
    proc = fresh_python(LOADER, given, back, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report["classes"] == [f"symvi._runtime.core.results.{name}" for name in
                                 ("BVPBatch", "BVPResult", "BatchResult", "NewtonError",
                                  "State", "Status", "StepResult")]
    assert report["packages"] == [] and str(build_dir) not in report["path"]
    assert_same(objects, pickle.loads(back.read_bytes()))


def test_results_of_two_packages_round_trip_to_one_class(compiled):
    """Results of two packages are two classes here; through a pickle both become
    symvi's, each equal to its original field by field."""
    pendulum, oscillator = compiled("pendulum"), compiled("harmonic_oscillator")
    a, b = step_result(compiled, "pendulum"), step_result(compiled, "harmonic_oscillator")
    assert a.success and b.success, (a.message, b.message)
    assert type(a) is not type(b)
    a_back, b_back = pickle.loads(pickle.dumps((a, b)))
    assert type(a_back) is type(b_back) is home.StepResult
    assert_same(a, a_back)
    assert_same(b, b_back)
    for result in (spline_bvp(compiled), states_bvp(compiled)):
        assert_same(result, pickle.loads(pickle.dumps(result)))
    assert pickle.loads(pickle.dumps(oscillator.Status.SADDLE)) is home.Status.SADDLE
    error = pickle.loads(pickle.dumps(pendulum.NewtonError(a)))
    assert type(error) is home.NewtonError and str(error) == a.message
    assert_same(a, error.result)
    for protocol in range(pickle.HIGHEST_PROTOCOL + 1):
        assert_same(a, pickle.loads(pickle.dumps(a, protocol=protocol)))


def test_importing_packages_registers_no_shared_module(compiled):
    """No ``symvi_runtime_results_*`` module: each package keeps its own classes, named
    by its own module."""
    pendulum, oscillator = compiled("pendulum"), compiled("harmonic_oscillator")
    assert not [m for m in sys.modules if m.startswith("symvi_runtime_results")]
    for package in (pendulum, oscillator):
        for name in ("StepResult", "BVPResult", "BatchResult", "BVPBatch", "State", "Status",
                     "NewtonError"):
            cls = getattr(package, name)
            assert cls.__module__.startswith(package.__name__ + "."), (name, cls.__module__)
            assert cls is not getattr(home, name)
    assert home.StepResult.__module__ == "symvi._runtime.core.results"


IMPORT_A_COPY = """
    import __future__, dataclasses, enum, importlib, importlib.util, json, os, secrets, sys
    import numpy
    before = set(sys.modules)
    spec = importlib.util.spec_from_file_location("a_copy_of_results", sys.argv[1])
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    print(json.dumps({"added": sorted(set(sys.modules) - before),
                      "modules": sorted({getattr(module, n).__module__ for n in
                                         ("StepResult", "State", "Status", "NewtonError",
                                          "_rebuild")})}))
"""


def test_importing_results_adds_only_itself_to_sys_modules(tmp_path):
    """In a new interpreter that has imported what the file imports, importing a copy of
    it (as a package's ``_runtime`` does) adds that copy to ``sys.modules`` and nothing
    else, and leaves its classes named by it."""
    proc = fresh_python(IMPORT_A_COPY, RESULTS_SOURCE, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout) == {"added": ["a_copy_of_results"],
                                       "modules": ["a_copy_of_results"]}


STANDALONE = """
    import pickle, sys

    class NotInstalled:         # symvi and SymPy as if not installed
        def find_spec(self, name, path=None, target=None):
            if name.partition(".")[0] in ("symvi", "sympy"):
                raise ModuleNotFoundError(f"No module named {name!r}", name=name)

    sys.meta_path.insert(0, NotInstalled())
    folder, out = sys.argv[1:3]
    sys.path.insert(0, folder)
    import pendulum as package
    result = package.integrate([[0.0], [0.1]], 20, 0.05)
    data = pickle.dumps((result, package.State(x=[0.0], v=[1.0]), result.status))
    open(out, "wb").write(data)
    try:
        pickle.loads(data)
    except ModuleNotFoundError as exc:
        print("cannot load:", exc)
    print(sorted(m for m in sys.modules if m.startswith("symvi_runtime_results")))
"""


def test_a_package_without_symvi_pickles_and_symvi_loads_it(compiled, build_dir, tmp_path):
    """Where symvi cannot be imported a package's results still pickle, and loading them
    needs symvi (ModuleNotFoundError naming it); a process with symvi loads them."""
    mod = compiled("pendulum")
    out = tmp_path / "standalone.pickle"
    proc = fresh_python(STANDALONE, build_dir, out, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines() == ["cannot load: No module named 'symvi'", "[]"]
    result, state, status = pickle.loads(out.read_bytes())
    assert_same(mod.integrate([[0.0], [0.1]], 20, 0.05), result)
    assert_same(mod.State(x=[0.0], v=[1.0]), state)
    assert status is home.Status.SUCCESS


def test_copies_stay_in_their_own_package(compiled):
    """``copy`` rebuilds through the same reduction but in the object's own copy of the
    file: no change of class, no import of symvi's."""
    for result in (step_result(compiled, "pendulum"), states_bvp(compiled),
                   batch_result(compiled), states_batch(compiled)):
        for again in (copy.copy(result), copy.deepcopy(result)):
            assert type(again) is type(result)
            for field in dataclasses.fields(result):
                value = getattr(again, field.name)
                if isinstance(value, np.ndarray):
                    np.testing.assert_array_equal(value, getattr(result, field.name))
    state = compiled("pendulum").State(x=[0.0], v=[1.0])
    assert type(copy.deepcopy(state)) is type(state)


def load_copy(tmp_path: Path, name: str, source: str):
    """Import ``source`` as a copy of results.py, as a package's ``_runtime`` would."""
    path = tmp_path / name / "results.py"
    path.parent.mkdir()
    path.write_text(source, encoding="utf-8")
    spec = importlib.util.spec_from_file_location(f"{name}_results", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    try:
        spec.loader.exec_module(module)
    finally:
        del sys.modules[spec.name]
    return module


def test_a_copy_takes_another_copys_objects_for_its_own(compiled, tmp_path):
    """``isinstance`` and ``issubclass`` take a class of another copy with the same name
    and fields for the copy's own: a ``symvi.State`` starts a package's run, a loaded
    pickle warm-starts a solve. A class whose fields differ is not taken."""
    pendulum, oscillator = compiled("pendulum"), compiled("harmonic_oscillator")
    a = step_result(compiled, "pendulum")
    assert isinstance(a, oscillator.StepResult) and isinstance(a, home.StepResult)
    assert issubclass(pendulum.BVPResult, oscillator.BVPResult)
    assert isinstance(symvi.State(v=[0.0]), pendulum.State)
    assert isinstance(pendulum.Status.SUCCESS, home.Status)
    assert isinstance(pendulum.NewtonError(a), oscillator.NewtonError)
    assert not isinstance(a, oscillator.BVPResult) and not issubclass(home.State, home.Status)
    assert not isinstance(np.zeros(2), home.State) and not isinstance(0, home.Status)
    started = pendulum.integrate(symvi.State(x=[0.1], v=[0.0]), 20, 0.05)
    assert started.success and started.x[0, 0] == 0.1
    # a pickled States solve, loaded as symvi's class, warm-starts the package's solve
    mod, r = compiled("cubic_spline"), states_bvp(compiled)
    loaded = pickle.loads(pickle.dumps(r))
    again = mod.solve_bvp(mod.State(x=[0.0, 0.0], v=[0.0, 1.0]),
                          mod.State(x=[1.0, 0.0], v=[0.0, 0.0]), 20, T=1.0, guess=loaded)
    assert again.success and again.iterations <= 1 and again.cost == pytest.approx(r.cost)
    source = RESULTS_SOURCE.read_text(encoding="utf-8")
    field = "    g: object = None\n"
    assert source.count(field) == 1
    other = load_copy(tmp_path, "other", source.replace(field, field + "    w: object = None\n"))
    assert not isinstance(other.State(v=0.0), home.State)
    assert not isinstance(home.State(v=0.0), other.State)
    assert isinstance(pendulum.Status.SUCCESS, other.Status) and issubclass(other.StepResult,
                                                                          home.StepResult)


def test_a_pickle_with_unknown_fields_names_them():
    data = pickle.dumps(home.State(v=[1.0]))
    assert pickle.loads(data) == home.State(v=[1.0])
    with pytest.raises(TypeError, match="a pickled State has fields this State has not: w"):
        home._rebuild("State", {"v": 1.0, "w": 2.0})


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
