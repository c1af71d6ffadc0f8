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


#: A test of a groupoid's kind: ``kind ==``, ``kind in``, ``kind !=``, ``info["kind"] ==``
#: (Python), ``F.kind == …``, ``selectattr("kind", "equalto", …)`` (Jinja), and a lookup
#: by kind, ``TABLE[g.kind]``. Reading it for a message or the metadata is no branch.
KIND_BRANCH = re.compile(r"""\bkind\b["']?\]?\s*(==|!=|in\b)|["']kind["']\s*,\s*["']equalto"""
                         r"""|\[\s*[\w.]+\.kind\s*\]|\[\s*\w+\[["']kind["']\]\s*\]""")
#: A test of a retraction's name: ``.name == "cayley"``, ``retraction == "exp"``,
#: ``"cayley" in …``, a Jinja ``equalto``/``rejectattr`` on ``retraction``.
RETRACTION_NAMES = r"""["'](?:cayley|exp)["']"""
RETRACTION_BRANCH = re.compile(
    rf"""(==|!=)\s*{RETRACTION_NAMES}|{RETRACTION_NAMES}\s*(==|!=|in\b)"""
    rf"""|["']retraction["']\s*,\s*["']equalto|retraction\s*(==|!=)""")


def _lines(paths, skip=lambda path: False):
    for path in paths:
        if skip(path):
            continue
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            yield f"{path.relative_to(ROOT)}:{number}: {line.strip()}", line


def _sources():
    """symvi/ (the run time included) and templates/."""
    return [*sorted(SYMVI.rglob("*.py")), *sorted((ROOT / "templates").glob("*.j2"))]


def test_no_kind_branches_outside_the_groupoids():
    """Outside symvi/groupoids/ nothing tests a groupoid's kind (symvi/, the run time,
    the templates): what differs between kinds is data or methods the groupoid gives."""
    offending = [where for where, line in _lines(_sources(),
                                                 skip=lambda p: "groupoids" in p.parts)
                 if KIND_BRANCH.search(line)]
    assert not offending, "kind branches outside symvi/groupoids/:\n" + "\n".join(offending)


def test_no_kind_branches_in_templates_and_runtime():
    """Neither the templates nor the run time read a kind at all (the run time may show
    ``INFO.kind`` in messages and results, never branch on it)."""
    runtime = sorted((SYMVI / "_runtime").rglob("*.py"))
    templates = sorted((ROOT / "templates").glob("*.j2"))
    offending = [where for where, line in _lines([*runtime, *templates])
                 if re.search(r"""\bkind\b["']?\s*(==|!=|in\b)|F\.kind|"kind",""", line)]
    assert not offending, "kind tests in templates/ or _runtime/:\n" + "\n".join(offending)


def test_no_retraction_name_branches():
    """Retractions differ by their classes' methods and the C macros they name; their
    names are read only in the registry of symvi/groupoids/retraction.py (the bundled
    models choose a name for their own, not a behaviour: symvi/models/ is user code)."""
    registry = SYMVI / "groupoids" / "retraction.py"
    offending = [where for where, line in _lines(_sources(),
                                                 skip=lambda p: p == registry
                                                 or p.parent == SYMVI / "models")
                 if RETRACTION_BRANCH.search(line)]
    assert not offending, "retraction-name branches:\n" + "\n".join(offending)


#: Run-time files that still read the old flag, until they read what replaced it
#: (compiled.py: ``paths.initial_layout(model).read``; issue 49).
NODE_PAIRS_PENDING: set[str] = set()


def test_the_runtime_reads_what_to_do_not_a_node_pairs_flag():
    """The run time maps states to fibres and back through ``INFO.fibre_nodes`` and
    reads initial data in the layout ``INFO.initial_layout`` names; no test of
    ``node_pairs``."""
    runtime = [p for p in sorted((SYMVI / "_runtime").rglob("*.py"))
               if p.name not in NODE_PAIRS_PENDING]
    offending = [where for where, line in _lines([*runtime, SYMVI / "plots.py"])
                 if "node_pairs" in line]
    assert not offending, "node_pairs tests in the run time:\n" + "\n".join(offending)


def test_the_branch_patterns_catch_what_they_must():
    """The patterns above catch the branches that were removed (issue 49)."""
    for line in ('if F.kind == "pair"', '{% if F.kind == "pair" %}', "if g.kind in ('a',):",
                 '{% if factors | selectattr("kind", "equalto", "pair") | list %}',
                 'if info["kind"] != "lie":', "READERS[groupoid.kind](x)",
                 'READERS[info["kind"]](x)'):
        assert KIND_BRANCH.search(line), line
    for line in ('if self.retraction.name == "cayley":', '{% if G.retraction == "exp" %}',
                 'groups | rejectattr("retraction", "equalto", "cayley")',
                 'elif self.retraction.name == "exp" and _numeric(X):'):
        assert RETRACTION_BRANCH.search(line), line
    for line in ('kind=model.info["kind"], bound_multipliers=z',
                 'def __exit__(self, kind, exc, tb):',
                 'retraction: str = "cayley"', 'G = SO3(retraction=retraction)',
                 '"name": dm.name, "kind": dm.kind,', "names.get(arr.dtype.kind, 'x')",
                 "f\"(this is a {model.info['kind']} groupoid)\""):
        assert not KIND_BRANCH.search(line) and not RETRACTION_BRANCH.search(line), line


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
