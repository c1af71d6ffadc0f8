"""The build cache key's reach and the portable build lock (issue 19, item 4).

* The key hashes what determines a package's files: editing a check or the command line
  reuses a build; editing a template or the derivation rebuilds it. The sources hashed
  are the import closure of the modules the build runs, found without a full parse.
* The build lock excludes other processes and other threads; on Windows (simulated: no
  ``fcntl``) it locks the lock file's first byte with ``msvcrt.locking``.
"""
from __future__ import annotations

import ast
import errno
import importlib.util
import json
import os
import shutil
import subprocess
import sys
import textwrap
import threading
import time
import types
from pathlib import Path

import pytest

import symvi.build
import symvi.build.swap
import symvi.codegen.emit
from symvi.build import cache_key
from symvi.build.cache import (SYMVI, _closure, _file_digest, _generates,
                               _import_statements, _read_once, generating_sources,
                               library_versions)
from symvi.build.swap import Layout
from symvi.models import get

from test_build_hardening import FAST_ARGS, TINY_SOURCE, tiny

NAME = "tiny"


def relative(paths) -> set[str]:
    return {path.relative_to(SYMVI).as_posix() for path in paths}


# -- what the key hashes -------------------------------------------------------------------
def test_closure_holds_the_generating_modules_and_no_others():
    sources = relative(generating_sources([type(tiny()).__module__]))
    assert {"derivation/derive.py", "discretisation/discretise.py", "codegen/emit.py",
            "declaration/model.py", "discretisation/rules.py", "groupoids/lie.py",
            "groupoids/analytic.py", "build/package.py", "build/ccompile.py",
            "build/_cffi_build.py"} <= sources, sources
    assert not [s for s in sources if s.startswith(("checks/", "models/"))], sources
    assert not sources & {"cli.py", "build/__init__.py", "build/swap.py", "build/stages.py",
                          "timing.py"}


def test_closure_reaches_what_the_build_calls():
    """Each symvi function or class ``_build`` (and ``_compile``) uses that is not the
    build's own machinery lies in a module of the closure: a new stage cannot be left out
    of the key."""
    sources = relative(generating_sources())
    used = symvi.build._build.__code__.co_names + symvi.build._compile.__code__.co_names
    modules = {getattr(symvi.build.__dict__.get(name), "__module__", None) for name in used}
    generating = {m for m in modules if m and m.startswith("symvi") and _generates(m)}
    assert {"symvi.discretisation.discretise", "symvi.derivation.derive", "symvi.codegen.emit", "symvi.build.package",
            "symvi.build.ccompile"} <= generating
    for module in generating:
        spec = importlib.util.find_spec(module)
        assert Path(spec.origin).relative_to(SYMVI).as_posix() in sources, module


def full_parse(source: str) -> set[str]:
    return {ast.dump(node) for node in ast.walk(ast.parse(source))
            if isinstance(node, (ast.Import, ast.ImportFrom))}


def scanned(source: str) -> set[str]:
    return {ast.dump(node) for node in _import_statements(source)}


def test_import_scan_misses_no_import_of_symvi():
    for path in sorted(SYMVI.rglob("*.py")):
        source = path.read_text(encoding="utf-8")
        assert full_parse(source) <= scanned(source), path


def test_import_scan_reads_every_form_of_import_statement():
    source = textwrap.dedent('''\
        if TYPE_CHECKING: from .a import b
        try: import fcntl
        except ImportError: import msvcrt
        import os; from . import c
        from .d import (e,  # a comment with a bracket )
            f)
        from \\
            .g import h
        from.i import j
        def k(): from ..l import m; return m
        y = "n"; import p
        from .q import (r,
            s); import t
        text = """
        import looks_like_an_import
        """
    ''')
    assert scanned(source) - full_parse(source) \
        == {ast.dump(ast.parse("import looks_like_an_import").body[0])}
    assert full_parse(source) <= scanned(source)


def test_key_covers_compile_flags_compiler_and_python_abi(tmp_path, monkeypatch):
    model = tiny()
    base = cache_key(model)
    assert cache_key(tiny()) == base
    monkeypatch.setenv("SYMVI_UNRELATED", "1")
    assert cache_key(model) == base
    wrapper = tmp_path / "cc-wrapper"
    wrapper.write_text(f"#!/bin/sh\nexec {shutil.which('cc') or 'gcc'} \"$@\"\n")
    wrapper.chmod(0o755)
    changed = {}
    with monkeypatch.context() as patch:
        patch.setenv("CC", str(wrapper))
        changed["compiler"] = cache_key(model)
    with monkeypatch.context() as patch:
        patch.setenv("CFLAGS", "-DSYMVI_TEST")
        changed["CFLAGS"] = cache_key(model)
    with monkeypatch.context() as patch:
        patch.setattr(symvi.build, "COMPILE_ARGS", [*symvi.build.COMPILE_ARGS, "-DX"])
        changed["args"] = cache_key(model)
    real = symvi.build.sysconfig.get_config_var

    def other_abi(name: str):
        return ".cpython-399-fake.so" if name == "EXT_SUFFIX" else real(name)
    with monkeypatch.context() as patch:
        patch.setattr(symvi.build.sysconfig, "get_config_var", other_abi)
        changed["abi"] = cache_key(model)
    assert base not in changed.values() and len(set(changed.values())) == len(changed), changed
    assert cache_key(model) == base


