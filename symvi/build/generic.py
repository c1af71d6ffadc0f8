"""The generic library: the C that depends on no model, compiled once and linked into
every package.

``templates/generic.c.j2`` holds the solvers whose sizes are run-time numbers (the band
factorisation, solves and products of the whole-trajectory Newton; the lifted system's
inertia and equilibration). It is compiled once per symvi version, compiler and flags
(its key, :func:`generic_key`) into an object file in a cache folder shared by every
build of this user (:func:`cache_folder`), and each package's extension links a copy of
it: the package carries the generic code inside its own extension, so it stays
self-contained (numpy and cffi at run time), keeps working when moved, copied or loaded
by a Dask worker, and needs no loader path (an ``$ORIGIN`` rpath, a DLL search) nor a
library of the right version beside it. What each package repeats is some 16 kB of
machine code; what it no longer repeats is the compile (measured: a tenth of pendulum's C
compile, a fifth of rigid_body_oc's).

The cache folder ``CACHE/generic/`` holds::

    lock                the lock every build of the library, and every use, holds
    <key16>/            one built library: symvi_generic.o and record.json (its key,
                        size, SHA-256 and the nonce of the build that made it)
    build-*/            scratch of a build in progress (or killed; the next build
                        removes it)

The object is read and checked against its record under the lock, and handed to the
build as a copy in the build's own scratch folder: a damaged copy (size or content
changed, record missing) is rebuilt with a :class:`~symvi.errors.CacheWarning`, and a
library is built once however many threads and processes compile models at once (the
others wait for it). Where the cache folder cannot be made or locked (a read-only home),
each build compiles its own copy. The libraries of other keys (another symvi, compiler or
set of flags, which may be in use beside this one) are left in place: 16 kB each.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import sysconfig
import tempfile
import uuid
import warnings
from pathlib import Path

from ..codegen.emit import generic_source
from ..errors import CacheWarning
from ..version import __version__
from .cache import compiler_identity
from .ccompile import compile_object
from .files import sha256_file, write_file, writing
from .swap import FileLock

#: The environment variable that names the cache folder (default :func:`cache_folder`).
CACHE_ENV = "SYMVI_CACHE_DIR"
NAME = "symvi_generic"
RECORD = "record.json"
LOCK = "lock"
SCRATCH = "build-"


def cache_folder() -> Path:
    """The user's symvi cache: ``$SYMVI_CACHE_DIR``, else ``$XDG_CACHE_HOME/symvi`` or
    ``~/.cache/symvi`` (on Windows ``%LOCALAPPDATA%\\symvi``). Read at each call."""
    named = os.environ.get(CACHE_ENV)
    if named:
        return Path(named)
    if os.name == "nt":
        base = os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local"
    else:
        base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "symvi"


def generic_key(source: str, args: list[str]) -> str:
    """Content hash of what determines the library's object file: symvi's version, its C
    text, the compile flags, the compiler (:func:`~symvi.build.cache.compiler_identity`)
    and Python's extension suffix (whose build configuration adds flags)."""
    h = hashlib.sha256()
    for label, value in (("symvi", __version__), ("source", source), ("args", "\0".join(args)),
                         ("compiler", compiler_identity()),
                         ("python", str(sysconfig.get_config_var("EXT_SUFFIX")))):
        h.update(hashlib.sha256(f"{label}\0{value}".encode("utf-8", "surrogatepass")).digest())
    return h.hexdigest()


def generic_object(workdir: Path, args: list[str], timeout: float | None = None,
                   verbose: bool = False) -> Path:
    """The generic library's object file, compiled with ``args``, as a verified copy in
    the build's folder ``workdir``; built into the cache first if it is missing or
    damaged. Raises :class:`~symvi.build.ccompile.CompileTimeout` past ``timeout``
    seconds (waiting for another build of it, about a second, is not counted) and
    :class:`~symvi.errors.BuildError` if the compile fails."""
    source = generic_source()
    key = generic_key(source, args)
    store = cache_folder() / "generic"
    try:
        store.mkdir(parents=True, exist_ok=True)
        lock = FileLock(store / LOCK)
    except OSError:                 # no cache to be had: this build compiles its own
        return compile_object(source, NAME, _fresh(workdir / "generic"), args, timeout,
                              verbose)
    with lock:
        lock.acquire()
        try:
            data = _cached(store / key[:16], key) or _build(store, key, source, args, timeout,
                                                             verbose)
        finally:
            lock.release()
    copy = workdir / f"{NAME}.o"
    write_file(copy, data)
    return copy


def _fresh(folder: Path) -> Path:
    with writing(folder, "create"):
        folder.mkdir()
    return folder


def _cached(entry: Path, key: str) -> bytes | None:
    """The object file of the library ``entry`` if it is there, built for ``key`` and
    intact (call under the lock); None if it is missing, and a warning if damaged."""
    if not entry.exists():
        return None
    problem, data = "record.json: missing or unreadable", None
    try:
        record = json.loads((entry / RECORD).read_text())
        data = (entry / f"{NAME}.o").read_bytes()
    except (OSError, ValueError):
        record = None
    if isinstance(record, dict) and data is not None:
        problem = "built for another key" if record.get("key") != key else \
            f"size changed ({record.get('size')} → {len(data)} bytes)" \
            if record.get("size") != len(data) else \
            "content changed" if hashlib.sha256(data).hexdigest() != record.get("sha256") \
            else None
    elif isinstance(record, dict):
        problem = f"{NAME}.o: missing or unreadable"
    if problem is None:
        return data
    warnings.warn(f"the generic library cached at {entry} is damaged ({problem}); "
                  f"rebuilding it", CacheWarning, stacklevel=4)
    return None


def _build(store: Path, key: str, source: str, args: list[str], timeout: float | None,
           verbose: bool) -> bytes:
    """Compile the library into ``store/<key16>`` (call under the lock), replacing a
    damaged one there and what killed builds left; its object file's bytes."""
    for debris in store.glob(f"{SCRATCH}*"):
        shutil.rmtree(debris, ignore_errors=True)
    with writing(store, "create a scratch folder in"):
        scratch = Path(tempfile.mkdtemp(prefix=SCRATCH, dir=store))
    try:
        built = compile_object(source, NAME, scratch, args, timeout, verbose)
        entry = _fresh(scratch / "entry")
        with writing(built, "read the compiled"):
            data = built.read_bytes()
        write_file(entry / f"{NAME}.o", data)
        record = {"key": key, "size": len(data), "sha256": sha256_file(entry / f"{NAME}.o"),
                  "built": uuid.uuid4().hex[:8]}
        write_file(entry / RECORD, json.dumps(record, indent=2) + "\n")
        final = store / key[:16]
        shutil.rmtree(final, ignore_errors=True)
        with writing(final, "move the built generic library to"):
            os.rename(entry, final)
        return data
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
