"""File helpers of the build stage: content hashes and writes that fail with a message.

Every file the build writes goes through :func:`write_file` (or runs inside
:func:`writing`), so that a full disk or a read-only folder surfaces as a
:class:`~symvi.errors.BuildError` naming the file, never as a raw ``OSError``.
"""
from __future__ import annotations

import contextlib
import errno
import hashlib
from pathlib import Path
from typing import Iterator

from ..errors import BuildError

#: errno values that mean "the disk (or the user's quota) is full".
_FULL = {errno.ENOSPC, errno.EDQUOT}
#: errno values that mean "this folder may not be written".
READ_ONLY = {errno.EACCES, errno.EPERM, errno.EROFS}


def sha256_file(path: Path) -> str:
    """Hex SHA-256 of a file's content."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def describe_os_error(exc: OSError) -> str:
    """A short reason for a failed write: the disk is full, not writable, or strerror."""
    if exc.errno in _FULL:
        return "no space left on device"
    if exc.errno in READ_ONLY:
        return "the folder is not writable"
    return exc.strerror or str(exc)


@contextlib.contextmanager
def writing(path: Path, what: str = "write") -> Iterator[None]:
    """Turn an ``OSError`` raised inside the block into a :class:`BuildError` naming
    ``path`` (``what`` is the verb: write, create, move, ...)."""
    try:
        yield
    except OSError as exc:
        raise BuildError(f"could not {what} {path}: {describe_os_error(exc)}") from None


def write_file(path: Path, data: bytes | str) -> None:
    """Write ``data`` (text as UTF-8) to ``path``; errors become :class:`BuildError`."""
    raw = data.encode("utf-8") if isinstance(data, str) else data
    with writing(path):
        path.write_bytes(raw)
