"""ARCHITECTURE.md against the tree, and the house rules on whole packages (issue 49).

Read from the sources, like ``test_layout.py``, whose rules (module-level import circles,
``kind`` branches, the table's files) this extends: every file ARCHITECTURE.md names
exists and every module and template is named there; no import cycle between symvi's
packages; no module-level mutable state.
"""
from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from test_layout import _lines, _modules

ROOT = Path(__file__).resolve().parent.parent
SYMVI = ROOT / "symvi"
TEXT = (ROOT / "ARCHITECTURE.md").read_text(encoding="utf-8")

#: The packages whose dependencies must run one way.
PACKAGES = ("declaration", "groupoids", "discretisation", "derivation", "codegen", "build",
            "_runtime", "checks")
#: Modules that count as units of their own in the package graph: the rule table, which
#: the groupoids read to list their rules and which imports no groupoid (ARCHITECTURE.md,
#: "Rules of the house"); the rest of ``discretisation`` reads the groupoids.
OWN_UNITS = ("symvi.discretisation.rules",)


# -- ARCHITECTURE.md names every module, and only modules that exist ---------------------
def _files() -> set[str]:
    """Every module of symvi and every template, by its path from the repository root."""
    return ({p.relative_to(ROOT).as_posix() for p in SYMVI.rglob("*.py")}
            | {p.relative_to(ROOT).as_posix() for p in (ROOT / "templates").glob("*.j2")})


def _table_rows() -> list[tuple[tuple[str, ...], str]]:
    """(the folders of the row, the row's text) for each row of the table of folders."""
    rows = []
    for line in TEXT.splitlines():
        match = re.match(r"^\| ((?:`[\w/]+/`(?:, )?)+) \|", line)
        if match:
            rows.append((tuple(re.findall(r"`([\w/]+)/`", match.group(1))), line))
    return rows


def _named() -> tuple[set[str], list[str]]:
    """The files ARCHITECTURE.md names, by path from the root, and the names it gives that
    match no file. A name is a path from the root (``symvi/cli.py``,
    ``templates/bvp.c.j2``, ``tests/test_layout.py``) or from ``symvi/``
    (``build/cache.py``), or a bare file name in a row of the table,
    which lies in one of that row's folders; a folder named with a trailing ``/``
    (``symvi/checks/``) names its ``__init__.py``."""
    files = _files()
    named, unknown = set(), []
    paths = re.findall(r"(?<![\w/<>.])((?:symvi|templates|[a-z_]+)/[\w/]*[\w]+\.(?:py|j2))\b",
                       TEXT)
    for path in paths:
        found = [p for p in (path, f"symvi/{path}") if (ROOT / p).is_file()]
        named |= set(found[:1]) & files
        if not found:
            unknown.append(path)
    for folder in re.findall(r"`((?:symvi|templates)(?:/[\w]+)*)/`", TEXT):
        if f"{folder}/__init__.py" in files:
            named.add(f"{folder}/__init__.py")
    for folders, line in _table_rows():
        for name in re.findall(r"`([\w.]+\.(?:py|j2))`", line):
            found = [f"{folder}/{name}" for folder in folders if f"{folder}/{name}" in files]
            named |= set(found)
            if not found:
                unknown.append(f"{'|'.join(folders)}/{name}")
    return named, unknown


def test_architecture_names_only_modules_that_exist():
    _, unknown = _named()
    assert not unknown, f"ARCHITECTURE.md names files that do not exist: {unknown}"


def test_architecture_names_every_module_and_template():
    named, _ = _named()
    unnamed = sorted(_files() - named)
    assert not unnamed, f"modules ARCHITECTURE.md does not name: {unnamed}"


def test_the_names_are_read_as_files():
    """The reading above finds the table's rows and what they name (a guard against a
    change of format that would make both tests pass vacuously)."""
    named, _ = _named()
    assert {"symvi/_runtime/core/results.py", "symvi/build/cache.py", "symvi/cli.py",
            "templates/kernel.c.j2", "symvi/declaration/rank.py"} <= named
    assert len(_table_rows()) >= 9


