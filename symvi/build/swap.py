"""The on-disk layout of generated packages, the build lock and the atomic swap.

For a model ``NAME`` compiled into ``DIR``::

    DIR/NAME -> .NAME/<version>     relative symlink: the package Python imports
    DIR/.NAME/<version>/            one complete build (never modified once published)
    DIR/.NAME/build-*/              scratch folder of a build in progress (or killed)
    DIR/.NAME/lock                  held (:class:`FileLock`) by the one build at a time

A build is written into a scratch folder, renamed to ``<version>`` (the cache key's
first 16 hex digits and a nonce) and published by replacing ``DIR/NAME`` with a new
link in one ``os.replace``, which is atomic: a reader sees the old package or the new
one, never none. After publishing, the build removes every other entry of ``.NAME/``
except the version it replaced, which a process that was importing it during the swap
may still be reading; that one goes at the next publish. A build killed at any point
leaves a ``build-*`` folder, a temporary ``link-*`` or an unlinked version, all of
which the next build removes.

A build touches only what symvi made (:meth:`Layout.refuse_foreign`, before any work):
``DIR/NAME`` is symvi's if it is a link ``.NAME/<version>`` or a folder holding a
manifest (the package of a symvi before the link layout, moved into ``.NAME/`` as
``legacy-*`` at the next publish); ``.NAME/`` if it is a real folder that is empty or
holds the lock or an entry symvi names and types as its own (a version, scratch or
legacy folder, a temporary link: ``_OWN``). Anything else named so is refused with an
:class:`~symvi.errors.OutputConflictError`, never moved or deleted. Clean-up removes
only such entries of ``.NAME/``, and beside ``DIR/NAME`` only an older symvi's debris;
it never lists or deletes through a symbolic link.

The lock (:class:`FileLock`) is ``flock`` on POSIX and a lock on the lock file's first
byte (``msvcrt.locking``) on Windows; either excludes other processes and other threads
of this process.
"""
from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import stat
import tempfile
import time
import uuid
from pathlib import Path
from typing import Iterator

from ..errors import BuildError, OutputConflictError
from .cache import MANIFEST, read_manifest
from .files import READ_ONLY, describe_os_error, writing

try:
    import fcntl
except ImportError:          # Windows
    fcntl = None
    import msvcrt

LOCK = "lock"
SCRATCH = "build-"
_TEMP_LINK = "link-"
_LEGACY = "legacy-"
#: The names symvi gives the entries of ``.NAME/`` it makes, by what they are: version
#: folders (:meth:`Layout.new_version`: 16 hex digits of the key, a nonce), scratch
#: folders (``tempfile.mkdtemp``'s eight characters), moved-aside packages of an older
#: layout, and temporary links (eight hex digits). Nothing else there is symvi's.
_OWN = {"folder": re.compile(rf"[0-9a-f]{{16}}-[0-9a-f]{{8}}|{SCRATCH}[a-z0-9_]{{8}}"
                             rf"|{_LEGACY}[0-9a-f]{{8}}"),
        "link": re.compile(rf"{_TEMP_LINK}[0-9a-f]{{8}}")}
#: errno of ``msvcrt.locking`` when another handle holds the byte: EACCES for the
#: non-blocking try used here (EDEADLOCK is the CRT's "gave up" of its waiting modes).
_BUSY = {errno.EACCES, getattr(errno, "EDEADLOCK", errno.EDEADLK)}
#: How often (seconds) a blocking acquire on Windows tries again: ``msvcrt`` has no
#: lock that waits indefinitely, and a short poll keeps Ctrl-C responsive.
_POLL = 0.05


class FileLock:
    """An exclusive lock on the file ``path`` (created if missing), between processes
    and between the threads of one process.

    Each instance opens the file anew, and a lock belongs to that open file (POSIX
    ``flock``: to the open file description; Windows ``msvcrt.locking``: to the file
    handle), so two instances exclude each other wherever they are. An instance is
    used by one thread at a time. Opening raises ``OSError``; closing releases.
    """

    def __init__(self, path: Path):
        self.path = path
        # never through a link: a link named ``lock`` would create or lock its target
        self._fd = os.open(path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o666)

    def acquire(self, wait: bool = True) -> bool:
        """Take the lock, waiting for it unless ``wait`` is off; whether it is held."""
        return _lock(self._fd, wait)

    def release(self) -> None:
        """Give the lock up."""
        _unlock(self._fd)

    def close(self) -> None:
        """Close the file (which releases the lock if it is held)."""
        os.close(self._fd)

    def __enter__(self) -> FileLock:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


if fcntl is not None:
    def _lock(fd: int, wait: bool) -> bool:
        """Lock the open file ``fd`` (waiting unless not ``wait``); whether it is locked."""
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        except BlockingIOError:
            return False
        return True

    def _unlock(fd: int) -> None:
        """Unlock the open file ``fd``."""
        fcntl.flock(fd, fcntl.LOCK_UN)