def test_sources_and_compiler_are_read_once_per_process():
    cache_key(tiny())
    caches = (_closure, _read_once, _file_digest, library_versions)
    misses = [cache.cache_info().misses for cache in caches]
    cache_key(tiny())
    cache_key(get("pendulum"))
    assert [cache.cache_info().misses for cache in caches] == misses


# -- the key's reach, on a copy of symvi ---------------------------------------------------
#: Run with the copy of symvi at SRC first on ``sys.path``: for each line read, compiles
#: the tiny model into OUT and prints the package's state. Before each compile it empties
#: the key's per-process caches, so that each compile computes the key as a fresh process
#: would (one process instead of five saves importing SymPy four more times).
COMPILE_CHILD = textwrap.dedent("""
    import json, sys
    from pathlib import Path
    src, out, model_file, args = sys.argv[1:5]
    sys.path.insert(0, src)
    import symvi, symvi.build, symvi.build.cache
    from symvi.models import load
    assert Path(symvi.__file__).is_relative_to(src), symvi.__file__
    symvi.build.COMPILE_ARGS = json.loads(args)
    for _ in sys.stdin:
        for cached in vars(symvi.build.cache).values():
            getattr(cached, "cache_clear", lambda: None)()
        symvi.build.compile_model(load(model_file), out)
        folder = (Path(out) / "tiny").resolve()
        manifest = json.loads((folder / "symvi.json").read_text())
        stat = (folder / manifest["extension"]).stat()
        print(json.dumps({"folder": str(folder), "key": manifest["key"],
                          "extension": [stat.st_ino, stat.st_mtime_ns]}), flush=True)
""")


@pytest.fixture
def symvi_copy(tmp_path) -> Path:
    """A copy of the symvi package and its templates, laid out as in the checkout."""
    src = tmp_path / "src"
    ignore = shutil.ignore_patterns("__pycache__")
    shutil.copytree(SYMVI, src / "symvi", ignore=ignore)
    if not (src / "symvi" / "templates").is_dir():    # a checkout, not an installed copy
        shutil.copytree(symvi.codegen.emit.template_dir(), src / "templates", ignore=ignore)
    return src


def copied_template(src: Path, name: str) -> Path:
    """The copy's template ``name``: inside the package when installed, else beside it."""
    installed = src / "symvi" / "templates" / name
    return installed if installed.exists() else src / "templates" / name