# -- no import cycle between packages ---------------------------------------------------
def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
        (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The symvi modules ``name`` imports anywhere — at load or inside a function, which
    is a dependency all the same — except under ``if TYPE_CHECKING:`` (annotations only,
    never run)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    stack = list(ast.parse(path.read_text(encoding="utf-8")).body)
    while stack:
        node = stack.pop()
        if isinstance(node, ast.If) and _is_type_checking(node):
            stack.extend(node.orelse)
            continue
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = package.rsplit(".", node.level - 1)[0] if node.level else ""
            module = ".".join(p for p in (base, node.module) if p)
            found |= {f"{module}.{a.name}" if f"{module}.{a.name}" in modules else module
                      for a in node.names}
        stack.extend(ast.iter_child_nodes(node))
    return found & modules.keys()


def _unit(module: str) -> str | None:
    """The unit of the package graph ``module`` belongs to (None: outside the packages)."""
    if module in OWN_UNITS:
        return module
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in PACKAGES else None


def package_edges() -> dict[tuple[str, str], list[str]]:
    """(importing unit, imported unit) -> the module imports that make the edge."""
    modules = _modules()
    edges: dict[tuple[str, str], list[str]] = {}
    for name, path in modules.items():
        for target in _imports(name, path, modules):
            a, b = _unit(name), _unit(target)
            if a and b and a != b:
                edges.setdefault((a, b), []).append(f"{name} -> {target}")
    return edges


def test_no_import_cycle_between_packages():
    edges = package_edges()
    units = sorted({u for edge in edges for u in edge})
    index = {u: i for i, u in enumerate(units)}
    rows, cols = np.array([(index[a], index[b]) for a, b in edges]).T
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(units),) * 2)
    count, labels = connected_components(graph, directed=True, connection="strong")
    cycles = [[units[i] for i in np.flatnonzero(labels == c)] for c in range(count)]
    cycles = [c for c in cycles if len(c) > 1]
    detail = {edge: found for edge, found in edges.items()
              if any(set(edge) <= set(c) for c in cycles)}
    assert not cycles, f"import cycles between packages: {cycles}; through {detail}"


#: The pipeline's order (ARCHITECTURE.md): a unit imports only units before it.
LAYERS = ("symvi.discretisation.rules", "groupoids", "declaration", "discretisation",
          "derivation", "codegen", "build", "checks")


def test_the_pipeline_runs_one_way():
    """Each package imports only those before it in the pipeline: the declaration neither
    the discretisation nor the derivation (issue 49's reach-backs), the run time no symvi
    package. Another package may read the run time only in its leaves, modules that import
    no other module of the run time (the shared constants of ``_runtime/core/signs.py``, which
    imports nothing at all, read by the declaration): never its machinery."""
    edges = package_edges()
    backwards = {edge: found for edge, found in edges.items()
                 if edge[0] == "_runtime" or (edge[1] != "_runtime"
                                              and LAYERS.index(edge[1]) >= LAYERS.index(edge[0]))}
    assert not backwards, f"imports against the pipeline: {backwards}"
    modules = _modules()
    read = {link.rpartition(" -> ")[2] for (_, b), found in edges.items() if b == "_runtime"
            for link in found}
    assert "symvi._runtime.core.signs" in read
    machinery = sorted(m for m in read
                       if _imports(m, modules[m], modules) - {m} or modules[m].name == "__init__.py")
    assert not machinery, f"other packages read the run time's machinery: {machinery}"
    signs = ast.parse((SYMVI / "_runtime" / "core" / "signs.py").read_text(encoding="utf-8"))
    assert not [n for n in ast.walk(signs) if isinstance(n, (ast.Import, ast.ImportFrom))]


# -- no module-level mutable state --------------------------------------------------------
#: Methods that change a dict, list, set, deque or OrderedDict in place, or take a lock.
MUTATORS = {"append", "extend", "insert", "pop", "popitem", "remove", "clear", "update",
            "setdefault", "add", "discard", "move_to_end", "appendleft", "sort", "reverse",
            "difference_update", "intersection_update", "symmetric_difference_update",
            "acquire", "release"}