else:
    def _lock(fd: int, wait: bool) -> bool:
        while True:
            # msvcrt locks the bytes from the file position on: always byte 0 (the
            # file is empty; Windows allows locking beyond its end).
            os.lseek(fd, 0, os.SEEK_SET)
            try:
                msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
                return True
            except OSError as exc:
                if exc.errno not in _BUSY:
                    raise
            if not wait:
                return False
            time.sleep(_POLL)

    def _unlock(fd: int) -> None:
        os.lseek(fd, 0, os.SEEK_SET)
        msvcrt.locking(fd, msvcrt.LK_UNLCK, 1)


def not_writable(folder: Path) -> BuildError:
    """The error for a build that must write into a folder it may not write."""
    return BuildError(f"output folder {folder} is not writable, and the package must be "
                      f"(re)built; choose another folder (-o) or make it writable")


def conflict(path: Path, name: str, what: str) -> OutputConflictError:
    """The refusal of ``path``, in the way of the package ``name`` and not symvi's."""
    return OutputConflictError(
        f"{path} is in the way of the package {name!r}: it was not made by symvi ({what}), "
        f"and symvi neither moves nor deletes it; compile into another folder (-o) or "
        f"rename it")


def _entry_type(path: Path) -> str | None:
    """What ``path`` itself is, links not followed: "link", "folder", "file" or None
    (nothing there)."""
    try:
        mode = path.lstat().st_mode
    except (FileNotFoundError, NotADirectoryError):
        return None
    if stat.S_ISLNK(mode):
        return "link"
    return "folder" if stat.S_ISDIR(mode) else "file"


def _is_package(folder: Path) -> bool:
    """Whether the real folder ``folder`` holds a symvi manifest (every symvi wrote one
    into each package before publishing it)."""
    manifest = read_manifest(folder)
    return manifest is not None and "key" in manifest


def _is_own_entry(entry: Path) -> bool:
    """Whether an entry of ``.NAME/`` is one a build makes and clean-up may remove, by
    its name and what it is (:data:`_OWN`; never the lock)."""
    pattern = _OWN.get(_entry_type(entry))
    return pattern is not None and pattern.fullmatch(entry.name) is not None


def _remove(path: Path) -> None:
    """Remove ``path``: a real folder with its content, anything else (a link included)
    by unlinking it; a link is never followed."""
    if _entry_type(path) == "folder":
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(OSError):
            path.unlink()


