"""The files of a generated package: extension, C source, run-time copy, ``__init__.py``
and manifest, written into a (scratch) folder by :func:`write_package`.

User text (the model's name, description, parameter names, ...) reaches
``__init__.py`` only as escaped Python literals (:func:`python_string`,
:func:`python_literal`), never as code.
"""
from __future__ import annotations

import ast
from pathlib import Path
from typing import Any

from ..version import __version__
from .cache import file_records, write_manifest
from ..derivation.derive import DerivedModel
from ..codegen.emit import CSource, environment
from ..errors import BuildError
from .files import write_file, writing
from ..declaration.symbols import sign
from .._runtime.core.model_info import VERSION as MODEL_INFO_VERSION
from .._runtime.core.model_info import Defaults, GroupInfo, Kernel, KernelInfo, ModelInfo

#: The symvi package folder (its sources are part of the cache key).
PACKAGE = Path(__file__).resolve().parent.parent



def runtime_files() -> list[Path]:
    """The run-time sources copied into every package (``symvi/_runtime/**/*.py``: its
    ``__init__.py`` and ``compiled.py``, and the subpackages ``core/``, ``step/``, ``bvp/``
    and ``bounded/``)."""
    return sorted(path for path in (PACKAGE / "_runtime").rglob("*.py")
                  if "__pycache__" not in path.parts)


def python_string(text: str) -> str:
    """``text`` as a Python string literal: triple-quoted (readable, for docstrings)
    when that reads back exactly, else ``repr``."""
    plain = ("\\" not in text and '"""' not in text and not text.endswith('"')
             and all(c.isprintable() or c == "\n" for c in text))
    if plain:
        literal = f'"""{text}"""'
        if ast.literal_eval(literal) == text:
            return literal
    return repr(text)


def python_literal(value: Any) -> str:
    """``repr`` of a value built from str, numbers, bools, lists and dicts, checked to
    read back as that value (a non-finite float would not)."""
    literal = repr(value)
    try:
        same = ast.literal_eval(literal) == value
    except (ValueError, SyntaxError):
        same = False
    if not same:
        raise BuildError(f"cannot write {literal[:200]} as a Python literal in the generated "
                         f"__init__.py (a parameter default that is not a finite number?)")
    return literal


def fibre_nodes(dm: DerivedModel) -> list[int]:
    """Per fibre coordinate: the base coordinate of the element's target node that it
    copies (the C's ``node_copies``: a pair factor's f = q_{k+1}), or −1 (an increment
    ξ = τ⁻¹(w)/h, or anything else). The run time reads a state (x, v) into a first
    fibre through it, f_a = x_j + h·v_a or v_a (:mod:`._runtime.step.legendre`), and the
    velocity of a path out of it (:mod:`symvi.plots`)."""
    nodes = [-1] * dm.fibre_dim
    for copy in dm.c_context.node_copies:
        for k in range(copy.dim):
            nodes[copy.f_offset + k] = copy.x_offset + k
    return nodes


def info(dm: DerivedModel, key: str, description: str) -> ModelInfo:
    """The package's ``INFO``: what the run time needs to know of the model, typed
    (:class:`~symvi._runtime.core.model_info.ModelInfo`, written as its literal)."""
    return ModelInfo(
        version=MODEL_INFO_VERSION, name=dm.name, kind=dm.kind, order=dm.order,
        source_dim=dm.source_dim, fibre_dim=dm.fibre_dim,
        configuration_dim=dm.c_context.configuration_dim,
        parameters=tuple(str(s) for s in dm.parameters),
        defaults=Defaults((str(s), v) for s, v in zip(dm.parameters, dm.defaults)),
        parameter_signs=tuple(sign(s) for s in dm.parameters),
        coordinate_names=dm.coordinate_names, velocity_names=dm.velocity_names,
        control_names=dm.control_names, has_energy=dm.has_energy,
        initial_layout=dm.initial_layout, whole_trajectory=dm.whole_trajectory,
        lifted=bool(dm.fibre_sources), constraints=dm.constraint_count,
        constraint_names=tuple(dm.constraint_names), unactuated=tuple(dm.unactuated),
        end_free=dm.end_free, end_conditions=tuple(dm.end_names),
        controls=dm.control_count, inequalities=tuple(dm.inequality_names),
        boundary_inequalities=tuple(dm.boundary_names), intervals=tuple(dm.intervals),
        free_horizon=any(k.name == Kernel.HORIZON.value for k in dm.kernels),
        pure_minimum_time=dm.pure_minimum_time,
        step_scaled=tuple(dm.step_scaled), symmetries=tuple(dm.symmetries),
        gauges=tuple(dm.gauges),
        groups=tuple(GroupInfo(label=G.label, matrix_dim=G.matrix_dim,
                               **{k: _nested(v) for k, v in G.invariants.items()})
                     for G in dm.c_context.groups),
        fibre_nodes=tuple(fibre_nodes(dm)),
        configuration_base=tuple(dm.configuration_base),
        kernels=tuple(KernelInfo(name=k.name, nz=len(k.z),
                                 outputs=tuple(len(M) for _, M in k.outputs))
                      for k in dm.kernels),
        symvi_version=__version__, key=key, description=description)


def _nested(value: Any) -> Any:
    """Nested lists as nested tuples (a frozen :class:`GroupInfo`)."""
    return tuple(map(_nested, value)) if isinstance(value, (list, tuple)) else value


def _render_init(dm: DerivedModel, key: str, description: str, extension: str,
                 version: str, imported: dict[str, str]) -> str:
    env = environment()
    env.filters.update(pystring=python_string, pyliteral=python_literal)
    data = info(dm, key, description)
    literal = data.to_literal()
    if ModelInfo.from_literal(literal) != data:
        raise BuildError(f"model {dm.name!r}: INFO does not read back as written")
    defaults = ", ".join(f"{n}={v:g}" for n, v in zip(data.parameters, dm.defaults))
    return env.get_template("package_init.py.j2").render(
        name=dm.name, version=__version__, kind=dm.kind, order=dm.order, info=literal,
        extension=extension, description=description, defaults_text=defaults or "none",
        version_folder=version, files=imported)


def write_package(folder: Path, dm: DerivedModel, src: CSource, key: str, description: str,
                  built: Path, version: str) -> None:
    """Write the complete package into the new ``folder`` (manifest last).

    ``built`` is the compiled extension, ``version`` the name of the folder the package
    will be published as (``__init__.py`` pins its imports to it).
    """
    with writing(folder, "create"):
        (folder / "_runtime").mkdir(parents=True)
        for part in sorted({path.parent for path in runtime_files()} - {PACKAGE / "_runtime"}):
            (folder / part.relative_to(PACKAGE)).mkdir()
    with writing(built, "read the compiled extension"):
        extension = built.read_bytes()
    write_file(folder / built.name, extension)
    write_file(folder / f"{dm.name}.c", src.c_source)
    for name, text in src.units:
        write_file(folder / f"{dm.name}_{name}.c", text)
    for path in runtime_files():
        write_file(folder / path.relative_to(PACKAGE), path.read_bytes())
    imported = {rel: record["sha256"] for rel, record in file_records(folder).items()
                if not rel.endswith(".c")}
    init = _render_init(dm, key, description, built.name.split(".")[0], version, imported)
    write_file(folder / "__init__.py", init)
    write_manifest(folder, name=dm.name, key=key, extension=built.name, version=version)
