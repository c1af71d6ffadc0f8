"""What a compiled package knows about its model: :class:`ModelInfo`, the one typed
contract between the build and the run time.

The build (``symvi/build/package.py``) fills one :class:`ModelInfo` and writes it into
the package's ``__init__.py`` as a Python literal (:meth:`ModelInfo.to_literal`); the
package reads it back with :meth:`ModelInfo.from_literal` when it is imported, and
publishes it as ``INFO``. The run time reads it by attribute (``model.info.fibre_nodes``)
and names kernels by :class:`Kernel`, never by free strings.

A literal of another schema :data:`VERSION`, or with a key too many or too few, or a
value of the wrong type, is refused at load with a :class:`ModelInfoError` that says to
recompile. A leaf of the run time: it imports the standard library only (the build reads
it too, and a generated package cannot import symvi).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from enum import Enum
from typing import Any, Iterator, Mapping

#: The schema version of :class:`ModelInfo`: raised whenever a field is added, removed,
#: renamed or changes meaning, so that a package written with another schema is refused.
VERSION = 5


class ModelInfoError(ValueError):
    """A package's ``INFO`` literal does not fit this run time's :class:`ModelInfo`."""


class Kernel(Enum):
    """The compiled kernels the run time calls; the value is the C name's stem
    (``symvi_<value>``, ``symvi_<value>_path``, ``symvi_<value>_points``). A model has
    those its derivation produced (:meth:`ModelInfo.has_kernel`); the end stencils
    ``stencil_end<j>`` are named by string only (:meth:`ModelInfo.kernel`)."""

    STEP = "step"
    PREDICT = "predict"
    TARGET = "target"
    VARIATIONS = "variations"
    LAGRANGIAN = "lagrangian"
    MANIFOLD = "manifold"
    STENCIL = "stencil"
    MOVE = "move"
    CONSTRAINT = "constraint"
    INEQUALITY = "inequality"
    BOUNDARY = "boundary"
    GAUGE = "gauge"
    CONTROLS = "controls"
    HORIZON = "horizon"
    NOETHER = "noether"
    ENERGY = "energy"
    END_CONDITION = "end_condition"
    END_HORIZON = "end_horizon"
    WINDOW_HESSIAN = "window_hessian"
    VARIATIONS_DUAL = "variations_dual"
    MOMENTUM_PLUS = "momentum_plus"
    MOMENTUM_MINUS = "momentum_minus"
    LEGENDRE = "legendre"


def kernel_name(kernel: Kernel | str) -> str:
    """The C stem of ``kernel``: a :class:`Kernel`'s value, or a name as given. Any
    package's :class:`Kernel` (each package holds its own copy of this module)."""
    return kernel.value if isinstance(kernel, Enum) else kernel


class Defaults(Mapping):
    """The parameters' defaults by name, in the order of the parameter vector p: a
    read-only mapping (``INFO.defaults["l"]``, ``dict(INFO.defaults)``), hashable like the
    rest of a :class:`ModelInfo`."""

    def __init__(self, items: Mapping[str, float] | Any = ()):
        pairs = tuple((items.items() if isinstance(items, Mapping) else items))
        self._items = tuple((str(k), v) for k, v in pairs)
        self._index = dict(self._items)

    def __getitem__(self, name: str) -> float:
        return self._index[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._index)

    def __len__(self) -> int:
        return len(self._items)

    def __hash__(self) -> int:
        return hash(self._items)

    def __repr__(self) -> str:
        return repr(self._index)


@dataclass(frozen=True)
class KernelInfo:
    """One compiled kernel."""

    #: The kernel's name, the stem of its C functions (a :class:`Kernel` value, or
    #: ``stencil_end<j>``).
    name: str
    #: Length of its coordinates z (base point, then the elements of its window).
    nz: int
    #: Size of each output, in order (a Jacobian flattened).
    outputs: tuple[int, ...]

    def width(self, m: int, n: int) -> int:
        """Elements in the kernel's window, for base dimension ``m`` and fibre ``n``."""
        return (self.nz - m) // n


@dataclass(frozen=True)
class GroupInfo:
    """One matrix-group factor of the configuration (``MatrixLieGroup.invariants``): the
    conditions a configuration g must meet to lie on it, checked on the user's data."""

    #: The group's label (``SO(3)``, ``SE(2)``, …).
    label: str
    #: d: configurations are d × d matrices (d² entries of the flat g).
    matrix_dim: int
    #: Bases J of the invariant quadratic forms, gᵀJg = J.
    quadratic: tuple
    #: Bases K of the invariant co-forms, gKgᵀ = K.
    coquadratic: tuple
    #: Fixed vectors, g v = v.
    fixed: tuple
    #: Fixed covectors, wᵀg = wᵀ.
    cofixed: tuple

    @property
    def invariants(self) -> dict[str, tuple]:
        """The conditions as :func:`.geometry.group_defects` takes them."""
        return {"quadratic": self.quadratic, "coquadratic": self.coquadratic,
                "fixed": self.fixed, "cofixed": self.cofixed}