class Layout:
    """The paths of one model's package in one output folder (see the module doc)."""

    def __init__(self, out: Path, name: str):
        self.out, self.name = out, name
        self.target = out / name
        self.store = out / f".{name}"
        # what a symvi before the link layout left beside DIR/NAME when killed: its
        # scratch folders (``tempfile.mkdtemp``'s eight characters) and swapped-out
        # packages (eight hex digits)
        self._old_debris = re.compile(
            rf"\.{re.escape(name)}(?:-build-[a-z0-9_]{{8}}|\.old-[0-9a-f]{{8}})")

    # -- what is symvi's ------------------------------------------------------------------
    def refuse_foreign(self) -> None:
        """Raise :class:`~symvi.errors.OutputConflictError` if ``DIR/NAME`` or ``.NAME``
        is there and not symvi's (see the module doc). Reads only: call it before any
        work, also for a build that may be a cache hit in a read-only folder."""
        for path, what in ((self.target, self._foreign_target()),
                           (self.store, self._foreign_store())):
            if what is not None:
                raise conflict(path, self.name, what)

    def _foreign_target(self) -> str | None:
        """What ``DIR/NAME`` is if it is not symvi's (None: absent or symvi's)."""
        entry = _entry_type(self.target)
        if entry == "link":
            text = os.readlink(self.target)
            return None if self._is_own_link(text) else f"a symbolic link to {text}"
        if entry == "folder" and not _is_package(self.target):
            return f"a folder without symvi's manifest {MANIFEST}"
        return "a file" if entry == "file" else None

    def _is_own_link(self, text: str) -> bool:
        """Whether a link's ``text`` is the one :meth:`publish` writes: ``.NAME/<version>``."""
        store, _, version = text.replace(os.sep, "/").partition("/")
        return store == self.store.name and version not in ("", ".", "..") \
            and "/" not in version

    def _foreign_store(self) -> str | None:
        """What ``.NAME`` is if it is not symvi's (None: absent or symvi's)."""
        entry = _entry_type(self.store)
        if entry == "link":
            return f"a symbolic link to {os.readlink(self.store)}"
        if entry == "file":
            return "a file"
        entries = self._entries()
        if entry is None or not entries or any(
                _is_own_entry(e) or (e.name == LOCK and _entry_type(e) == "file") for e in entries):
            return None
        return "a folder without symvi's build lock or builds"

    # -- locking --------------------------------------------------------------------------
    @contextlib.contextmanager
    def locked(self, wait: bool = True) -> Iterator[bool]:
        """Hold the build lock; yields False if ``wait`` is off and another build has it.

        Raises :class:`BuildError` if the folder is not writable (the lock file cannot be
        created), which is only asked for when something must be written.
        """
        try:
            self.store.mkdir(exist_ok=True)
            lock = FileLock(self.store / LOCK)
        except OSError as exc:
            if exc.errno in READ_ONLY:
                raise not_writable(self.out) from None
            raise BuildError(f"could not create the build lock {self.store / LOCK}: "
                             f"{describe_os_error(exc)}") from None
        with lock:
            if not lock.acquire(wait):
                yield False
                return
            try:
                yield True
            finally:
                lock.release()

    # -- building and publishing ----------------------------------------------------------
    def new_scratch(self) -> Path:
        """A fresh scratch folder inside ``.NAME/`` (call under the lock)."""
        with writing(self.store, "create a scratch folder in"):
            return Path(tempfile.mkdtemp(prefix=SCRATCH, dir=self.store))

    def new_version(self, key: str) -> str:
        """A version folder name that no earlier build used."""
        return f"{key[:16]}-{uuid.uuid4().hex[:8]}"

    def publish(self, package: Path, version: str) -> str | None:
        """Move the finished ``package`` folder to ``.NAME/<version>`` and point
        ``DIR/NAME`` at it atomically. Returns the replaced version's folder name (in
        ``.NAME/``), if there was one. Raises :class:`~symvi.errors.OutputConflictError`,
        replacing nothing, if ``DIR/NAME`` is no longer symvi's."""
        final = self.store / version
        with writing(final, "move the finished package to"):
            os.rename(package, final)
        previous = self._previous_version()
        link = self.store / f"{_TEMP_LINK}{uuid.uuid4().hex[:8]}"
        with writing(self.target, "replace"):
            # The link's text is resolved relative to the folder holding the link, which
            # is DIR once it has replaced DIR/NAME.
            os.symlink(f"{self.store.name}/{version}", link)
            previous = self._move_aside_real_folder() or previous
            os.replace(link, self.target)
        return previous

    def _previous_version(self) -> str | None:
        """The version folder ``DIR/NAME`` links to now, if it is one of ours."""
        if not self.target.is_symlink():
            return None
        resolved = self.target.resolve()
        return resolved.name if resolved.parent == self.store.resolve() else None

    def _move_aside_real_folder(self) -> str | None:
        """Migration from a symvi that wrote ``DIR/NAME`` as a folder: move it into
        ``.NAME/`` (this once, the swap is two steps). Checked again here, just before
        the swap, since the build began: what is not symvi's is refused, not moved."""
        what = self._foreign_target()
        if what is not None:
            raise conflict(self.target, self.name, what)
        if _entry_type(self.target) != "folder":
            return None
        aside = f"{_LEGACY}{uuid.uuid4().hex[:8]}"
        os.rename(self.target, self.store / aside)
        return aside

    # -- cleaning -------------------------------------------------------------------------
    def clean(self, keep: set[str]) -> None:
        """Remove every entry of ``.NAME/`` that a build makes but ``keep``, and the
        debris of older symvi versions beside ``DIR/NAME`` (call under the lock)."""
        self._remove_all(e for e in self._entries()
                         if e.name not in keep and _is_own_entry(e))
        self._remove_all(self._older_debris())

    def clean_scratch(self) -> None:
        """Remove what killed builds left (scratch folders, temporary links) but no
        version: a cache hit does not know which version is the retained previous one."""
        self._remove_all(self._scratch())
        self._remove_all(self._older_debris())

    def has_debris(self) -> bool:
        """Whether a killed build left something for :meth:`clean_scratch`."""
        return bool(self._scratch() or self._older_debris())

    def _scratch(self) -> list[Path]:
        return [e for e in self._entries()
                if e.name.startswith((SCRATCH, _TEMP_LINK)) and _is_own_entry(e)]

    def _entries(self) -> list[Path]:
        """The entries of ``.NAME/`` (none if it is a link: never listed through one)."""
        if _entry_type(self.store) != "folder":
            return []
        try:
            return list(self.store.iterdir())
        except OSError:
            return []

    def _older_debris(self) -> list[Path]:
        """What a symvi before the link layout left beside ``DIR/NAME``: scratch folders
        and swapped-out packages (real folders, by their exact names) and its lock file
        (an empty file)."""
        try:
            beside = list(self.out.iterdir())
        except OSError:
            return []
        found = [p for p in beside
                 if self._old_debris.fullmatch(p.name) and _entry_type(p) == "folder"]
        lock = self.out / f"{self.store.name}.lock"
        with contextlib.suppress(OSError):
            if _entry_type(lock) == "file" and lock.lstat().st_size == 0:
                found.append(lock)
        return found

    @staticmethod
    def _remove_all(paths) -> None:
        for path in paths:
            _remove(path)


def ensure_folder(out: Path) -> None:
    """Create the output folder; a path that names a file, or an uncreatable folder,
    is a :class:`BuildError`."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise BuildError(f"output folder {out} is a file (or lies below one); give a "
                         f"folder with -o") from None
    except OSError as exc:
        if exc.errno in READ_ONLY:
            raise not_writable(out) from None
        raise BuildError(f"could not create the output folder {out}: "
                         f"{describe_os_error(exc)}") from None
