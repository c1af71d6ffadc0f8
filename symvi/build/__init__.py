"""Build stage: C source → cffi extension → importable package ``DIR/<name>``.

The only stage that touches the filesystem. ``DIR/<name>`` is a relative symlink to a
version folder ``DIR/.<name>/<version>/``, replaced atomically by each build (layout,
swap and clean-up: :mod:`symvi.build.swap`). A build is cached under a content hash of
what determines its files (:func:`cache_key`: the model and its description, the
templates, the run-time files, the sources of the code that generates them, the
compiler and its flags) and reused only after every file of the package has been
checked against the hashes of its manifest (:mod:`symvi.build.cache`); a damaged build
is rebuilt with a :class:`~symvi.errors.CacheWarning`. Builds of one package are
serialised by a lock (POSIX and Windows); the C compile runs in a child process
(:mod:`symvi.build.ccompile`), so that builds from several threads of one process do not
disturb each other, and gives a bitwise reproducible extension. An interrupted or
failed build leaves the previous package (or none) in place and debris that the next
build removes.
"""
from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import os
import shlex
import shutil
import sys
import sysconfig
import threading
import warnings
from pathlib import Path
from types import ModuleType

from ..version import __version__
from .cache import (MANIFEST, compiler_command, compiler_identity, files_digest, inspect,
                    library_versions, problems, read_manifest, sources_digest, summary)
from .ccompile import CompileTimeout, compile_extension
from ..derivation.derive import derive
from ..discretisation.discretise import discretise
from ..codegen.emit import CSource, emit, templates_digest
from ..errors import BuildError, CacheWarning, CompilerNotFoundError, DamagedPackageError
from .files import writing
from .generic import generic_object
from ..declaration.model import Model
from .package import runtime_files, write_package
from .stages import Expired, Progress, StageClock
from .swap import Layout, ensure_folder

__all__ = ["MANIFEST", "COMPILE_ARGS", "WRAPPER_ARGS", "cache_key", "compile_model", "find_compiler", "load"]

#: Flags of the C compile (part of the cache key). ``-g0`` keeps the extension free of
#: debug information, which would record the (randomly named) build folder: the same
#: model then compiles to a bitwise-identical extension.
COMPILE_ARGS = ["-O3", "-std=c99", "-fno-math-errno", "-g0"]
#: Generated C longer than this many characters is compiled at -O2 instead (issue 23).
#: Measured with gcc 12 (compile s, -O3 → -O2; step loop over 2·10⁴ steps): the double
#: pendulum's 63 kB 2.4 → 2.0, its loop 17 % slower at -O2; the heavy top's 135 kB 5.9 →
#: 4.3, loop no slower; se3_body's 182 kB 8.8 → 6.1, loop 12 % slower; the 10-link chain's
#: 240 kB 8.8 → 6.7, loop as fast; the 20-link chain's 780 kB 35 → 27 (register
#: allocation a third of it). Large models are compiled more often than their loops are
#: timed. The same arithmetic either way: no -ffast-math, so NaN checks keep working.
#: Superword vectorisation is off for them: on straight-line kernels it finds little and
#: costs much (20-link chain, kernels split by ``codegen/schedule.py``: 11.5 s and 400 MB
#: with it, 9.1 s and 280 MB without; the 10-link chain's loop is as fast).
#: Lowered from 150 000 when the generic library (issue 54, :mod:`.generic`) took 7 kB
#: (band solvers) to 17 kB (and the lifted inertia) out of every whole-trajectory model's
#: unit: the bundled models compiled at -O2 are those of before but heavy_top_rotors_oc
#: (154 → 137 kB), now at -O3.
LARGE_SOURCE = 142_000
LARGE_SOURCE_ARGS = ["-O2", "-fno-tree-slp-vectorize", *COMPILE_ARGS[1:]]
#: Flags of the unit of cffi's wrappers (argument conversions, no arithmetic of the
#: model's), compiled apart from the model's units (issue 54): at -O3, pendulum's 40
#: wrappers cost 0.67 s of CPU, two thirds of its C compile; at -O1 0.29 s.
WRAPPER_ARGS = ["-O1", "-std=c99", "-g0"]


def compile_args(src: CSource) -> list[str]:
    """The flags of the C compile of ``src`` (:data:`COMPILE_ARGS`, or
    :data:`LARGE_SOURCE_ARGS` above :data:`LARGE_SOURCE` characters in all its units)."""
    return LARGE_SOURCE_ARGS if src.size > LARGE_SOURCE else COMPILE_ARGS

_LOAD_LOCK = threading.RLock()