@dataclass(frozen=True)
class ModelInfo:
    """What the build knows about a model and the run time reads: written once into the
    package (``INFO``), read by attribute. Sizes: m = ``source_dim``, n = ``fibre_dim``."""

    #: The schema version the package was written with (must equal :data:`VERSION`).
    version: int
    #: The model's name (the package's name).
    name: str
    #: The groupoid's kind, for messages and results only (the run time never branches
    #: on it).
    kind: str
    #: r, the Lagrangian's order (K = 2r elements in a residual's stencil).
    order: int
    #: m, base coordinates per node x.
    source_dim: int
    #: n, fibre coordinates per element f.
    fibre_dim: int
    #: Entries of a node's flat configuration g (Σ d² over the matrix groups; 0 without).
    configuration_dim: int
    #: The parameters' names, in the order of the parameter vector p.
    parameters: tuple[str, ...]
    #: Their defaults by name (:class:`Defaults`, in the same order).
    defaults: Defaults
    #: Per parameter: its declared sign assumption (a key of :data:`.signs.SIGNS`) or None.
    parameter_signs: tuple[str | None, ...]
    #: The declared names of the base coordinates x (m of them; none on a Lie group).
    coordinate_names: tuple[str, ...]
    #: The declared names of the velocities, one per fibre coordinate (a pair factor's
    #: q̇, a group factor's ξ): the velocities of a :class:`State`, in its order.
    velocity_names: tuple[str, ...]
    #: The declared names of the controls (optimal control: ``tau1``, …; else none).
    control_names: tuple[str, ...]
    #: Whether the model has an ``energy`` kernel (first order, autonomous).
    has_energy: bool
    #: How initial data is read into the first elements (a key of
    #: :data:`.paths.INITIAL_LAYOUTS`).
    initial_layout: str
    #: Whether it is solved as a whole trajectory (``solve_bvp``) at all.
    whole_trajectory: bool
    #: Whether its whole-trajectory solve uses the lifted system (:mod:`.lifted`).
    lifted: bool
    #: s, the constraints per window (multipliers λ ∈ Rˢ).
    constraints: int
    #: The constraints' names (for optimal control: the unactuated directions').
    constraint_names: tuple[str, ...]
    #: Per constraint of optimal control: the fibre coordinate of its unactuated direction.
    unactuated: tuple[int, ...]
    #: Whether the last nodes are unknowns (free or conditioned end).
    end_free: bool
    #: The names of the end conditions ψ = 0.
    end_conditions: tuple[str, ...]
    #: Controls per window (optimal control; 0 otherwise).
    controls: int
    #: The names of the inequalities c ≤ 0 of every window.
    inequalities: tuple[str, ...]
    #: The names of those among them without controls, checked on the boundary elements.
    boundary_inequalities: tuple[str, ...]
    #: Pairs (i, j) of those rows whose sum depends on the parameters alone: a bound's
    #: two sides, c_i + c_j = lower − upper.
    intervals: tuple[tuple[int, int], ...]
    #: Whether the final time is free (the ``horizon`` kernel).
    free_horizon: bool
    #: Whether the cost is the horizon alone (pure minimum time): no control cost, the
    #: controls fixed by their bounds only.
    pure_minimum_time: bool
    #: Per fibre coordinate: whether it is an increment over h (a group factor's ξ).
    step_scaled: tuple[bool, ...]
    #: The names of the declared symmetries (one Noether quantity each).
    symmetries: tuple[str, ...]
    #: The names of the symmetries the constraints depend on exactly (gauges).
    gauges: tuple[str, ...]
    #: The matrix-group factors of the configuration, in order.
    groups: tuple[GroupInfo, ...]
    #: Per fibre coordinate: the base coordinate of the target node it copies, or −1.
    fibre_nodes: tuple[int, ...]
    #: Per base coordinate: the row-major index into the flat configuration g of the
    #: entry it equals (a group acting on itself), or −1.
    configuration_base: tuple[int, ...]
    #: The compiled kernels.
    kernels: tuple[KernelInfo, ...]
    #: The symvi version that built the package.
    symvi_version: str
    #: The build's cache key.
    key: str
    #: The model's description.
    description: str

    def __post_init__(self) -> None:
        if tuple(self.defaults) != self.parameters:
            raise ModelInfoError(f"INFO.defaults names {list(self.defaults)}, not the "
                                 f"parameters {list(self.parameters)}: recompile the model")
        # the kernels by name, for lookups in O(1) (not a field: no part of the literal,
        # equality or the schema)
        object.__setattr__(self, "_by_name", {k.name: k for k in self.kernels})

    @property
    def matrix_dims(self) -> tuple[int, ...]:
        """Sizes d of the matrix-group factors."""
        return tuple(G.matrix_dim for G in self.groups)

    @property
    def kernel_names(self) -> tuple[str, ...]:
        """The names of the compiled kernels, in the build's order."""
        return tuple(k.name for k in self.kernels)

    def has_kernel(self, kernel: Kernel | str) -> bool:
        """Whether the model compiled ``kernel`` (a :class:`Kernel` or a name)."""
        return kernel_name(kernel) in self._by_name

    def kernel(self, kernel: Kernel | str) -> KernelInfo:
        """The kernel ``kernel`` (a :class:`Kernel` or a name); ValueError, naming those
        compiled, if the model has none such."""
        name = kernel_name(kernel)
        try:
            return self._by_name[name]
        except (KeyError, TypeError):       # TypeError: an unhashable name
            raise ValueError(f"unknown kernel {name!r}; known: "
                             f"{sorted(self.kernel_names)}") from None

    def to_literal(self) -> dict[str, Any]:
        """The plain dict (str, numbers, bools, None, lists, dicts) the build writes."""
        return _plain(dataclasses.asdict(self))

    @classmethod
    def from_literal(cls, data: Mapping[str, Any]) -> ModelInfo:
        """Read a package's literal back; :class:`ModelInfoError` if its version is not
        :data:`VERSION`, a key is unknown or missing, or a value has the wrong type."""
        if not isinstance(data, Mapping):
            raise ModelInfoError(f"INFO is a {type(data).__name__}, not a mapping: "
                                 f"recompile the model")
        version = data.get("version")
        if version != VERSION:
            raise ModelInfoError(
                f"the package's INFO has schema version {version!r} (symvi "
                f"{data.get('symvi_version', 'unknown')}); this run time reads version "
                f"{VERSION}: recompile the model")
        return _read(cls, data, "INFO")


