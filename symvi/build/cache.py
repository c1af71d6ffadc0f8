"""The build cache: what its key hashes besides the model, and the manifest.

The key (:func:`symvi.build.cache_key`) hashes, besides the model, the sources of the
code that generates a package (:func:`generating_sources`), the compiler
(:func:`compiler_identity`) and the libraries that shape the files
(:func:`library_versions`).

The manifest ``symvi.json`` of a generated package names the cache key it was built
for and records the size and SHA-256 of every file of the package (the extension, the
C source, ``__init__.py``, each ``_runtime/**/*.py``). A build is reused only when its key
matches and every recorded file is intact; files the manifest does not list (e.g.
``__pycache__``) are ignored.
"""
from __future__ import annotations

import ast
import functools
import hashlib
import importlib.metadata
import io
import itertools
import json
import os
import re
import shlex
import shutil
import sysconfig
import tokenize
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Iterator

from .files import sha256_file, write_file

MANIFEST = "symvi.json"
#: At most this many problems are spelled out in a message about a damaged package.
_SHOWN = 3

#: The symvi package folder.
SYMVI = Path(__file__).resolve().parent.parent
#: The modules the build runs to produce a package (``symvi.build._build``): the symbolic
#: stages, the package writer, the C compile and the script it runs in a child process,
#: and the groupoid classes, whose methods give a model its C context.
PIPELINE = ("symvi.discretisation.discretise", "symvi.derivation.derive", "symvi.codegen.emit",
            "symvi.build.package", "symvi.build.generic",
            "symvi.build.ccompile", "symvi.build._cffi_build", "symvi.groupoids")
#: Packages and modules whose code never reaches a generated file: the import closure
#: does not enter them. The checks read models and never build them; the bundled model
#: files are data (a model's content is in its fingerprint); ``symvi.build`` itself
#: (orchestration, loading, the key), the stage clock and its timing, and the lock and
#: swap only run the build. What of them reaches the files (compile flags, compiler) is
#: hashed by value.
_NOT_GENERATING_PACKAGES = ("symvi.checks", "symvi.models")
_NOT_GENERATING_MODULES = ("symvi.cli", "symvi.build", "symvi.build.stages",
                           "symvi.build.swap", "symvi.timing")
#: The keyword of every import statement: only lines that contain it are searched. (A
#: plain literal: the regular expression engine finds it fast; ``\b`` would slow it.)
_IMPORT_WORD = re.compile("import")
#: Where an import statement can begin: at the start of a line, or after the ``;`` or
#: ``:`` of a one-line compound statement (``if TYPE_CHECKING: from . import x``).
#: Matches inside strings are harmless: they fail to parse, or add a module too many.
_IMPORT_START = re.compile(
    r"(?:^|[;:])[ \t]*((?:from(?=[ \t.\\])(?:[ \t]|\\\n)*[.\w]+(?:[ \t]|\\\n)+)?import\b)",
    re.M)
#: Flags that setuptools (run by cffi) adds to the compile and link commands, each from
#: the environment variable of that name and from Python's build configuration.
_FLAG_VARIABLES = ("CFLAGS", "CPPFLAGS", "LDSHARED", "LDFLAGS")
#: The libraries that shape the generated files: SymPy simplifies and prints the C,
#: Jinja2 renders it, cffi writes the wrapper and drives the compile.
_LIBRARIES = ("sympy", "symengine", "jinja2", "cffi")


# -- the sources that generate a package ---------------------------------------------------
def generating_sources(extra_roots: Iterable[str] = ()) -> tuple[Path, ...]:
    """The source files of the :data:`PIPELINE` modules, of the symvi modules among
    ``extra_roots`` (e.g. the module of a model's class) and of every symvi module they
    import, directly or not, except the modules that never reach a generated file.

    Imports are found statically (conditional and function-level ones included) and
    relative ones resolved; ``from M import n`` imports ``M.n`` if that is a module,
    else ``M``. Computed once per process and set of roots.
    """
    own = frozenset(name for name in extra_roots if _module_file(name) is not None)
    return _closure(frozenset(PIPELINE) | own)


def sources_digest(extra_roots: Iterable[str] = ()) -> str:
    """Hash of :func:`generating_sources`, read once per process."""
    return _read_once(generating_sources(extra_roots))


@functools.lru_cache(maxsize=None)
def _read_once(paths: tuple[Path, ...]) -> str:
    return files_digest(paths)


def files_digest(paths: Iterable[Path]) -> str:
    """Hash of the files ``paths`` of the symvi package: their paths and contents."""
    h = hashlib.sha256()
    for path in sorted(paths):
        h.update(hashlib.sha256(path.relative_to(SYMVI).as_posix().encode()
                                + b"\0" + path.read_bytes()).digest())
    return h.hexdigest()


@functools.lru_cache(maxsize=None)
def _closure(roots: frozenset[str]) -> tuple[Path, ...]:
    seen: dict[str, Path] = {}
    pending = sorted(roots)
    while pending:
        name = pending.pop()
        path = _module_file(name)
        if name in seen or path is None or not _generates(name):
            continue
        seen[name] = path
        pending.extend(_imported(name, path))
    return tuple(sorted(set(seen.values())))


def _generates(name: str) -> bool:
    """Whether the module ``name`` may reach a generated file (see the exclusions)."""
    return name not in _NOT_GENERATING_MODULES and not any(
        name == p or name.startswith(p + ".") for p in _NOT_GENERATING_PACKAGES)


