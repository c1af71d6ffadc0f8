"""Generated packages stand alone, and the build cache is correct and safe.

* ``symvi compile NAME -o DIR`` (console script, or ``python -m symvi.cli``) works (one
  model of each kind); every bundled model's package imports and runs its example in a
  fresh interpreter where importing SymPy — and symvi itself — fails.
* An unchanged model reuses its build (same extension file, fast); a changed parameter
  default or Lagrangian rebuilds.
* Two concurrent compiles into one directory both succeed and leave one working package;
  debris of an interrupted build does not break the next compile or import, and goes.
* ``DIR/NAME`` links to a version folder in ``DIR/.NAME/``; a copy of the package
  elsewhere still works.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

import symvi
from symvi import Model, PairGroupoid, State
from symvi.build import MANIFEST, cache_key, compile_model
from symvi.build.generic import CACHE_ENV
from symvi.errors import CacheWarning
from symvi.models import BUNDLED, get

#: Directory that makes ``import symvi`` work in a child process (checkout or install).
SYMVI_ROOT = str(Path(symvi.__file__).resolve().parent.parent)


def child_env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (SYMVI_ROOT, env.get("PYTHONPATH")) if p)
    return env


def symvi_command() -> list[str]:
    """The ``symvi`` console script installed next to this interpreter, else ``-m``."""
    script = Path(sys.executable).with_name("symvi")
    if script.is_file() and os.access(script, os.X_OK):
        return [str(script)]
    return [sys.executable, "-m", "symvi.cli"]


def run_cli(*args, timeout=300, **popen) -> subprocess.CompletedProcess:
    return subprocess.run([*symvi_command(), *args], capture_output=True, text=True,
                          env=child_env(), timeout=timeout, **popen)


# Run in a fresh interpreter: SymPy and symvi are made unimportable *before* anything else,
# then the generated package is imported from DIR and its example integrated.
CHILD = textwrap.dedent("""
    import sys
    sys.modules["sympy"] = None          # `import sympy` now raises ImportError
    sys.modules["symvi"] = None          # so does `import symvi`
    import json
    spec = json.loads(sys.argv[1])
    for blocked in ("sympy", "symvi"):
        try:
            __import__(blocked)
        except ImportError:
            pass
        else:
            raise SystemExit(f"{blocked} is importable: the test set-up is broken")
    sys.path.insert(0, spec["dir"])
    import importlib
    mod = importlib.import_module(spec["name"])
    if "start" in spec:   # a whole-trajectory example (optimal control)
        ends = [mod.State(**e) if isinstance(e, dict) else e for e in (spec["start"], spec["end"])]
        r = mod.solve_bvp(*ends, spec["n_steps"], spec["h"], guess=spec.get("guess"))
        final, rows = r.f[-1], r.f.shape[0] + 1
    else:
        initial = spec["initial"]
        if mod.INFO.kind == "lie":
            initial = tuple(initial)
        r = mod.integrate(initial, spec["n_steps"], spec["h"])
        final, rows = r.q[-1], r.q.shape[0]
    loaded = sorted(m for m in sys.modules if m.split(".")[0] in ("sympy", "symvi")
                    and sys.modules[m] is not None)
    print(json.dumps({"success": bool(r.success), "message": r.message,
                      "final": final.tolist(), "rows": int(rows),
                      "file": mod.__file__, "loaded": loaded}))
