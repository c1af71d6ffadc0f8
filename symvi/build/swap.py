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

The lock (:class:`FileLock`) is ``flock`` on POSIX and a lock on the lock file's first
byte (``msvcrt.locking``) on Windows; either excludes other processes and other threads
of this process.
"""
from __future__ import annotations

import contextlib
import errno
import os
import shutil
import tempfile
import time
import uuid
from pathlib import Path
from typing import Iterator

from ..errors import BuildError
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
        self._fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)

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


class Layout:
    """The paths of one model's package in one output folder (see the module doc)."""

    def __init__(self, out: Path, name: str):
        self.out, self.name = out, name
        self.target = out / name
        self.store = out / f".{name}"

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
        ``.NAME/``), if there was one."""
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
        ``.NAME/`` (this once, the swap is two steps). Refuses to replace a file."""
        if self.target.is_symlink() or not self.target.exists():
            return None
        if not self.target.is_dir():
            raise BuildError(f"{self.target} exists and is not a generated package (it is a "
                             f"file); remove it or compile into another folder (-o)")
        aside = f"{_LEGACY}{uuid.uuid4().hex[:8]}"
        os.rename(self.target, self.store / aside)
        return aside

    # -- cleaning -------------------------------------------------------------------------
    def clean(self, keep: set[str]) -> None:
        """Remove every entry of ``.NAME/`` but the lock and ``keep``, and the debris
        of older symvi versions beside ``DIR/NAME`` (call under the lock)."""
        self._remove_all(e for e in self._entries() if e.name not in keep | {LOCK})
        self._remove_legacy_debris()

    def clean_scratch(self) -> None:
        """Remove what killed builds left (scratch folders, temporary links) but no
        version: a cache hit does not know which version is the retained previous one."""
        self._remove_all(e for e in self._entries()
                         if e.name.startswith((SCRATCH, _TEMP_LINK)))
        self._remove_legacy_debris()

    def has_debris(self) -> bool:
        """Whether a killed build left something for :meth:`clean_scratch`."""
        legacy = any(self.out.glob(f".{self.name}-build-*")) \
            or any(self.out.glob(f".{self.name}.old-*"))
        return legacy or any(e.name.startswith((SCRATCH, _TEMP_LINK)) for e in self._entries())

    def _entries(self) -> list[Path]:
        try:
            return list(self.store.iterdir())
        except OSError:
            return []

    def _remove_legacy_debris(self) -> None:
        self._remove_all([*self.out.glob(f".{self.name}-build-*"),
                          *self.out.glob(f".{self.name}.old-*"),
                          *self.out.glob(f".{self.name}.lock")])

    @staticmethod
    def _remove_all(paths) -> None:
        for path in paths:
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path, ignore_errors=True)
            else:
                with contextlib.suppress(OSError):
                    path.unlink()


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