@functools.lru_cache(maxsize=None)
def _module_file(name: str) -> Path | None:
    """The source file of the symvi module ``name``; None if ``name`` is no module of
    symvi (another package's, or an attribute of a module)."""
    top, _, rest = name.partition(".")
    if top != "symvi":
        return None
    base = SYMVI.joinpath(*rest.split(".")) if rest else SYMVI
    candidates = [base / "__init__.py"] if not rest else [base.with_suffix(".py"),
                                                           base / "__init__.py"]
    return next((path for path in candidates if path.is_file()), None)


def _imported(name: str, path: Path) -> list[str]:
    """The absolute names of the modules that the source of module ``name`` imports."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []
    for node in _import_statements(path.read_text(encoding="utf-8")):
        if isinstance(node, ast.Import):
            found += [alias.name for alias in node.names]
        else:
            module = _absolute(package, node.module, node.level)
            found += [f"{module}.{a.name}" if _module_file(f"{module}.{a.name}") else module
                      for a in node.names]
    return found


def _absolute(package: str, module: str | None, level: int) -> str:
    """The absolute name of ``from <level dots><module> import ...`` in ``package``."""
    if level == 0:
        return module or ""
    base = package.rsplit(".", level - 1)[0] if level > 1 else package
    return f"{base}.{module}" if module else base


def _import_statements(source: str) -> Iterator[ast.Import | ast.ImportFrom]:
    """The import statements of ``source``.

    Parsing whole files costs some 150 ms for the closure; instead each line that says
    ``import`` (joined to the lines it continues with a backslash) is searched for places
    where an import statement can begin (:data:`_IMPORT_START`), and each is parsed with
    the rest of its logical line (:func:`_parse_statement`). A test checks that this
    finds what a full parse does in every module of symvi.
    """
    done = 0
    for word in _IMPORT_WORD.finditer(source):
        if word.start() < done:           # on a line already searched
            continue
        begin, done = _line_around(source, word.start())
        text = source[begin:done]
        for match in _IMPORT_START.finditer(text):
            body = _parse_statement(text[match.start(1):], source, done)
            yield from (n for n in body if isinstance(n, (ast.Import, ast.ImportFrom)))


def _line_around(source: str, position: int) -> tuple[int, int]:
    """Start and end of the line of ``source`` at ``position``, with the lines before it
    that a backslash continues (``from x \\`` then ``import y``)."""
    end = source.find("\n", position) + 1 or len(source)
    begin = source.rfind("\n", 0, position) + 1
    while begin >= 2 and source[begin - 2] == "\\":
        begin = source.rfind("\n", 0, begin - 1) + 1
    return begin, end


def _parse_statement(first: str, source: str, end: int) -> list[ast.stmt]:
    """The statements of the logical line that begins with ``first`` and may go on in
    ``source`` after ``end`` (none if it is not code: text in a string that looks like
    an import).

    A line that parses on its own is the whole logical line (open brackets, a trailing
    backslash or an open string would make it fail), so the tokenizer only reads on
    when it does not.
    """
    try:
        return ast.parse(first).body
    except SyntaxError:
        pass
    following = io.StringIO(source)
    following.seek(end)
    statement = _logical_line(itertools.chain([first], iter(following.readline, "")))
    try:
        return ast.parse(statement).body if statement is not None else []
    except SyntaxError:
        return []


def _logical_line(lines: Iterator[str]) -> str | None:
    """The first logical line of ``lines`` (None if it does not tokenize)."""
    read: list[str] = []

    def readline() -> str:
        line = next(lines, "")
        read.append(line)
        return line
    try:
        for token in tokenize.generate_tokens(readline):
            if token.type in (tokenize.NEWLINE, tokenize.ENDMARKER):
                return "".join(read)
    except (tokenize.TokenError, SyntaxError):
        return None
    return None


# -- the compiler and the libraries ---------------------------------------------------------
def compiler_command() -> str:
    """The compiler command cffi (through setuptools) runs: ``$CC``, else Python's."""
    return os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc"


def compiler_identity() -> str:
    """The compiler cffi would run and the flags setuptools adds (from the environment
    and from Python's build configuration). The compiler is its command and, for each
    word of it that names a program (``ccache gcc``: both), the program's resolved path
    and the SHA-256 of that file, hashed once per process.

    The compiler is identified by its files, not by running ``cc --version``: the key
    is computed on every cache hit and before a build's timeout applies, when a
    compiler wrapper (ccache, distcc, a script) should not run.
    """
    flags = [(var, os.environ.get(var), sysconfig.get_config_var(var))
             for var in _FLAG_VARIABLES]
    command = compiler_command()
    try:
        words = shlex.split(command)
    except ValueError:                  # unbalanced quotes: find_compiler says so
        words = []
    programs = [os.path.realpath(found) for found in map(shutil.which, words) if found]
    files = [(path, _file_digest(path)) for path in programs]
    return repr((command, files, flags))


@functools.lru_cache(maxsize=None)
def _file_digest(path: str) -> str:
    try:
        return sha256_file(Path(path))
    except OSError as exc:
        return f"unreadable ({exc.strerror})"


@functools.lru_cache(maxsize=None)
def library_versions() -> str:
    """The installed versions of the libraries that shape the generated files."""
    return ", ".join(f"{name} {importlib.metadata.version(name)}" for name in _LIBRARIES)


# -- the manifest ---------------------------------------------------------------------------
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
