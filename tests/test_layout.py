"""The rules of the house (ARCHITECTURE.md, issue 19) hold on the code as it is.

Each test reads the package's sources, not a list kept by hand: a new ``kind`` branch
outside the groupoids, a module-level import circle or a file that ARCHITECTURE.md names
but that was moved fails here.
"""
from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

ROOT = Path(__file__).resolve().parent.parent
SYMVI = ROOT / "symvi"


def _modules() -> dict[str, Path]:
    """Every module of the package by its dotted name (a package by its __init__)."""
    found = {}
    for path in SYMVI.rglob("*.py"):
        parts = path.relative_to(ROOT).with_suffix("").parts
        found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def _imports_at_load(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The symvi modules that importing ``name`` imports at once: its top-level import
    statements (imports inside functions run later and cannot close a circle at load)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = package.rsplit(".", node.level - 1)[0] if node.level else ""
            module = ".".join(p for p in (base, node.module) if p)
            found |= {f"{module}.{a.name}" if f"{module}.{a.name}" in modules else module
                      for a in node.names}
    return found & modules.keys()


def test_no_kind_branches_outside_the_groupoids():
    branch = re.compile(r"\bkind\s*(==|in\b)")
    offending = [f"{path.relative_to(ROOT)}:{number}: {line.strip()}"
                 for path in SYMVI.rglob("*.py") if "groupoids" not in path.parts
                 for number, line in enumerate(path.read_text().splitlines(), 1)
                 if branch.search(line)]
    assert not offending, "kind branches outside symvi/groupoids/:\n" + "\n".join(offending)


def test_no_module_level_import_circles():
    modules = _modules()
    names = sorted(modules)
    index = {name: i for i, name in enumerate(names)}
    edges = [(index[a], index[b]) for a in names
             for b in _imports_at_load(a, modules[a], modules) if b != a]
    rows, cols = np.array(edges).T
    graph = coo_matrix((np.ones(len(edges)), (rows, cols)), shape=(len(names),) * 2)
    count, labels = connected_components(graph, directed=True, connection="strong")
    circles = [sorted(names[i] for i in np.flatnonzero(labels == c)) for c in range(count)]
    circles = [c for c in circles if len(c) > 1]
    assert not circles, f"import circles: {circles}"


def test_architecture_names_only_files_that_exist():
    """Each file ARCHITECTURE.md names in its table lies in the folder of its row."""
    text = (ROOT / "ARCHITECTURE.md").read_text()
    missing = []
    for row in re.findall(r"^\| `([\w/]+)/`.*$", text, flags=re.M):
        line = next(l for l in text.splitlines() if l.startswith(f"| `{row}/`"))
        folder = ROOT / ("templates" if row == "templates" else row)
        for name in re.findall(r"`([\w.]+\.(?:py|j2))`", line):
            if not (folder / name).is_file():
                missing.append(f"{row}/{name}")
    assert len(re.findall(r"^\| `", text, flags=re.M)) >= 9
    assert not missing, f"ARCHITECTURE.md names files that do not exist: {missing}"