def cache_key(model: Model) -> str:
    """Content hash of everything that determines the generated package's files.

    Hashed, each part separately (so that no two parts can run into each other):

    * the model: its fingerprint and its description (the package's docstring and
      ``INFO`` carry it);
    * symvi's version (written into ``INFO`` and the C source's header);
    * the templates (:func:`~symvi.codegen.emit.templates_digest`) and the run-time files copied
      into the package (``symvi/_runtime/**/*.py``), read from disk as the build would;
    * the sources of every symvi module that generates the files: the closure of the
      symvi-internal imports of the modules the build runs, without the checks, the
      command line, the bundled model files and the build's own orchestration, lock and
      swap (:func:`~symvi.build.cache.generating_sources`);
    * the compile: :data:`COMPILE_ARGS` and the large-source rule (:func:`compile_args`),
      :data:`WRAPPER_ARGS`,
      the compiler cffi would run and the flags
      setuptools adds (:func:`~symvi.build.cache.compiler_identity`), Python's extension
      suffix (its ABI), and the versions of SymPy (simplifies and prints the C),
      SymEngine (differentiates), Jinja2 (renders it) and cffi (writes the wrapper,
      drives the compile).

    Editing a check, the command line or the build's lock therefore reuses every build.
    The sources, the compiler's files and the libraries' versions are read once per
    process (the code that runs is the code loaded then); the rest at each call.
    """
    h = hashlib.sha256()
    for label, value in _key_parts(model):
        h.update(hashlib.sha256(f"{label}\0{value}".encode("utf-8", "surrogatepass")).digest())
    return h.hexdigest()


def _key_parts(model: Model) -> list[tuple[str, str]]:
    """The inputs of :func:`cache_key`, labelled."""
    classes = (type(model), type(model.control_system))
    return [
        ("model", model.fingerprint()),
        ("description", str(model.description or "")),
        ("symvi", __version__),
        ("templates", templates_digest()),
        ("runtime", files_digest(runtime_files())),
        ("sources", sources_digest(c.__module__ for c in classes)),
        ("compile args", "\0".join(COMPILE_ARGS + [str(LARGE_SOURCE)] + LARGE_SOURCE_ARGS
                                   + WRAPPER_ARGS)),
        ("compiler", compiler_identity()),
        ("python", str(sysconfig.get_config_var("EXT_SUFFIX"))),
        ("libraries", library_versions()),
    ]


def find_compiler() -> str:
    """The C compiler cffi will run; raise :class:`CompilerNotFoundError` if it is missing."""
    executable = shlex.split(compiler_command())[0]
    if shutil.which(executable) is None:
        raise CompilerNotFoundError(
            f"no C compiler found: cffi would run {executable!r} (from $CC or Python's build "
            f"configuration) and it is not on PATH. Install a C compiler (e.g. "
            f"`apt-get install gcc`) or point $CC at one.")
    return executable


# -- importing -----------------------------------------------------------------------------
def load(package_dir: str | os.PathLike) -> ModuleType:
    """Import a generated package from its directory (without editing ``sys.path``).

    ``package_dir`` is ``DIR/<name>`` (followed to its version folder) or a copy of a
    package. Its files are first checked against its manifest: a damaged package
    raises :class:`~symvi.errors.DamagedPackageError` (an ``ImportError``) saying what
    is wrong and how to recompile. Safe to call from several threads.
    """
    folder = Path(package_dir).resolve()
    manifest = read_manifest(folder)
    found = [f"{MANIFEST}: missing or unreadable"] if manifest is None \
        else problems(folder, manifest)
    if found:
        out = Path(package_dir).absolute().parent
        raise DamagedPackageError(
            f"generated package {folder} is damaged ({summary(found)}); recompile it: "
            f"symvi compile <model> -o {out} --force, or "
            f"symvi.compile_model(model, {str(out)!r}, force=True)")
    return _import(folder, manifest)


def _import(folder: Path, manifest: dict) -> ModuleType:
    """Import the verified package ``folder`` under an alias unique to its folder and
    build, so that packages of one name from several folders can be loaded side by side."""
    where = hashlib.sha256(str(folder).encode("utf-8", "surrogatepass")).hexdigest()[:8]
    alias = f"_symvi_{manifest.get('name', folder.name)}_{str(manifest.get('key'))[:16]}_{where}"
    # One lock for all loads: a second thread must not find the first one's module in
    # sys.modules before it has finished executing.
    with _LOAD_LOCK:
        if alias in sys.modules:
            return sys.modules[alias]
        spec = importlib.util.spec_from_file_location(
            alias, folder / "__init__.py", submodule_search_locations=[str(folder)])
        module = importlib.util.module_from_spec(spec)
        sys.modules[alias] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[alias]
            raise
        return module


