"""Build stage: C source → cffi extension → importable package ``DIR/<name>/``.

The only stage that touches the filesystem. A build is cached under a content hash of the
model, the templates, the run-time sources and the symvi version. Builds run in a
temporary directory beside the target and are swapped in by rename under a lock, so an
interrupted or concurrent build leaves a working package or none.
"""
from __future__ import annotations

import contextlib
import fcntl
import hashlib
import importlib.util
import json
import os
import shlex
import shutil
import sys
import sysconfig
import tempfile
import uuid
from pathlib import Path
from types import ModuleType

import cffi

from . import __version__
from .derive import DerivedModel, derive
from .discretise import discretise
from .emit import CSource, emit, environment, templates_digest
from .errors import BuildError, CompilerNotFoundError
from .model import Model

MANIFEST = "symvi.json"
COMPILE_ARGS = ["-O3", "-std=c99", "-fno-math-errno"]


PACKAGE = Path(__file__).resolve().parent


def _runtime_files() -> list[Path]:
    return sorted((PACKAGE / "_runtime").glob("*.py"))


def cache_key(model: Model) -> str:
    """Content hash of everything that determines the generated package.

    The model, the templates, the compile flags, the symvi version and symvi's own
    sources (the derivation code and the run-time files copied into the package).
    """
    h = hashlib.sha256()
    for part in (__version__, templates_digest(), model.fingerprint(), " ".join(COMPILE_ARGS)):
        h.update(part.encode() + b"\0")
    for path in sorted(PACKAGE.rglob("*.py")):
        h.update(str(path.relative_to(PACKAGE)).encode() + path.read_bytes())
    return h.hexdigest()


def find_compiler() -> str:
    """The C compiler cffi will run; raise :class:`CompilerNotFoundError` if it is missing."""
    command = os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc"
    executable = shlex.split(command)[0]
    if shutil.which(executable) is None:
        raise CompilerNotFoundError(
            f"no C compiler found: cffi would run {executable!r} (from $CC or Python's build "
            f"configuration) and it is not on PATH. Install a C compiler (e.g. "
            f"`apt-get install gcc`) or point $CC at one.")
    return executable


@contextlib.contextmanager
def _locked(path: Path):
    with open(path, "a+") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


@contextlib.contextmanager
def _captured_output(sink: Path):
    """Send this process's stdout/stderr (fds 1, 2: the compiler's) to ``sink``."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    with open(sink, "w") as out:
        os.dup2(out.fileno(), 1)
        os.dup2(out.fileno(), 2)
        try:
            yield
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])


def _compile_extension(src: CSource, module: str, workdir: Path, verbose: bool) -> Path:
    ffi = cffi.FFI()
    ffi.cdef(src.cdef)
    ffi.set_source(module, src.c_source, extra_compile_args=COMPILE_ARGS, libraries=["m"])
    workdir.mkdir(parents=True, exist_ok=True)
    log = workdir / "compiler.log"
    try:
        with contextlib.nullcontext() if verbose else _captured_output(log):
            built = ffi.compile(tmpdir=str(workdir / "build"), verbose=verbose)
    except Exception as exc:  # cffi wraps distutils/setuptools errors in several types
        output = log.read_text() if log.exists() else ""
        raise BuildError(f"the C compiler failed on {module}.c: {exc}\n"
                         f"--- compiler output ---\n{output.strip()}") from None
    return Path(built)


def _info(dm: DerivedModel, key: str, description: str) -> dict:
    return {
        "name": dm.name, "kind": dm.kind, "order": dm.order, "source_dim": dm.source_dim,
        "fibre_dim": dm.fibre_dim, "parameters": [str(s) for s in dm.parameters],
        "defaults": list(dm.defaults), "has_energy": dm.has_energy,
        "whole_trajectory": dm.whole_trajectory, "constraints": dm.constraint_count,
        "controls": dm.control_count, "step_scaled": list(dm.step_scaled),
        "symmetries": list(dm.symmetries), "gauges": list(dm.gauges),
        "symvi_version": __version__, "key": key,
        "configuration_dim": dm.c_context["configuration_dim"],
        "matrix_dims": [G["matrix_dim"] for G in dm.c_context["groups"]],
        "description": description,
        "kernels": {k.name: {"nz": len(k.z), "outputs": [len(M) for _, M in k.outputs]}
                    for k in dm.kernels},
    }


def _write_package(pkg: Path, dm: DerivedModel, src: CSource, key: str, model: Model,
                   verbose: bool) -> None:
    module = f"_ext_{key[:16]}"
    built = _compile_extension(src, module, pkg.parent / f"{pkg.name}-work", verbose)
    pkg.mkdir()
    shutil.copy2(built, pkg / built.name)
    (pkg / f"{dm.name}.c").write_text(src.c_source)
    runtime = pkg / "_runtime"
    runtime.mkdir()
    for path in _runtime_files():
        shutil.copy2(path, runtime / path.name)
    info = _info(dm, key, model.description)
    defaults = ", ".join(f"{n}={v:g}" for n, v in zip(info["parameters"], dm.defaults)) or "none"
    init = environment().get_template("package_init.py.j2").render(
        name=dm.name, version=__version__, kind=dm.kind, order=dm.order, info=repr(info),
        extension=module, description=model.description or "", defaults_text=defaults)
    (pkg / "__init__.py").write_text(init)
    (pkg / MANIFEST).write_text(json.dumps({"key": key, "extension": built.name}, indent=2))


def _is_current(target: Path, key: str) -> bool:
    try:
        manifest = json.loads((target / MANIFEST).read_text())
    except (OSError, ValueError):
        return False
    return manifest.get("key") == key and (target / manifest.get("extension", "")).is_file()


def _swap_in(new: Path, target: Path) -> None:
    if target.exists():
        old = target.with_name(f".{target.name}.old-{uuid.uuid4().hex[:8]}")
        os.rename(target, old)
        os.rename(new, target)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.rename(new, target)


def load(package_dir: str | os.PathLike) -> ModuleType:
    """Import a generated package from its directory (without editing ``sys.path``)."""
    package_dir = Path(package_dir)
    manifest = json.loads((package_dir / MANIFEST).read_text())
    alias = f"_symvi_{package_dir.name}_{manifest['key'][:16]}"
    if alias in sys.modules:
        return sys.modules[alias]
    spec = importlib.util.spec_from_file_location(
        alias, package_dir / "__init__.py", submodule_search_locations=[str(package_dir)])
    module = importlib.util.module_from_spec(spec)
    sys.modules[alias] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[alias]
        raise
    return module


def compile_model(model: Model, out_dir: str | os.PathLike = "generated", *,
                  force: bool = False, verbose: bool = False) -> ModuleType:
    """Derive, emit and build ``model`` into ``out_dir/<name>/`` and import it.

    An unchanged model reuses its build unless ``force``. Raises
    :class:`~symvi.errors.ModelError` for an invalid (e.g. non-regular) model,
    :class:`~symvi.errors.BuildError` with the compiler's output if C compilation fails and
    :class:`~symvi.errors.CompilerNotFoundError` if there is no C compiler.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    key, target = cache_key(model), out / model.name
    with _locked(out / f".{model.name}.lock"):
        if force or not _is_current(target, key):
            find_compiler()
            derived = derive(discretise(model))
            src = emit(derived)
            scratch = Path(tempfile.mkdtemp(prefix=f".{model.name}-build-", dir=out))
            try:
                _write_package(scratch / model.name, derived, src, key, model, verbose)
                _swap_in(scratch / model.name, target)
            finally:
                shutil.rmtree(scratch, ignore_errors=True)
    return load(target)
