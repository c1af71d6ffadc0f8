"""The Python face of a compiled model: kernels, the step map and the whole-trajectory solve."""
from __future__ import annotations

import importlib
import inspect
import types
from typing import Callable, Mapping

import numpy as np

from .core import arguments
from .core.geometry import check_configurations
from .core.model_info import Kernel, KernelInfo, ModelInfo, kernel_name
from .core.options import SolveOptions, StepOptions
from .core.paths import check_configured, held, increments, initial_layout
from .core.results import State
from .step.legendre import first_fibres, state_arrays
from .step.stepping import integrate


def _documented_by(function: Callable) -> Callable:
    """Give a method that forwards to the runtime ``function`` (whose first parameter is
    the model) that function's signature, its model becoming ``self``, and its docstring:
    ``help()`` and :func:`inspect.signature` on a generated package's ``integrate`` and
    ``solve_bvp`` then name every option, from the one source that implements them."""
    signature = inspect.signature(function)
    first, *rest = signature.parameters.values()

    def decorate(method: Callable) -> Callable:
        method.__signature__ = signature.replace(parameters=[first.replace(name="self"), *rest])
        method.__doc__ = function.__doc__
        return method
    return decorate


class _Solve:
    """A method that forwards to a function of the run time (``module``'s ``name``): a
    whole-trajectory function of ``bvp/``, or the batch of ``step/batch.py``, imported on
    the first call or the first look at its signature or docstring (then as
    :func:`_documented_by` gives them): a package whose model is only stepped never imports
    ``bvp/``, ``bounded/`` or SciPy, and its first ``integrate`` not the batch's threads.
    ``refuse`` (the model → None, or raises) runs before each call."""

    def __init__(self, module: str, name: str, refuse: Callable | None = None):
        self._module, self.__name__, self.__qualname__ = module, name, f"CompiledModel.{name}"
        self._refuse = refuse

    @property
    def function(self) -> Callable:
        return getattr(importlib.import_module(self._module, __package__), self.__name__)

    @property
    def __doc__(self) -> str | None:
        return self.function.__doc__

    @property
    def __signature__(self) -> inspect.Signature:
        signature = inspect.signature(self.function)
        first, *rest = signature.parameters.values()
        return signature.replace(parameters=[first.replace(name="self"), *rest])

    def __get__(self, model, owner=None):
        return self if model is None else types.MethodType(self, model)

    def __call__(self, model, *args, **options):
        if self._refuse is not None:
            self._refuse(model)
        return self.function(model, *args, **options)


def _stepped(model: CompiledModel) -> None:
    """Refuse a model with constraints (multipliers) in the step map's calls."""
    if model.constraints:
        raise ValueError(f"model {model.name!r} has constraints with multipliers; it is "
                         f"solved as a whole trajectory: use solve_bvp")


def result_labels(info: ModelInfo) -> dict:
    """The ``labels`` of this model's results, plain data (they pickle with the result):
    the model's name, the declared names of the base coordinates (``x``), velocities
    (``v``), controls and symmetries, ``INFO.fibre_nodes``, and per matrix-group factor
    its label and whether it is affine (a last row (0, …, 0, 1) fixed, as on SE(n): its
    last column is a position)."""
    def affine(group) -> bool:
        last = tuple([0.0] * (group.matrix_dim - 1) + [1.0])
        return any(tuple(map(float, w)) == last for w in group.cofixed)
    return {"model": info.name, "x": info.coordinate_names, "v": info.velocity_names,
            "controls": info.control_names, "symmetries": info.symmetries,
            "fibre_nodes": info.fibre_nodes,
            "groups": tuple((G.label, affine(G)) for G in info.groups)}