#: Calls that make a mutable container or a lock.
MUTABLE_CALLS = {"dict", "list", "set", "OrderedDict", "defaultdict", "deque", "Counter",
                 "bytearray", "Lock", "RLock", "Semaphore", "Condition", "Event"}
#: Module-level state kept on purpose, each with its reason: (file, name) -> why.
KEPT = {
    ("symvi/build/__init__.py", "_LOAD_LOCK"):
        "guards sys.modules, which is process-wide by nature, while a package loads",
    ("symvi/derivation/derive.py", "PROCESS_CACHE"):
        "the derivations a process shares by default (the build, the checks and a test "
        "session derive the same models); an explicit object passed as derive's default "
        "argument, which a caller replaces with its own",
}


def _mutable(value: ast.expr) -> bool:
    if isinstance(value, (ast.Dict, ast.List, ast.Set, ast.DictComp, ast.ListComp,
                          ast.SetComp)):
        return True
    if isinstance(value, ast.Call):
        f = value.func
        return (f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", None)) \
            in MUTABLE_CALLS
    return False


def _module_state(tree: ast.Module) -> set[str]:
    """Names a module binds at its top level to a mutable container or a lock."""
    names = set()
    for node in tree.body:
        if isinstance(node, ast.Assign):
            targets, value = node.targets, node.value
        elif isinstance(node, ast.AnnAssign) and node.value is not None:
            targets, value = [node.target], node.value
        else:
            continue
        names |= {t.id for t in targets if isinstance(t, ast.Name) and _mutable(value)}
    return names


def _changes(node: ast.AST, names: set[str]) -> str | None:
    """The module-level name ``node`` changes in place (or takes, a lock), if any."""
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
            and isinstance(node.func.value, ast.Name) and node.func.value.id in names \
            and node.func.attr in MUTATORS:
        return node.func.value.id
    if isinstance(node, (ast.Assign, ast.AugAssign, ast.Delete)):
        targets = [node.target] if isinstance(node, ast.AugAssign) else node.targets
        for t in targets:
            if isinstance(t, (ast.Subscript, ast.Attribute)) and isinstance(t.value, ast.Name) \
                    and t.value.id in names:
                return t.value.id
    if isinstance(node, (ast.With, ast.AsyncWith)):
        for item in node.items:
            if isinstance(item.context_expr, ast.Name) and item.context_expr.id in names:
                return item.context_expr.id
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
            and node.func.id == "globals":
        return "globals()"
    return None


def mutable_state(path: Path) -> list[tuple[str, int, str]]:
    """(name, line, what) for each change of module-level state after the module has
    loaded: a container or lock bound at the top level and changed inside a function, a
    ``global`` statement, a write through ``globals()``. Building a constant at the top
    level (a list appended to while the module loads) is not state."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = _module_state(tree)
    found = []
    functions = [n for n in ast.walk(tree)
                 if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))]
    found += [(t.id, node.lineno, "a cache held by the module") for node in tree.body
              if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call)
              and getattr(node.value.func, "id", "").endswith("Cache")
              for t in node.targets if isinstance(t, ast.Name)]
    for function in functions:
        for node in ast.walk(function):
            if isinstance(node, ast.Global):
                found += [(name, node.lineno, "global statement") for name in node.names]
            name = _changes(node, names)
            if name:
                found.append((name, node.lineno, "changed in a function"))
    return sorted(set(found))


def test_no_module_level_mutable_state():
    offending = []
    for path in sorted(SYMVI.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        offending += [f"{rel}:{line}: {name} ({what})" for name, line, what in
                      mutable_state(path) if (rel, name) not in KEPT]
    assert not offending, "module-level mutable state:\n" + "\n".join(offending)


def test_the_state_scan_finds_state(tmp_path):
    """The scan sees a cache dict filled in a function, a lock taken, ``global``, a
    write through ``globals()`` and a cache object held by the module; not a constant
    built while the module loads."""
    source = tmp_path / "m.py"
    source.write_text("import threading\n"
                      "_MEMO = {}\n_LOCK = threading.Lock()\nCOUNT = 0\nTABLE = []\n"
                      "SHARED = DerivationCache()\n"
                      "TABLE.append(1)\nNAMES = ('a', 'b')\n"
                      "def f(k):\n    with _LOCK:\n        _MEMO[k] = 1\n"
                      "def g():\n    global COUNT\n    COUNT += 1\n"
                      "def h():\n    globals()['x'] = 1\n    return TABLE[0], NAMES\n")
    assert [(n, w) for n, _, w in mutable_state(source)] == [
        ("COUNT", "global statement"), ("SHARED", "a cache held by the module"),
        ("_LOCK", "changed in a function"),
        ("_MEMO", "changed in a function"), ("globals()", "changed in a function")]


# -- the compile → run contract is one typed ModelInfo (issue 49, item 2) ------------------
#: A string lookup in the package's metadata: ``info[…]``, ``INFO[…]``, ``info.get(…)``,
#: ``INFO.get(…)`` (``model.info``, ``self.info``, ``module.INFO`` alike).
INFO_LOOKUP = re.compile(r"""\b(?:info|INFO)\s*(?:\[|\.get\s*\()""")
#: A kernel named by a free string where the run time calls or looks one up:
#: ``along_vector("gauge", …)``, ``kernel_outputs("end_horizon", …)``, ``kernel("step")``.
KERNEL_BY_STRING = re.compile(r"""\b(?:along_vector|along|kernel_outputs|evaluate|kernel"""
                              r"""|has_kernel|_points|width)\s*\(\s*["']"""
                              r"""|\b_Quantity\s*\(\s*["'][^"']*["']\s*,\s*["']"""
                              r"""|\b_points\s*\(\s*\w+\s*,\s*["']""")


def test_model_info_is_read_by_attribute():
    """No ``info[…]``/``info.get(…)``/``INFO[…]`` string lookup is left in symvi/ (the run
    time included) or the templates: what a package knows about its model is
    ``_runtime/core/model_info.py``'s frozen ``ModelInfo``, read by attribute; and the run
    time names the kernels it calls by ``Kernel``, not by strings."""
    sources = [*sorted(SYMVI.rglob("*.py")), *sorted((ROOT / "templates").glob("*.j2"))]
    lookups = [where for where, line in _lines(sources) if INFO_LOOKUP.search(line)]
    assert not lookups, "string lookups in INFO:\n" + "\n".join(lookups)
    runtime = sorted((SYMVI / "_runtime").rglob("*.py"))
    named = [where for where, line in _lines(runtime) if KERNEL_BY_STRING.search(line)]
    assert not named, "kernels named by strings in the run time:\n" + "\n".join(named)
    for line in ('spec = self.info["kernels"].get(kernel)', "info['kind']", 'INFO["key"]',
                 'model.info.get("gauges", ())', 'int(info.get("controls") or 0)',
                 "{model.info['kind']} groupoid", 'info ["x"]'):
        assert INFO_LOOKUP.search(line), line
    for line in ('model.along_vector("gauge", x, f, h, p)', 'kernel_outputs("end_horizon", z)',
                 '_points(model, "legendre", Z, P, H)', 'width("momentum_plus")',
                 '_Quantity("momenta", "momentum_minus", w, 0, r)'):
        assert KERNEL_BY_STRING.search(line), line
    for line in ("info.kernel(Kernel.STEP).nz", "INFO.fibre_nodes", "information[0]",
                 "model.along_vector(Kernel.GAUGE, x, f, h, p)",
                 '_Quantity("momenta", Kernel.MOMENTUM_MINUS, w, 0, r)'):
        assert not INFO_LOOKUP.search(line) and not KERNEL_BY_STRING.search(line), line


def test_model_info_is_a_leaf_of_the_run_time():
    """The build writes ``INFO`` through ``ModelInfo`` and the package reads it back: the
    module imports the standard library only (symvi reads it, a package cannot import
    symvi), and its schema version is an integer the literal carries."""
    path = SYMVI / "_runtime" / "core" / "model_info.py"
    tree = ast.parse(path.read_text(encoding="utf-8"))
    imported = {alias.name.split(".")[0] for node in ast.walk(tree)
                if isinstance(node, ast.Import) for alias in node.names}
    imported |= {(node.module or "").split(".")[0] for node in ast.walk(tree)
                 if isinstance(node, ast.ImportFrom) and not node.level}
    assert not [n for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.level]
    assert imported <= {"__future__", "dataclasses", "enum", "typing"}, imported


# -- the run time's parts run one way -----------------------------------------------------
#: The run time's parts (ARCHITECTURE.md), each importing only those before it.
RUNTIME_PARTS = ("core", "step", "bvp", "bounded")
#: The imports against that order, each inside the function that needs it: the fixed-horizon
#: solve reaches the bounded solve only for a model with inequalities.
RUNTIME_LAZY = {"symvi._runtime.bvp.bvp -> symvi._runtime.bounded.barrier",
                "symvi._runtime.bvp.bvp -> symvi._runtime.bounded.bounded"}


def _module_level(path: Path) -> list[ast.AST]:
    """The statements run when ``path`` loads (not those inside a function)."""
    found, stack = [], list(ast.parse(path.read_text(encoding="utf-8")).body)
    while stack:
        node = stack.pop()
        found.append(node)
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            stack.extend(ast.iter_child_nodes(node))
    return found


def test_the_runtime_parts_run_one_way():
    """``core/`` ← ``step/`` ← ``bvp/`` ← ``bounded/``: a part imports no part after it,
    but for :data:`RUNTIME_LAZY`, made inside a function; the top (``__init__.py``,
    ``compiled.py``) loads ``core/`` and ``step/`` only — ``bvp/`` is imported by name on
    a model's first whole-trajectory call — and no module of ``core/`` or ``step/`` loads
    SciPy. So a package whose model is only stepped runs on numpy and cffi alone."""
    modules = {name: path for name, path in _modules().items()
               if name.startswith("symvi._runtime")}

    def part(name: str) -> str | None:
        parts = name.split(".")
        return parts[2] if len(parts) > 2 and parts[2] in RUNTIME_PARTS else None

    backwards, lazy_found = [], set()
    for name, path in modules.items():
        for target in _imports(name, path, modules):
            a, b = part(name), part(target)
            if a is None or b is None or RUNTIME_PARTS.index(b) <= RUNTIME_PARTS.index(a):
                continue
            link = f"{name} -> {target}"
            if link in RUNTIME_LAZY:
                lazy_found.add(link)
            else:
                backwards.append(link)
    assert not backwards, f"run-time imports against core ← step ← bvp ← bounded: {backwards}"
    assert lazy_found == RUNTIME_LAZY
    for name, path in modules.items():
        loaded = {(node.module or "") if isinstance(node, ast.ImportFrom) else alias.name
                  for node in _module_level(path)
                  if isinstance(node, (ast.Import, ast.ImportFrom)) for alias in node.names}
        if part(name) in (None, "core", "step"):
            assert not any(m.split(".")[0] == "scipy" for m in loaded), name
        if part(name) is None:           # the top: core/ and step/ at load, never bvp/
            assert not {m for m in loaded
                        if m.lstrip(".").split(".")[0] in ("bvp", "bounded")}, name
        elif part(name) == "bvp":
            assert not {m for m in loaded if m.lstrip(".").split(".")[0] == "bounded"}, name


def test_the_symbolic_side_looks_kernels_up_by_kernel_not_by_string():
    """The checks and the derivation ask a DerivedModel for its kernels by the run time's
    ``Kernel`` names (``dm.kernel(KernelName.STEP)``), not by free strings (issue 49)."""
    pattern = re.compile(r"\.kernel\(\s*[\"']")
    offending = [f"{path.relative_to(SYMVI.parent)}:{number}: {line.strip()}"
                 for path in sorted(SYMVI.rglob("*.py"))
                 for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
                 if pattern.search(line)]
    assert not offending, "kernels looked up by a string:\n" + "\n".join(offending)
    assert pattern.search('derived.kernel("step")') and not pattern.search("dm.kernel(Kernel.STEP)")