""")


def _as_list(value):
    """Nested arrays (tuples of arrays for (x, g) data) as JSON lists; None (an unknown
    end) as null; a State as the dict of its fields."""
    if isinstance(value, State):
        return {k: _as_list(v) for k, v in (("x", value.x), ("g", value.g), ("v", value.v))
                if v is not None}
    if isinstance(value, tuple):
        return [_as_list(v) for v in value]
    return None if value is None else np.asarray(value, dtype=float).tolist()


def run_standalone(directory: Path, name: str, example) -> dict:
    spec = {"dir": str(directory), "name": name, "n_steps": int(example.n_steps),
            "h": float(example.h)}
    if example.whole_trajectory:
        spec |= {"start": _as_list(example.start), "end": _as_list(example.end)}
        if example.guess is not None:     # its first path (a nonholonomic example's)
            spec["guess"] = _as_list(example.guess_nodes(order=get(name).order))
    else:
        spec["initial"] = _as_list(example.initial)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    proc = subprocess.run([sys.executable, "-c", CHILD, json.dumps(spec)], capture_output=True,
                          text=True, env=env, cwd=str(directory), timeout=300)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def extension_of(package: Path) -> Path:
    manifest = json.loads((package / MANIFEST).read_text())
    return package / manifest["extension"]


# -- the command line and standalone packages -------------------------------------------------
#: Through the command line: one model per groupoid, order and kind of problem (the CLI's
#: code path is the same for all; each child costs a second of imports). The others'
#: packages come from the session's build and are run standalone the same way.
CLI = ("pendulum", "cubic_spline", "rigid_body_exp", "planar_body", "heavy_top", "se3_body",
       "rigid_body_oc", "heavy_top_rotors_oc_variational")


@pytest.mark.parametrize("name", BUNDLED)
def test_cli_compile_then_standalone_import_runs_example(build_dir, compiled, name):
    # The session's build directory, where every model is compiled once per run: the CLI
    # finds the build (test_cli_second_compile_is_a_cache_hit compiles from scratch).
    cli_dir = build_dir
    package = cli_dir / name
    if name in CLI:
        proc = run_cli("compile", name, "-o", str(cli_dir))
        assert proc.returncode == 0, proc.stderr
        assert name in proc.stdout and "ready" in proc.stdout
    else:
        compiled(name)
    assert (package / "__init__.py").is_file() and extension_of(package).is_file()
    assert (package / "_runtime").is_dir()

    example = get(name).example
    out = run_standalone(cli_dir, name, example)
    assert out["success"], out["message"]
    assert out["loaded"] == []                       # neither sympy nor symvi was loaded
    assert Path(out["file"]).resolve() == (package / "__init__.py").resolve()
    # Same numbers as the in-process build of the same model (same C source and flags).
    if example.whole_trajectory:
        # from States, N + 2 nodes (the end elements' midpoints at t = 0 and T)
        assert out["rows"] == example.n_steps + 1 + isinstance(example.start, State)
        reference = compiled(name).solve_bvp(example.start, example.end, example.n_steps,
                                             example.h).f[-1]
    else:
        assert out["rows"] == example.n_steps + 1
        reference = compiled(name).integrate(example.initial, example.n_steps, example.h).q[-1]
    np.testing.assert_allclose(out["final"], reference, rtol=1e-12, atol=1e-12)


def test_cli_second_compile_is_a_cache_hit(tmp_path):
    import re

    first = run_cli("compile", "pendulum", "-o", str(tmp_path))
    assert first.returncode == 0, first.stderr
    ext = extension_of(tmp_path / "pendulum")
    before = ext.stat()
    second = run_cli("compile", "pendulum", "-o", str(tmp_path))
    assert second.returncode == 0, second.stderr
    after = ext.stat()
    assert (after.st_ino, after.st_mtime_ns) == (before.st_ino, before.st_mtime_ns)
    seconds = [float(m) for m in re.findall(r"ready in ([0-9.]+) s", first.stdout + second.stdout)]
    assert len(seconds) == 2, first.stdout + second.stdout
    print(f"\nCLI compile pendulum: first {seconds[0]:.2f} s, second {seconds[1]:.2f} s")
    assert seconds[1] < 0.5 and seconds[1] < seconds[0] / 2


def test_cli_reports_unknown_model(tmp_path):
    proc = run_cli("compile", "no_such_model", "-o", str(tmp_path))
    assert proc.returncode == 2
    assert "no_such_model" in proc.stderr and "bundled models" in proc.stderr


# -- cache -----------------------------------------------------------------------------------
def oscillator(k_default=1.0, quartic=False, name="cache_probe"):
    G = PairGroupoid("x")
    (x,), (v,) = G.q, G.qdot
    k = sp.Symbol("k", positive=True)
    L = v**2 / 2 - k * x**2 / 2 - (x**4 / 4 if quartic else 0)
    return Model(name, G, lagrangian=L, parameters={k: k_default})


def test_a_model_is_derived_once_per_process():
    """Derivations are memoised by fingerprint: an equal model (built anew) reuses the
    derived kernels, a changed default does not."""
    from symvi.derivation.derive import derive
    from symvi.discretisation.discretise import discretise

    first = derive(discretise(oscillator(2.5, name="memo_probe")))
    assert derive(discretise(oscillator(2.5, name="memo_probe"))) is first
    changed = derive(discretise(oscillator(3.5, name="memo_probe")))
    assert changed is not first and changed.defaults == (3.5,)


def test_unchanged_model_reuses_build(tmp_path):
    mod = compile_model(oscillator(), tmp_path)
    ext = extension_of(tmp_path / "cache_probe")
    before = ext.stat()
    # CPU time of this process: the wall clock also counts other test workers' load
    start = time.process_time()
    again = compile_model(oscillator(), tmp_path)    # an equal model, built anew in Python
    elapsed = time.process_time() - start
    after = ext.stat()
    assert (after.st_ino, after.st_mtime_ns) == (before.st_ino, before.st_mtime_ns)
    assert extension_of(tmp_path / "cache_probe") == ext
    assert elapsed < 0.5, f"cached compile took {elapsed:.2f} s"
    assert again.INFO.key == mod.INFO.key
    print(f"\ncached compile: {elapsed * 1e3:.1f} ms")


def test_changed_default_or_lagrangian_rebuilds(tmp_path):
    T, N = np.pi, 2000
    h = T / N
    base = compile_model(oscillator(1.0), tmp_path)
    key0 = base.INFO.key
    ext0 = extension_of(tmp_path / "cache_probe")

    stiffer = compile_model(oscillator(4.0), tmp_path)        # ω = 2: x(π) = x(0)
    ext1 = extension_of(tmp_path / "cache_probe")
    assert stiffer.INFO.key != key0 and ext1 != ext0
    assert stiffer.INFO.defaults == {"k": 4.0}
    # the new default is what the new build uses (no params given)
    r0 = base.integrate([[1.0], [np.cos(h)]], N, h)
    r1 = stiffer.integrate([[1.0], [np.cos(2 * h)]], N, h)
    assert r0.q[-1, 0] == pytest.approx(-1.0, abs=1e-5)
    assert r1.q[-1, 0] == pytest.approx(1.0, abs=1e-5)

    quartic = compile_model(oscillator(4.0, quartic=True), tmp_path)
    ext2 = extension_of(tmp_path / "cache_probe")
    assert quartic.INFO.key not in (key0, stiffer.INFO.key) and ext2 not in (ext0, ext1)
    r2 = quartic.integrate([[1.0], [np.cos(2 * h)]], N, h)
    assert abs(r2.q[-1, 0] - 1.0) > 1e-2                      # different dynamics
    # only the current build is left in the package directory, and beside it only the
    # version it replaced
    assert sorted(p.name for p in (tmp_path / "cache_probe").glob("_ext_*")) == [ext2.name]
    kept = sorted(p.name for p in (tmp_path / ".cache_probe").iterdir() if p.name != "lock")
    assert len(kept) == 2 and (tmp_path / "cache_probe").resolve().name in kept, kept


# -- concurrency and interrupted builds ------------------------------------------------------
def test_concurrent_compiles_into_same_directory(tmp_path):
    name = "harmonic_oscillator"
    procs = [subprocess.Popen([*symvi_command(), "compile", name, "-o", str(tmp_path)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              env=child_env())
             for _ in range(2)]
    results = [p.communicate(timeout=300) for p in procs]
    for p, (out, err) in zip(procs, results):
        assert p.returncode == 0, err
    # one package (a link to the one version folder), no scratch folder left behind
    assert sorted(p.name for p in tmp_path.iterdir()) == [f".{name}", name]
    store = sorted(p.name for p in (tmp_path / f".{name}").iterdir())
    assert store == sorted(["lock", (tmp_path / name).resolve().name]), store
    assert len(list((tmp_path / name).glob("_ext_*"))) == 1
    example = get(name).example
    out = run_standalone(tmp_path, name, example)
    assert out["success"], out["message"]


def test_concurrent_compiles_build_the_generic_library_once(tmp_path):
    """Three processes compile three models into three folders from an empty cache: the
    generic library (symvi.build.generic) is built once, by whichever comes first, and
    linked into all three packages, which run."""
    cache = tmp_path / "cache"
    env = child_env() | {CACHE_ENV: str(cache)}
    names = ("harmonic_oscillator", "pendulum", "cubic_spline")
    procs = [subprocess.Popen([*symvi_command(), "compile", name, "-o", str(tmp_path / name)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              env=env)
             for name in names]
    results = [p.communicate(timeout=300) for p in procs]
    for p, (out, err) in zip(procs, results):
        assert p.returncode == 0, err
    built = sorted(p.name for p in (cache / "generic").iterdir())
    assert len(built) == 2 and "lock" in built, built       # one library, no scratch
    for name in names:
        out = run_standalone(tmp_path / name, name, get(name).example)
        assert out["success"], out["message"]


def test_interrupted_build_debris_does_not_break_compile_or_import(tmp_path):
    name = "pendulum"
    example = get(name).example
    # half-written scratch folders of earlier, killed builds (this symvi's and an older
    # one's), a temporary link of a build killed while swapping ...
    for junk in (tmp_path / f".{name}" / "build-deadbeef" / "package",
                 tmp_path / f".{name}-build-deadbeef" / name):
        junk.mkdir(parents=True)
        (junk / "__init__.py").write_text("raise RuntimeError('half-written package imported')\n")
        (junk / "_ext_0000000000000000.c").write_text("this is not C")
    (tmp_path / f".{name}" / "link-deadbeef").symlink_to("nowhere")
    # ... and the package folder of a symvi before the link layout (its manifest, which
    # listed no files, but not its extension): symvi's, so it is replaced; a folder
    # without a manifest would be the user's, and refused (test_build_hardening)
    partial = tmp_path / name
    (partial / "_runtime").mkdir(parents=True)
    (partial / "__init__.py").write_text("raise RuntimeError('partial package imported')\n")
    (partial / MANIFEST).write_text(json.dumps({"key": cache_key(get(name)),
                                                "extension": "_ext_0000000000000000.so"}))

    with pytest.warns(CacheWarning, match="pendulum: cached build is damaged"):
        mod = compile_model(get(name), tmp_path)
    assert mod.integrate(example.initial, 100, example.h).success
    assert partial.is_symlink() and extension_of(partial).is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == [f".{name}", name]
    store = sorted(p.name for p in (tmp_path / f".{name}").iterdir())
    assert not [e for e in store if e.startswith(("build-", "link-"))], store
    out = run_standalone(tmp_path, name, example)
    assert out["success"], out["message"]

    # a later compile of the same model is a cache hit despite the debris
    ext = extension_of(partial)
    before = ext.stat()
    compile_model(get(name), tmp_path)
    assert ext.stat().st_mtime_ns == before.st_mtime_ns


def test_package_with_missing_extension_is_rebuilt(tmp_path):
    name = "harmonic_oscillator"
    compile_model(get(name), tmp_path)
    ext = extension_of(tmp_path / name)
    ext.unlink()                                     # manifest now points at nothing
    with pytest.warns(CacheWarning, match=rf"cached build is damaged \({ext.name}: missing"):
        compile_model(get(name), tmp_path)
    assert extension_of(tmp_path / name).is_file()
    example = get(name).example
    out = run_standalone(tmp_path, name, example)
    assert out["success"], out["message"]


def test_generated_package_is_relocatable(tmp_path):
    """The package carries its own runtime: copied elsewhere it still imports and runs."""
    name = "cubic_spline"
    compile_model(get(name), tmp_path / "a")
    shutil.copytree(tmp_path / "a" / name, tmp_path / "b" / name)
    shutil.rmtree(tmp_path / "a")
    example = get(name).example
    out = run_standalone(tmp_path / "b", name, example)
    assert out["success"], out["message"]