class CompiledModel:
    """Wraps the cffi ``ffi``/``lib`` of one generated extension.

    ``info`` is what symvi wrote about the model (:class:`.model_info.ModelInfo`: name,
    kind, order, source_dim (m), fibre_dim (n), parameters, defaults, kernels, …), read by
    attribute.
    """

    #: The options of the whole-trajectory solve and of the step map (``options=`` of
    #: :meth:`solve_bvp` and :meth:`integrate`), this package's own classes.
    SolveOptions, StepOptions = SolveOptions, StepOptions

    def __init__(self, ffi, lib, info: ModelInfo):
        if not isinstance(info, ModelInfo):
            raise TypeError(f"info must be a ModelInfo (ModelInfo.from_literal), not "
                            f"{type(info).__name__}")
        self.ffi, self.lib, self.info = ffi, lib, info
        self.name: str = info.name
        self.order: int = info.order
        self.m: int = info.source_dim
        self.n: int = info.fibre_dim
        #: s, the constraints per window (multipliers λ^k ∈ R^s).
        self.constraints: int = info.constraints
        #: Per fibre coordinate: whether it is an increment over h (a group factor's ξ).
        self.step_scaled = np.array(info.step_scaled or [False] * self.n, dtype=bool)
        self.step_scaled.flags.writeable = False
        #: Whether the last nodes are unknowns, and the number of end conditions ψ = 0.
        self.end_free = info.end_free
        self.end_count = len(info.end_conditions)
        #: The inequalities c ≤ 0 of every window (bounded optimal control), by name.
        self.inequalities: tuple[str, ...] = info.inequalities
        self.parameter_names: tuple[str, ...] = info.parameters
        self.parameter_defaults: tuple[float, ...] = tuple(info.defaults.values())
        #: What a result carries to read itself (its summary, ``plot()``): the declared
        #: names and how the fibres relate to the nodes.
        self.labels: dict = result_labels(info)

    def __repr__(self) -> str:
        return (f"<symvi model {self.name!r}: {self.info.kind} groupoid, order {self.order}, "
                f"n={self.n}, parameters {dict(self.info.defaults)}>")

    @property
    def stencil_elements(self) -> int:
        """K = 2r elements in the stencil of one residual."""
        return 2 * self.order

    def ptr(self, array: np.ndarray):
        """A ``double *`` on a C-contiguous float64 array, without copying."""
        return self.ffi.from_buffer("double[]", array)

    def params(self, given=None) -> np.ndarray:
        return arguments.parameters(self.parameter_names, self.parameter_defaults, given,
                                    self.info.parameter_signs)

    def evaluate(self, kernel: Kernel | str, z, h: float,
                 params: Mapping[str, float] | None = None) -> tuple[np.ndarray, ...]:
        """Evaluate one compiled kernel at stencil coordinates ``z``.

        ``kernel``: ``step`` (residual, ∂R/∂f_{K−1}), ``stencil`` (residual, ∂R/∂z),
        ``predict``, ``target``, ``momentum_plus``, ``momentum_minus``, ``lagrangian`` and,
        for first-order models, ``energy`` (all of them: ``INFO.kernel_names``; a
        :class:`.model_info.Kernel` or its name). ``z``: the kernel's coordinates (base
        point, then elements; its length ``INFO.kernel(kernel).nz``), ``h`` the step,
        ``params`` parameter overrides (mapping name → value). Returns the outputs as
        arrays (Jacobians as matrices).
        """
        spec = self.info.kernel(kernel)
        z = arguments.finite_array(z, (spec.nz,), f"stencil z of kernel {spec.name!r}")
        outs = self.kernel_outputs(kernel, z, self.params(params), arguments.step_size(h))
        if len(outs) == 2:
            outs[1] = outs[1].reshape(outs[0].size, -1)
        return tuple(outs)

    def kernel_outputs(self, kernel: Kernel | str, z: np.ndarray, p: np.ndarray,
                       h: float) -> list[np.ndarray]:
        """The flat outputs of the compiled ``kernel`` at the float64 coordinates ``z``,
        the parameter vector ``p`` already assembled (:meth:`params`) and ``h`` checked:
        :meth:`evaluate` without its argument checks, for the runtime's own calls."""
        spec = self.info.kernel(kernel)
        outs = [np.zeros(size) for size in spec.outputs]
        getattr(self.lib, f"symvi_{spec.name}")(self.ptr(np.ascontiguousarray(z)), self.ptr(p),
                                                h, *[self.ptr(o) for o in outs])
        return outs

    def along(self, kernel: Kernel | str, x: np.ndarray, f: np.ndarray, h: float, params=None,
              windows: int | None = None) -> np.ndarray:
        """Evaluate a kernel's first output on every window of consecutive elements."""
        return self.along_vector(kernel, x, f, h, self.params(params), windows)

    def along_vector(self, kernel: Kernel | str, x: np.ndarray, f: np.ndarray, h: float,
                     p: np.ndarray, windows: int | None = None) -> np.ndarray:
        """:meth:`along` with the parameter vector ``p`` already assembled.

        Raises ``ValueError`` when ``windows`` exceeds what the path holds (the C loop
        would read past the end of ``x`` or ``f``)."""
        spec = self._along_spec(kernel)
        x = np.ascontiguousarray(x, dtype=np.float64)
        f = np.ascontiguousarray(f, dtype=np.float64)
        available = self._windows_available(spec, x, f)
        windows = available if windows is None else windows
        if windows > available:
            raise ValueError(f"kernel {spec.name!r}: {windows} windows asked, but the path "
                             f"holds {max(available, 0)} (elements f: {f.shape}, base "
                             f"points x: {x.shape})")
        out = np.zeros((max(windows, 0), spec.outputs[0]))
        if windows > 0:
            getattr(self.lib, f"symvi_{spec.name}_path")(self.ptr(x), self.ptr(f), windows,
                                                         self.ptr(p), arguments.step_size(h),
                                                         self.ptr(out))
        return out

    def _along_spec(self, kernel: Kernel | str) -> KernelInfo:
        name = kernel_name(kernel)
        if not self.info.has_kernel(name) or not hasattr(self.lib, f"symvi_{name}_path"):
            along = sorted(k for k in self.info.kernel_names
                           if hasattr(self.lib, f"symvi_{k}_path"))
            raise ValueError(f"kernel {name!r} cannot be evaluated along a path; "
                             f"those that can: {along}")
        return self.info.kernel(name)

    def _windows_available(self, spec: KernelInfo, x: np.ndarray, f: np.ndarray) -> int:
        """Windows of the kernel's width in the path: window i reads base point i and
        elements i … i + width − 1."""
        width = spec.width(self.m, self.n)
        rows = {name: a.shape[0] if a.ndim else 0 for name, a in (("x", x), ("f", f))}
        if f.size != rows["f"] * self.n or (self.m and x.size != rows["x"] * self.m):
            raise ValueError(f"kernel {spec.name!r}: the path must be base points x (nodes, "
                             f"{self.m}) and elements f (elements, {self.n}), got x "
                             f"{x.shape} and f {f.shape}")
        windows = rows["f"] - width + 1
        return min(windows, rows["x"]) if self.m else windows

    def momenta(self, x: np.ndarray, f: np.ndarray, h: float,
                params: Mapping[str, float] | None = None) -> np.ndarray:
        """Discrete momenta at every state of the path of base points ``x`` and elements
        ``f`` (a result's ``x`` and ``f``; see :class:`StepResult`), step ``h``, parameter
        overrides ``params``.

        F⁻L_d on windows 0 … r−1 gives states 0 … r−1; F⁺L_d on window i gives state i + r.
        """
        r, n = self.order, self.n
        if f.shape[0] - (2 * r - 1) + 1 < r:
            return np.zeros((0, n) if r == 1 else (0, r, n))
        minus = self.along(Kernel.MOMENTUM_MINUS, x, f, h, params, windows=r).reshape(-1, r, n)
        plus = self.along(Kernel.MOMENTUM_PLUS, x, f, h, params).reshape(-1, r, n)
        states = np.concatenate([minus, plus])
        return states[:, 0, :] if r == 1 else states

    def noether(self, x: np.ndarray, f: np.ndarray, h: float,
                params: Mapping[str, float] | None = None) -> np.ndarray | None:
        """Conserved quantities F_Z of the declared symmetries (paper §4.4) at nodes
        r−1, r, … of the path ``x``, ``f`` (step ``h``, parameter overrides ``params``), one
        column per name in ``info.symmetries``; None without symmetries."""
        if not self.info.symmetries:
            return None
        return self.along(Kernel.NOETHER, x, f, h, params)

    @_documented_by(integrate)
    def integrate(self, initial, n_steps: int, h: float, params=None, **options):
        _stepped(self)
        return integrate(self, initial, n_steps, h, params, **options)

    integrate_many = _Solve(".step.batch", "integrate_many", _stepped)
    solve_bvp = _Solve(".bvp.bvp", "solve_bvp")
    solve_bvp_many = _Solve(".bvp.bvp_batch", "solve_bvp_many")
    continuation = _Solve(".bvp.bvp_batch", "continuation")

    @property
    def matrix_dims(self) -> tuple[int, ...]:
        """Sizes d of the matrix-group factors whose configurations are reconstructed."""
        return self.info.matrix_dims

    def configurations(self, g: np.ndarray):
        """Split flat configurations (steps × Σd²) into (steps, d, d) arrays, one per group
        factor; a single factor is returned as its array, none as None."""
        if not self.matrix_dims:
            return None
        blocks, at = [], 0
        for d in self.matrix_dims:
            blocks.append(g[:, at:at + d * d].reshape(-1, d, d))
            at += d * d
        return blocks[0] if len(blocks) == 1 else tuple(blocks)

    def increments(self, g, h: float, params=None) -> np.ndarray:
        """ξ_k = τ⁻¹(g_k⁻¹g_{k+1})/h of configurations g (K, d, d) on a matrix Lie group;
        see :func:`.core.paths.increments`."""
        return increments(self, g, h, params)

    def state_parts(self, state: State) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The position x, velocity v and flat configuration g₀ of ``state``, checked.
        Where every base coordinate is an entry of g (a group acting on itself) x may be
        left out — it is g's entries — and a given x must be them."""
        g0 = self.configuration(state.g, "the state's configuration g")
        if self.matrix_dims:
            check_configurations(self, g0[None, :], "the state's configuration g")
        if state.x is None and held(self):
            state = State(v=state.v, x=g0[list(self.info.configuration_base)], g=state.g)
        x, v = state_arrays(self, state)
        if self.m:
            check_configured(self, x[None, :], g0[None, :], "the state's", 0,
                             "State(v=..., g=...), x filled from g (the identity unless "
                             "given),")
        return x, v, g0

    def initial_state(self, initial, h: float | None = None,
                      p: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Split initial data into the stencil prefix (x_0, f_0, …, f_{K−2}) and g_0.

        A :class:`State` (first-order models; needs the step ``h`` and the parameter
        vector ``p``): its first element from the discrete Legendre transform
        (:mod:`.legendre`). Pair groupoid: the first K nodes, shape (K, n).
        Otherwise ``(x_0, g_0, f)``: the first base point, the configurations of the
        matrix-group factors (one (d, d) matrix, or a sequence of them; optional,
        identity by default) and the first K−1 fibre parts; a Lie group over a point has
        no base point: ``(g_0, f)``.
        """
        if isinstance(initial, State):
            x0, v0, g0 = self.state_parts(initial)
            f0 = first_fibres(self, x0[None], v0[None], np.array([h]), p[None])[0]
            return np.concatenate([x0, f0]), g0
        return initial_layout(self).read(self, initial)

    def configuration(self, given=None, what: str = "initial configuration g_0") -> np.ndarray:
        """One node's configurations, flattened factor by factor (Σ d² numbers): ``given``
        is a (d, d) matrix, or a sequence of them with several group factors; None is the
        identity. The shapes and finiteness are checked here, the group by the caller."""
        dims = self.matrix_dims
        if not dims:
            return np.zeros(1)
        if given is None:
            return np.concatenate([np.eye(d).reshape(-1) for d in dims])
        blocks = [given] if len(dims) == 1 else list(given)
        if len(blocks) != len(dims):
            raise ValueError(f"{what} needs {len(dims)} matrices, one per group factor")
        return np.concatenate([arguments.finite_array(b, (d, d), what).reshape(-1)
                               for b, d in zip(blocks, dims)])