@pytest.fixture
def compile_copy(symvi_copy, tmp_path):
    """compile_copy(): compile the tiny model with the copy of symvi (in one child
    process); the package's folder, key and extension's inode and mtime."""
    model_file = tmp_path / "tiny_model.py"
    model_file.write_text(f"DESCRIPTION = ''\n{TINY_SOURCE}")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    child = subprocess.Popen(
        [sys.executable, "-c", COMPILE_CHILD, str(symvi_copy), str(tmp_path / "out"),
         str(model_file), json.dumps(FAST_ARGS)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env, cwd=str(tmp_path))

    def compile_copy() -> dict:
        child.stdin.write("compile\n")
        child.stdin.flush()
        line = child.stdout.readline()
        assert line, "the child process failed (its traceback is in the captured stderr)"
        return json.loads(line)
    yield compile_copy
    child.kill()
    child.wait()


def append(path: Path, text: str) -> None:
    with open(path, "a", encoding="utf-8") as handle:
        handle.write(text)


def test_editing_code_that_does_not_generate_reuses_the_build(symvi_copy, compile_copy):
    built = compile_copy()
    for edited in ("symvi/checks/report.py", "symvi/cli.py"):
        append(symvi_copy / edited, "\n# edited: the build must be reused\n")
        assert compile_copy() == built, edited       # same folder, key, extension file
    append(copied_template(symvi_copy, "module.c.j2"), "{# edited: rebuild #}\n")
    after_template = compile_copy()
    assert after_template["key"] != built["key"]
    assert after_template["folder"] != built["folder"]
    append(symvi_copy / "symvi" / "derivation" / "derive.py", "\n# edited: rebuild\n")
    after_derive = compile_copy()
    assert after_derive["key"] != after_template["key"]
    assert after_derive["folder"] != after_template["folder"]


# -- the lock ------------------------------------------------------------------------------
#: Holds the build lock of OUT/NAME until a line arrives on stdin. The packages symvi and
#: symvi.build are stood in for by empty ones (SYMVI is symvi's folder), so that only the
#: lock's modules are imported, not SymPy: 0.1 s instead of 4.
HOLD_CHILD = textwrap.dedent("""
    import sys, types
    from pathlib import Path
    out, name, symvi_folder = sys.argv[1:4]
    for package, folder in (("symvi", symvi_folder), ("symvi.build", symvi_folder + "/build")):
        sys.modules[package] = types.ModuleType(package)
        sys.modules[package].__path__ = [folder]
    from symvi.build.swap import Layout
    assert "sympy" not in sys.modules
    with Layout(Path(out), name).locked() as held:
        print("held" if held else "not held", flush=True)
        sys.stdin.readline()
""")


def try_lock(out: Path) -> bool:
    with Layout(out, NAME).locked(wait=False) as held:
        return held


def test_lock_excludes_another_process(tmp_path):
    child = subprocess.Popen(
        [sys.executable, "-c", HOLD_CHILD, str(tmp_path), NAME, str(SYMVI)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "held"
        assert not try_lock(tmp_path)
        child.stdin.write("\n")
        child.stdin.flush()
        assert child.wait(timeout=60) == 0
    finally:
        child.kill()
        child.wait()
    assert try_lock(tmp_path)


def test_lock_excludes_another_thread_and_waits_for_it(tmp_path):
    holding, release, waited = threading.Event(), threading.Event(), threading.Event()

    def hold() -> None:
        with Layout(tmp_path, NAME).locked() as held:
            assert held
            holding.set()
            release.wait(timeout=60)

    def wait_for_it() -> None:
        with Layout(tmp_path, NAME).locked() as held:
            if held:
                waited.set()
    holder, waiter = threading.Thread(target=hold), threading.Thread(target=wait_for_it)
    holder.start()
    try:
        assert holding.wait(timeout=60)
        assert not try_lock(tmp_path)
        waiter.start()
        time.sleep(0.3)
        assert not waited.is_set()     # blocked while the other thread holds the lock
    finally:
        release.set()
        holder.join(timeout=60)
    waiter.join(timeout=60)
    assert waited.is_set()
    assert try_lock(tmp_path)


class FakeMsvcrt(types.ModuleType):
    """Just enough of ``msvcrt``: ``locking`` records (mode, bytes, file position) and
    fails with errno ``busy`` (a list, consumed per call) while that is non-empty."""

    LK_UNLCK, LK_LOCK, LK_NBLCK, LK_RLCK, LK_NBRLCK = range(5)

    def __init__(self):
        super().__init__("msvcrt")
        self.calls: list[tuple[int, int, int]] = []
        self.busy: list[int] = []

    def locking(self, fd: int, mode: int, nbytes: int) -> None:
        self.calls.append((mode, nbytes, os.lseek(fd, 0, os.SEEK_CUR)))
        os.lseek(fd, 7, os.SEEK_SET)      # as a write would: the next call must seek back
        if self.busy:
            raise OSError(self.busy.pop(0), "locked")


@pytest.fixture
def windows_swap(monkeypatch):
    """A fresh copy of :mod:`symvi.build.swap` imported where ``fcntl`` is missing and
    ``msvcrt`` is :class:`FakeMsvcrt`."""
    msvcrt = FakeMsvcrt()
    monkeypatch.setitem(sys.modules, "fcntl", None)
    monkeypatch.setitem(sys.modules, "msvcrt", msvcrt)
    spec = importlib.util.spec_from_file_location("symvi.build._swap_on_windows",
                                                  symvi.build.swap.__file__)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    monkeypatch.setattr(module, "_POLL", 0.001)
    return module, msvcrt


def test_windows_lock_locks_byte_zero_with_msvcrt(windows_swap, tmp_path):
    swap, msvcrt = windows_swap
    assert swap.fcntl is None and swap.msvcrt is msvcrt
    with swap.Layout(tmp_path, NAME).locked(wait=False) as held:
        assert held
    assert msvcrt.calls == [(msvcrt.LK_NBLCK, 1, 0), (msvcrt.LK_UNLCK, 1, 0)]
    assert (tmp_path / f".{NAME}" / "lock").is_file()


def test_windows_lock_try_fails_while_held_and_blocking_waits(windows_swap, tmp_path):
    swap, msvcrt = windows_swap
    lock_file = tmp_path / "lock"
    with swap.FileLock(lock_file) as lock:
        msvcrt.busy = [errno.EACCES]
        assert not lock.acquire(wait=False)
        msvcrt.calls.clear()
        msvcrt.busy = [errno.EACCES, errno.EACCES]
        assert lock.acquire()
        assert msvcrt.calls == [(msvcrt.LK_NBLCK, 1, 0)] * 3
        lock.release()
        msvcrt.busy = [errno.EBADF]
        with pytest.raises(OSError):
            lock.acquire(wait=False)