#: Readers of the field types that appear above, by their annotation's text.
_SCALARS = {"int": int, "str": str, "bool": bool, "float": (int, float)}


def _read(cls, data: Mapping[str, Any], where: str):
    if not isinstance(data, Mapping):
        raise ModelInfoError(f"{where} is a {type(data).__name__}, not a mapping: "
                             f"recompile the model")
    fields = {f.name: f.type for f in dataclasses.fields(cls)}
    unknown, missing = sorted(set(data) - set(fields)), sorted(set(fields) - set(data))
    if unknown or missing:
        raise ModelInfoError(f"{where}: unknown keys {unknown}, missing keys {missing} for "
                             f"{cls.__name__} version {VERSION}: recompile the model")
    return cls(**{name: _value(annotation, data[name], f"{where}.{name}")
                  for name, annotation in fields.items()})


def _value(annotation: str, value: Any, where: str):
    if annotation in _SCALARS:
        return _scalar(annotation, value, where)
    if annotation == "str | None":
        return None if value is None else _scalar("str", value, where)
    if annotation == "tuple":
        return _frozen(value, where)
    if annotation.startswith("tuple[") and annotation.endswith(", ...]"):
        if not isinstance(value, (list, tuple)):
            raise ModelInfoError(f"{where} is a {type(value).__name__}, not a sequence: "
                                 f"recompile the model")
        item = annotation[len("tuple["):-len(", ...]")]
        return tuple(_value(item, v, f"{where}[{i}]") for i, v in enumerate(value))
    if annotation.startswith("tuple["):         # fixed length: tuple[int, int]
        items = annotation[len("tuple["):-1].split(", ")
        if not isinstance(value, (list, tuple)) or len(value) != len(items):
            raise ModelInfoError(f"{where} = {value!r} is not a {annotation}: recompile the "
                                 f"model")
        return tuple(_value(a, v, f"{where}[{i}]") for i, (a, v) in enumerate(zip(items, value)))
    if annotation == "Defaults":
        return _defaults(value, where)
    nested = {"KernelInfo": KernelInfo, "GroupInfo": GroupInfo}[annotation]
    return _read(nested, value, where)


def _scalar(annotation: str, value: Any, where: str):
    expected = _SCALARS[annotation]
    if not isinstance(value, expected) or (annotation != "bool" and isinstance(value, bool)):
        raise ModelInfoError(f"{where} = {value!r} is not of type {annotation}: recompile "
                             f"the model")
    return value


def _defaults(value: Any, where: str) -> Defaults:
    """A mapping of parameter names to numbers as :class:`Defaults`."""
    if not isinstance(value, Mapping):
        raise ModelInfoError(f"{where} is a {type(value).__name__}, not a mapping: "
                             f"recompile the model")
    return Defaults((_scalar("str", k, f"{where} key"), _scalar("float", v, f"{where}[{k!r}]"))
                    for k, v in value.items())


def _frozen(value: Any, where: str):
    """Nested lists of numbers as nested tuples."""
    if isinstance(value, (list, tuple)):
        return tuple(_frozen(v, where) for v in value)
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return value
    raise ModelInfoError(f"{where} holds {value!r}, not a number: recompile the model")


def _plain(value: Any):
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value