# -- compiling -----------------------------------------------------------------------------
def compile_model(model: Model, out_dir: str | os.PathLike = "generated", *,
                  force: bool = False, verbose: bool = False, timeout: float | None = None,
                  progress: Progress | None = None,
                  clock: StageClock | None = None) -> ModuleType:
    """Derive, emit and build ``model`` into ``out_dir/<name>`` and import it.

    An unchanged model reuses its build unless ``force``, after checking every file of
    it; a damaged build is rebuilt, with a :class:`~symvi.errors.CacheWarning` saying
    what was wrong. A current build is loaded without writing anything (it may sit in
    a read-only folder).

    ``timeout`` (seconds) bounds the whole build, counted from this call; at the
    deadline it stops with a :class:`~symvi.errors.BuildError` naming the stage that was
    running (discretise, derive, emit, C compile), the time since the start and the time
    of each finished stage. ``clock`` instead goes on with a clock already running, with
    its own timeout and progress (the command line's, started before it loaded the model
    file as its first stage, so that ``--timeout`` counts from the command's start). The
    symbolic stages can only be interrupted when called from the main thread
    (``SIGALRM``); from other threads the deadline bounds the C compile and is checked
    between stages.
    ``progress`` receives a line for each stage that runs longer than 2 s (``verbose``:
    for every stage); ``verbose`` also shows the compiler's output on stderr.

    The build touches only what symvi made: anything else at ``out_dir/<name>`` or
    ``out_dir/.<name>`` (a folder of the user's, a file, a link elsewhere) is refused,
    before any work, with an :class:`~symvi.errors.OutputConflictError` naming it; it is
    never moved or deleted.

    Raises :class:`~symvi.errors.ModelError` for an invalid (e.g. non-regular) model,
    :class:`~symvi.errors.BuildError` if C compilation fails (with the compiler's
    output), the output folder cannot be written or the timeout passes,
    :class:`~symvi.errors.OutputConflictError` (a ``BuildError`` and a ``ValueError``) for
    a name taken by something not symvi's, and
    :class:`~symvi.errors.CompilerNotFoundError` if there is no C compiler.
    """
    clock = _clock(model, timeout, progress, verbose, clock)
    out = Path(out_dir)
    ensure_folder(out)
    layout = Layout(out, model.name)
    layout.refuse_foreign()
    key = cache_key(model)
    if not force:
        verdict = inspect(layout.target, key)
        if verdict.current:
            _tidy(layout)
            return _import(verdict.folder, read_manifest(verdict.folder))
    with layout.locked():
        if not force:
            verdict = inspect(layout.target, key)
            if verdict.current:      # built meanwhile by another process
                return _import(verdict.folder, read_manifest(verdict.folder))
            if verdict.damage:
                warnings.warn(f"{model.name}: cached build is damaged "
                              f"({summary(verdict.damage)}); rebuilding",
                              CacheWarning, stacklevel=2)
        folder = _build(model, key, layout, clock, verbose)
        return _import(folder, read_manifest(folder))


def _clock(model: Model, timeout: float | None, progress: Progress | None, verbose: bool,
           running: StageClock | None) -> StageClock:
    """The build's stage clock: ``running`` (renamed for the model) or a new one."""
    if running is None:
        return StageClock(model.name, timeout, progress, verbose)
    if timeout is not None or progress is not None:
        raise ValueError("compile_model: give a timeout and progress either directly or "
                         "through the clock, not both")
    # until now the clock named what it was loading (a model file, a bundled name)
    running.name = model.name
    return running


def _tidy(layout: Layout) -> None:
    """Remove what killed builds left, if the folder is writable and no build runs."""
    if not layout.has_debris():
        return
    with contextlib.suppress(BuildError), layout.locked(wait=False) as held:
        if held:
            layout.clean_scratch()


def _build(model: Model, key: str, layout: Layout, clock: StageClock, verbose: bool) -> Path:
    """Build and publish a new version of the package (under the lock); its folder."""
    find_compiler()
    with clock.stage("discretise"):
        discrete = discretise(model)
    with clock.stage("derive"):
        derived = derive(discrete)
    with clock.stage("emit"):
        src = emit(derived)
    version = layout.new_version(key)
    scratch = layout.new_scratch()
    try:
        with clock.stage("C compile", interruptible=False):
            built = _compile(src, key, scratch / "work", clock, verbose)
        write_package(scratch / "package", derived, src, key, str(model.description or ""),
                      built, version)
        previous = layout.publish(scratch / "package", version)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    layout.clean(keep={version, previous} - {None})
    return layout.store / version


def _compile(src: CSource, key: str, workdir: Path, clock: StageClock, verbose: bool) -> Path:
    with writing(workdir, "create"):
        workdir.mkdir()
    try:
        # the generic library at the small sources' flags whatever the model's size: it
        # is compiled once for all models, and its loops are the solves' inner loops
        generic = generic_object(workdir, COMPILE_ARGS, clock.remaining(), verbose)
        return compile_extension(src.cdef, (("model", src.c_source), *src.units),
                                 f"_ext_{key[:16]}", workdir, compile_args(src), clock.remaining(),
                                 verbose, objects=[generic], wrapper_args=WRAPPER_ARGS)
    except CompileTimeout:
        raise Expired() from None
