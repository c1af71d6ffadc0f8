"""The generic library (issue 54, item 1): the C that depends on no model (band LU,
solves and products; the lifted system's inertia and equilibration) is compiled once per
symvi version, compiler and flags into a cached object file, verified by content hash,
rebuilt when damaged, and linked into every package's extension, so that a package needs
the cache neither moved nor elsewhere.

The concurrent builds of it are in test_build_hardening.py (threads) and
test_standalone.py (processes); a Dask worker loading a package is in test_dask.py.
"""
from __future__ import annotations

import hashlib
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from symvi.build import compile_model
from symvi.build.generic import CACHE_ENV, NAME, RECORD
from symvi.errors import CacheWarning
from symvi.models import get

from test_build_hardening import tiny, works
from test_false_success import cubic


def entries(cache: Path) -> list[Path]:
    """The built libraries in the cache folder ``cache`` (no lock, no scratch)."""
    return sorted(p for p in (cache / "generic").iterdir()
                  if p.is_dir() and not p.name.startswith("build-"))


def record(entry: Path) -> dict:
    return json.loads((entry / RECORD).read_text())


def intact(entry: Path) -> bool:
    data = (entry / f"{NAME}.o").read_bytes()
    found = record(entry)
    return found["size"] == len(data) and found["sha256"] == hashlib.sha256(data).hexdigest()


@pytest.fixture
def cache(tmp_path, monkeypatch) -> Path:
    """A fresh, empty cache folder for this test's builds."""
    folder = tmp_path / "cache"
    monkeypatch.setenv(CACHE_ENV, str(folder))
    return folder


def test_three_models_build_the_generic_library_once(tmp_path, cache):
    """A first-order model, a second-order one (the lifted system's inertia) and an
    optimal-control problem: one build of the library, reused unchanged (the same file,
    the same build's nonce) by the next two, whose own units hold none of it."""
    seen = []
    for name in ("harmonic_oscillator", "cubic_spline", "rigid_body_oc"):
        module = compile_model(get(name), tmp_path / name, force=True)
        [entry] = entries(cache)
        built = entry / f"{NAME}.o"
        seen.append((entry.name, record(entry)["built"], built.stat().st_ino,
                     built.stat().st_mtime_ns))
        source = (tmp_path / name / name / f"{name}.c").read_text()
        defined = set(re.findall(r"(\w+)\([^;{]*\)\s*\{", source))
        assert not defined & {"symvi_band_factor", "symvi_band_solve", "eliminate",
                              "symvi_shaped_inertia", "symvi_shaped_equilibrate"}
        assert module.model.lib.symvi_band_factor    # linked into the extension
    assert len(set(seen)) == 1, seen
    assert intact(entries(cache)[0])


def test_the_linked_library_solves_as_a_whole_trajectory_solver(tmp_path, cache):
    """The band LU and the lifted inertia of the library at work: cubic_spline's discrete
    solution is the cubic through its end nodes at the nodes for every N (the node
    system at N = 200, the lifted one at N = 4000), and the second-order verdict (the
    lifted system's inertia) calls it a minimum (SUCCESS)."""
    module = compile_model(get("cubic_spline"), tmp_path, force=True)
    for N in (200, 4000):
        h = 1.0 / N
        exact = cubic(h * np.arange(N + 1))
        result = module.solve_bvp(exact[:2], exact[-2:], N, h)
        assert result.success, result.message
        assert np.abs(result.x - exact).max() <= 1e-8 * np.abs(exact).max()


@pytest.mark.parametrize("damage", ["flipped byte", "truncated", "no record", "no object",
                                    "record of another key"])
def test_a_damaged_library_is_rebuilt_with_a_warning(tmp_path, cache, damage):
    compile_model(tiny(), tmp_path / "a")
    [entry] = entries(cache)
    first = record(entry)["built"]
    built = entry / f"{NAME}.o"
    if damage == "flipped byte":
        data = bytearray(built.read_bytes())
        data[len(data) // 2] ^= 0xFF
        built.write_bytes(bytes(data))
    elif damage == "truncated":
        built.write_bytes(built.read_bytes()[:100])
    elif damage == "no record":
        (entry / RECORD).unlink()
    elif damage == "no object":
        built.unlink()
    else:
        (entry / RECORD).write_text(json.dumps({**record(entry), "key": "0" * 64}))
    with pytest.warns(CacheWarning, match=r"generic library cached at .* is damaged"):
        module = compile_model(tiny(), tmp_path / "b")
    assert works(module)
    [entry] = entries(cache)
    assert intact(entry) and record(entry)["built"] != first
    assert not list((cache / "generic").glob("build-*"))


def test_without_a_usable_cache_each_build_compiles_its_own(tmp_path, monkeypatch):
    """A cache folder that cannot be made (here: its path names a file) costs the
    library's compile in every build, and nothing else."""
    blocked = tmp_path / "not-a-folder"
    blocked.write_text("")
    monkeypatch.setenv(CACHE_ENV, str(blocked / "cache"))
    assert works(compile_model(tiny(), tmp_path / "out", force=True))
    assert blocked.read_text() == ""


def test_a_package_needs_no_cache_moved_or_not(tmp_path, cache):
    """The library is inside each package's extension: with the cache gone, a package
    (and a copy of it elsewhere) loads and solves."""
    from test_standalone import run_standalone
    name = "cubic_spline"
    compile_model(get(name), tmp_path / "a")
    shutil.rmtree(cache)
    shutil.copytree(tmp_path / "a" / name, tmp_path / "b" / name)
    shutil.rmtree(tmp_path / "a")
    example = get(name).example
    out = run_standalone(tmp_path / "b", name, example)
    assert out["success"], out["message"]
    assert not cache.exists()
