"""The build cache's manifest: what a package folder must contain, and its verification.

The manifest ``symvi.json`` of a generated package names the cache key it was built
for and records the size and SHA-256 of every file of the package (the extension, the
C source, ``__init__.py``, each ``_runtime/*.py``). A build is reused only when its key
matches and every recorded file is intact; files the manifest does not list (e.g.
``__pycache__``) are ignored.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from .files import sha256_file, write_file

MANIFEST = "symvi.json"
#: At most this many problems are spelled out in a message about a damaged package.
_SHOWN = 3


def file_records(folder: Path) -> dict[str, dict]:
    """Size and SHA-256 of every file below ``folder`` (except the manifest), by
    relative POSIX path."""
    records = {}
    for path in sorted(folder.rglob("*")):
        if path.is_file() and path.name != MANIFEST and "__pycache__" not in path.parts:
            rel = path.relative_to(folder).as_posix()
            records[rel] = {"size": path.stat().st_size, "sha256": sha256_file(path)}
    return records


def write_manifest(folder: Path, **fields: str) -> None:
    """Write ``fields`` (name, key, extension, version) and the records of ``folder``'s
    files; written last, so a folder with a manifest is complete."""
    manifest = {**fields, "files": file_records(folder)}
    write_file(folder / MANIFEST, json.dumps(manifest, indent=2) + "\n")


def read_manifest(folder: Path) -> dict | None:
    """The manifest of ``folder``, or None if it is missing or unreadable."""
    try:
        manifest = json.loads((folder / MANIFEST).read_text())
    except (OSError, ValueError):
        return None
    return manifest if isinstance(manifest, dict) else None


def _file_problem(folder: Path, rel: str, record: dict) -> str | None:
    path = folder / rel
    try:
        size = path.stat().st_size if path.is_file() else None
        if size is None:
            return f"{rel}: missing"
        if size != record.get("size"):
            return f"{rel}: size changed ({record.get('size')} → {size} bytes)"
        if sha256_file(path) != record.get("sha256"):
            return f"{rel}: content changed"
    except OSError as exc:
        return f"{rel}: unreadable ({exc.strerror})"
    return None


def problems(folder: Path, manifest: dict) -> list[str]:
    """What is wrong with the files of ``folder`` against its manifest (empty: intact)."""
    records = manifest.get("files")
    if not isinstance(records, dict) or not records:
        return [f"{MANIFEST}: lists no files (written by an older symvi)"]
    found = [_file_problem(folder, rel, record) for rel, record in records.items()]
    return [p for p in found if p is not None]


def summary(found: list[str]) -> str:
    """``found`` as one line: the first few problems and how many more."""
    shown = "; ".join(found[:_SHOWN])
    return shown + (f"; and {len(found) - _SHOWN} more" if len(found) > _SHOWN else "")


@dataclass(frozen=True)
class Verdict:
    """The state of the package at ``DIR/<name>`` for one cache key.

    ``folder`` is the resolved package folder (None: there is no package); ``stale``
    means it was built for another key; ``damage`` lists what is wrong with it.
    """

    folder: Path | None
    stale: bool = False
    damage: list[str] = field(default_factory=list)

    @property
    def current(self) -> bool:
        """The package exists, was built for this key and is intact: reuse it."""
        return self.folder is not None and not self.stale and not self.damage


def inspect(target: Path, key: str) -> Verdict:
    """Check the package at ``target`` (a link to a version folder, or a folder)
    against ``key``, hashing its files only when the key matches."""
    if not target.exists():
        if target.is_symlink():
            return Verdict(target, damage=[f"{target.name} links to a missing folder "
                                           f"({target.readlink()})"])
        return Verdict(None)
    folder = target.resolve()
    manifest = read_manifest(folder)
    if manifest is None:
        return Verdict(folder, damage=[f"{MANIFEST}: missing or unreadable"])
    if manifest.get("key") != key:
        return Verdict(folder, stale=True)
    return Verdict(folder, damage=problems(folder, manifest))
