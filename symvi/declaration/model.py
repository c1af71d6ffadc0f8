"""Model declaration: a groupoid, named parameters and a (continuous or discrete) Lagrangian.

This is the first stage of the pipeline (DESIGN.md §1). A :class:`Model` is validated when
it is built: undeclared symbols, non-scalar Lagrangians, bad parameter defaults and a
discretisation that does not fit the Lagrangian's order are refused with a message that
names the problem. Regularity (an invertible step map) needs the derived equations and is
checked by :func:`symvi.derivation.derive.derive`.
"""
from __future__ import annotations

import keyword
import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np
import sympy as sp

from .._runtime.core.signs import SIGNS
from .symbols import h, sign
from ..errors import ModelError
from ..groupoids.base import Groupoid, step_matrix
from .rank import generic_rank
from .symmetry import Symmetry
from .validation import NOT_NUMBERS, check_model_name, check_smooth, scalar

#: The highest order :func:`_named_orders` asks a groupoid about past its own: a guard
#: against a groupoid without a highest derivative, far above the rules' (6).
_ORDER_SEARCH_LIMIT = 32


def _named_orders(g: Groupoid, unexplained: set[sp.Symbol]):
    """(k, the set of ``g.leading_symbols(k)``) for k = 2, 3, …: every order up to the
    groupoid's own, then higher ones while some of the ``unexplained`` symbols (a
    Lagrangian's symbols of no order ``g`` takes) are not found among them, until the
    groupoid names no derivatives of order k (the groupoids name them up to the rules'
    highest order, :data:`symvi.discretisation.rules.MAX_ORDER`). A groupoid that names
    derivatives of every order (none of symvi's does) is asked up to
    :data:`_ORDER_SEARCH_LIMIT`."""
    unexplained = set(unexplained)
    k = 2
    while k <= g.max_order or (unexplained and k <= _ORDER_SEARCH_LIMIT):
        try:
            leading = set(g.leading_symbols(k))
        except ModelError:
            return
        unexplained -= leading
        yield k, leading
        k += 1


@dataclass(frozen=True)
class Example:
    """A default run of a model, used by ``symvi run`` and the documentation.

    ``initial`` holds what the step map needs to start: for the pair groupoid the first
    ``2·order`` nodes q_0, …, q_{2r−1}, as an array of shape (2r, n). A first-order model
    may give ``state`` instead or as well, a :class:`symvi.State` (q₀, v₀): ``symvi run``
    then starts from it through the discrete Legendre transform, so that ``--h`` changes
    the step and not the motion (fixed nodes fix the velocity (q₁ − q₀)/h, which changes
    with h); ``initial`` is then the node form of about the same start at the step ``h``.
    A whole-trajectory example (optimal control) gives the boundary data ``start`` and
    ``end`` of ``solve_bvp`` instead — :class:`symvi.State` s at t = 0 and t = N·h, or the
    fixed nodes (``end`` None with end conditions) — with ``n_steps`` = N. Its ``guess``,
    if given, is a function of the normalised times s = k/N of the free nodes (an array)
    returning their coordinates (len(s), m): a first path for problems whose straight line
    between the ends is a degenerate start (nonholonomic parking: a sideways move has no
    first-order gradient there).
    """

    initial: Any = None
    h: float = 0.01
    n_steps: int = 100
    start: Any = None
    end: Any = None
    state: Any = None
    guess: Any = None

    def guess_nodes(self, n_steps: int | None = None, order: int = 1) -> Any:
        """``guess`` at the free nodes r … N − r of N = ``n_steps`` (default the example's)
        steps, or None when the example gives no guess."""
        if self.guess is None:
            return None
        N = self.n_steps if n_steps is None else n_steps
        return self.guess(np.arange(order, N - order + 1) / N)

    @property
    def run_from(self) -> Any:
        """What ``symvi run`` integrates from: ``state`` when given, else ``initial``."""
        return self.state if self.state is not None else self.initial

    @property
    def whole_trajectory(self) -> bool:
        return self.start is not None


def _default(symbol: sp.Symbol, value: Any) -> float:
    """The default ``value`` of parameter ``symbol`` as a float: a real number (Python,
    NumPy or SymPy, e.g. ``sp.Rational(1, 2)``); strings and booleans are refused in the
    run time's words (``parameter m must be a real number, got '1.0'``)."""
    if isinstance(value, np.ndarray) and value.ndim == 0:    # np.array("1.0") is a string
        value = value[()]
    if isinstance(value, NOT_NUMBERS):
        raise ModelError(f"parameter {symbol} must be a real number, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ModelError(f"parameter {symbol} has a non-numeric default {value!r}") from None


def _sympify_parameters(parameters: Mapping[Any, float]) -> tuple[tuple[sp.Symbol, float], ...]:
    items = []
    for key, value in parameters.items():
        symbol = sp.Symbol(key, real=True) if isinstance(key, str) else key
        if not isinstance(symbol, sp.Symbol):
            raise ModelError(f"parameter {key!r} must be a SymPy Symbol or a name")
        default = _default(symbol, value)
        if not math.isfinite(default):
            raise ModelError(f"parameter {symbol} has a non-finite default {default}")
        declared = sign(symbol)
        if declared and not SIGNS[declared][0](default):
            raise ModelError(f"parameter {symbol} is declared {declared} but its default is "
                             f"{default}")
        items.append((symbol, default))
    names = [str(s) for s, _ in items]
    if len(set(names)) != len(names):
        raise ModelError(f"parameter names repeat: {names}")
    for name in names:
        if not name.isidentifier() or keyword.iskeyword(name):
            raise ModelError(f"parameter name {name!r} is not a valid Python identifier")
        if name == str(h):
            raise ModelError(f"parameter name {name!r} is reserved for the time step")
    return tuple(items)


def _order(k: int) -> str:
    """"first order", "second order", "order 3", … for messages."""
    return {1: "first order", 2: "second order"}.get(k, f"order {k}")


@dataclass(frozen=True, eq=False)
class Model:
    """A discrete variational model on a Lie groupoid.

    Give either a continuous ``lagrangian`` (in the groupoid's continuous symbols, e.g.
    ``G.q``, ``G.qdot``, for second order ``G.qddot``, for order k ``G.derivative(k)``;
    on a Lie group ``G.xi``, ``G.xidot``, ``G.derivative(k − 1)``) together with a
    ``discretisation`` (see :data:`symvi.discretisation.rules.RULES`), or a ``discrete_lagrangian``
    directly (in the groupoid's discrete symbols and :data:`h`) with its ``order``.

    Parameters
    ----------
    name:
        Python identifier; the generated package is called this.
    groupoid:
        The Lie groupoid the discrete path lives on.
    lagrangian, discretisation:
        Continuous Lagrangian and the rule that turns it into L_d (DESIGN.md §3). Its order
        is that of the highest derivative it contains; with no discretisation given, the
        groupoid's default for that order: on a pair groupoid ``"midpoint"`` (first
        order), ``"three_point"`` (accelerations), ``"central<k>"`` (order k ≥ 3).
    discrete_lagrangian, order:
        A discrete Lagrangian given directly: order 1 (L_d : G → R), order 2
        (L_d : G₂ → R, paper §3.1) or order k ≤ 6 (k composable elements, the k + 1 nodes
        ``G.nodes(k + 1)`` of a pair groupoid).
    parameters:
        Mapping from parameter symbol (or name) to its default value. Values can be
        changed at run time without recompiling.
    example:
        Optional default run (:class:`Example`).
    constraints:
        Constraints Φ^A = 0 on the path of a first- or second-order model (paper §3.2),
        written like the Lagrangian (continuous, discretised by the same rule as
        h Σ w Φ(point), or discrete); each window of the action sum (an element at first
        order) gets its multipliers λ^k_A and the augmented L_d + λ^k_A Φ^A_d is made
        stationary (eq. ``constrainedso``). Constrained models are solved as whole
        trajectories (``solve_bvp``).
    controls:
        Continuous expressions evaluated at each window's quadrature point and returned
        by ``solve_bvp`` (an optimal-control problem's u = EL(L)_a; see
        :func:`symvi.optimal_control`).
    symmetries:
        Noether symmetries (:class:`symvi.declaration.symmetry.Symmetry`): their conserved quantities
        F_Z are compiled (``StepResult.noether``) and ``symvi check`` verifies the
        invariance (paper §4.4).
    control_system:
        Set by :func:`symvi.optimal_control`: the controlled system
        (:class:`symvi.declaration.control.ControlSystem`) the Lagrangian and constraints come from.
    """

    name: str
    groupoid: Groupoid
    lagrangian: Any = None
    discretisation: str | None = None
    discrete_lagrangian: Any = None
    order: int | None = None
    parameters: Mapping[Any, float] = field(default_factory=dict)
    example: Example | None = None
    description: str = ""
    constraints: Sequence[Any] = ()
    controls: Sequence[Any] = ()
    symmetries: Sequence[Symmetry] = ()
    control_system: Any = None

    def __post_init__(self) -> None:
        check_model_name(self.name)
        if not isinstance(self.groupoid, Groupoid):
            raise ModelError(f"groupoid must be a symvi Groupoid, got {type(self.groupoid).__name__}")
        object.__setattr__(self, "parameters", _sympify_parameters(dict(self.parameters)))
        if (self.lagrangian is None) == (self.discrete_lagrangian is None):
            raise ModelError("give exactly one of `lagrangian` (continuous) and "
                             "`discrete_lagrangian`")
        if self.lagrangian is not None:
            self._validate_continuous()
        else:
            self._validate_discrete()
            self._validate_extras()
        self._validate_symmetries()
        self._validate_example()

    # -- validation -------------------------------------------------------------------
    @property
    def parameter_symbols(self) -> tuple[sp.Symbol, ...]:
        return tuple(s for s, _ in self.parameters)

    @property
    def parameter_defaults(self) -> tuple[float, ...]:
        return tuple(v for _, v in self.parameters)

    def _check_symbols(self, expr: sp.Expr, allowed: Sequence[sp.Symbol], what: str,
                       smooth: bool = True) -> None:
        """Refuse undeclared symbols in ``expr`` and, if ``smooth``, kinks in the
        coordinates (anything but the parameters)."""
        clash = set(self.parameter_symbols) & set(self.groupoid_symbols())
        if clash:
            raise ModelError(f"parameter(s) {sorted(map(str, clash))} clash with coordinate symbols")
        unknown = expr.free_symbols - set(allowed)
        if unknown:
            names = ", ".join(sorted(map(str, unknown)))
            raise ModelError(
                f"undeclared symbol(s) {names} in the {what} of model {self.name!r}; "
                f"declare them as parameters or use the groupoid's symbols "
                f"({', '.join(map(str, allowed))})")
        if smooth:
            check_smooth(expr, set(allowed) - set(self.parameter_symbols), what)

    def groupoid_symbols(self) -> tuple[sp.Symbol, ...]:
        return self.groupoid.continuous_symbols(self.groupoid.max_order)

    def _validate_continuous(self) -> None:
        L = scalar(self.lagrangian, "Lagrangian")
        object.__setattr__(self, "lagrangian", L)
        g = self.groupoid
        # past the groupoid's orders only symbols it has no use for count (a groupoid
        # written for orders 1 and 2 may answer any other order with its first-order ones)
        own = set(g.continuous_symbols(g.max_order))
        unexplained = L.free_symbols - own - set(self.parameter_symbols)
        needed = max((k for k, leading in _named_orders(g, unexplained)
                      if leading & L.free_symbols and (k <= g.max_order or not leading <= own)),
                     default=1)
        top = [str(s) for s in g.leading_symbols(needed) if s in L.free_symbols]
        if needed > g.max_order:
            raise ModelError(f"the Lagrangian of model {self.name!r} depends on {top} (order "
                             f"{needed}); {g!r} takes orders up to {g.max_order}")
        name = self.discretisation or g.default_discretisation(needed)
        rule = g.rule(name)
        if rule.order < needed:
            raise ModelError(f"the Lagrangian depends on {top} ({_order(needed)}) but the "
                             f"discretisation {name!r} is {_order(rule.order)}; use "
                             f"{g.default_discretisation(needed)!r}")
        if self.order is not None and self.order != rule.order:
            raise ModelError(f"order={self.order} contradicts discretisation {name!r} "
                             f"(order {rule.order})")
        object.__setattr__(self, "discretisation", name)
        object.__setattr__(self, "order", rule.order)
        allowed = list(g.continuous_symbols(rule.order)) + list(self.parameter_symbols)
        self._check_symbols(L, allowed, "Lagrangian")
        self._validate_extras()
        self._check_hessian(L, g.leading_symbols(rule.order), allowed)

    def _check_hessian(self, L: sp.Expr, highest: Sequence[sp.Symbol], allowed) -> None:
        """Refuse a degenerate L: ∂²L/∂q̇² (∂²L/∂q̈² for second order, ∂²L/∂(q⁽ᵏ⁾)² for
        order k) singular everywhere.

        Its discretisation would then have D₁₂L_d (D₁₃L_d, …) singular as h → 0 — not a
        well-posed step map, even where a rule happens to make it invertible at finite h.
        With constraints Φ the condition is on the bordered Hessian
        [[∂²L/∂v², (∂Φ/∂v)ᵀ], [∂Φ/∂v, 0]] (v the highest derivatives).
        """
        if self.control_system is not None and self.control_system.pure_minimum_time:
            return
        hessian = sp.hessian(L, highest)
        what = f"its Hessian with respect to {[str(s) for s in highest]}"
        if self.constraints:
            B = sp.Matrix([list(c.diff(v) for v in highest) for c in self.constraints])
            hessian = sp.Matrix(sp.BlockMatrix([[hessian, B.T],
                                                [B, sp.zeros(B.rows, B.rows)]]))
            what = f"its Hessian bordered by the constraints' derivatives in {[str(s) for s in highest]}"
        free = [s for s in allowed if s not in self.parameter_symbols]
        rank = generic_rank(hessian, free, dict(self.parameters))
        if rank is not None and rank < hessian.rows:
            which = step_matrix(self.order)
            raise ModelError(
                f"the Lagrangian of model {self.name!r} is not regular: {what} has rank "
                f"{rank} < {hessian.rows} everywhere, so {which} of the discrete Lagrangian is "
                f"singular as h → 0")

    def _validate_discrete(self) -> None:
        Ld = scalar(self.discrete_lagrangian, "discrete Lagrangian")
        object.__setattr__(self, "discrete_lagrangian", Ld)
        if self.discretisation is not None:
            raise ModelError("a discrete Lagrangian takes no `discretisation`")
        top = self.groupoid.max_order
        if not isinstance(self.order, int) or isinstance(self.order, bool) \
                or not 1 <= self.order <= top:
            raise ModelError(f"a discrete Lagrangian on {self.groupoid!r} needs an integer "
                             f"order from 1 to {top} (the number of elements it spans), got "
                             f"{self.order!r}")
        allowed = list(self.groupoid.discrete_symbols(self.order)) + [h] \
            + list(self.parameter_symbols)
        self._check_symbols(Ld, allowed, "discrete Lagrangian")

    def _allowed_symbols(self) -> list[sp.Symbol]:
        if self.lagrangian is not None:
            symbols = list(self.groupoid.continuous_symbols(self.order))
        else:
            symbols = list(self.groupoid.discrete_symbols(self.order)) + [h]
        return symbols + list(self.parameter_symbols)

    def _validate_extras(self) -> None:
        """Constraints and controls: scalars in the Lagrangian's symbols."""
        for field_name in ("constraints", "controls"):
            values = getattr(self, field_name)
            if isinstance(values, (sp.Expr, str)) or not isinstance(values, (list, tuple, sp.MatrixBase)):
                values = [values]
            exprs = tuple(scalar(v, f"{field_name[:-1]} {i}") for i, v in enumerate(values))
            for i, e in enumerate(exprs):
                self._check_symbols(e, self._allowed_symbols(), f"{field_name[:-1]} {i}",
                                    smooth=field_name == "constraints")
            object.__setattr__(self, field_name, exprs)
        if self.constraints and self.order > 2:
            raise ModelError(f"model {self.name!r}: constraints are solved for models of "
                             f"order 1 (multipliers per element, as on D_d⁽²⁾ of a "
                             f"nonholonomic problem) and 2 (per window of two elements, eq. "
                             f"constrainedso); this one has order {self.order}")
        if self.controls and self.lagrangian is None:
            raise ModelError("controls are evaluated at the quadrature point of a continuous "
                             "Lagrangian's discretisation; give `lagrangian`")

    def _validate_symmetries(self) -> None:
        """Sections in the base coordinates, one coefficient per fibre direction."""
        symmetries = tuple(self.symmetries)
        object.__setattr__(self, "symmetries", symmetries)
        if not symmetries:
            return
        base = list(self.groupoid.algebroid().q) + list(self.parameter_symbols)
        element = base if self.order == 1 else \
            list(self.groupoid.discrete_symbols(1)) + [h] + list(self.parameter_symbols)
        names = [z.name for z in symmetries if isinstance(z, Symmetry)]
        if len(names) != len(symmetries):
            raise ModelError("symmetries must be symvi.Symmetry objects")
        if len(set(names)) != len(names) or not all(n.isidentifier() for n in names):
            raise ModelError(f"symmetry names {names} must be distinct identifiers")
        n = self.groupoid.fibre_dim
        for z in symmetries:
            if len(z.section) != n:
                raise ModelError(f"symmetry {z.name!r}: the section has {len(z.section)} "
                                 f"coefficients, the groupoid has {n} fibre directions")
            for a, c in enumerate(z.section):
                self._check_symbols(c, base, f"symmetry {z.name!r}, coefficient {a}")
            self._check_symbols(z.potential, element, f"symmetry {z.name!r}, potential")

    def _validate_example(self) -> None:
        """The example's data checked now, before any build (issue 53: a quadrotor's
        States were refused at run time, after a 101 s build)."""
        if self.example is None:
            return
        try:
            if self.example.initial is not None:
                self.groupoid.check_initial(self.example.initial, self.order)
            for what, value in (("start", self.example.start), ("end", self.example.end)):
                if value is not None:
                    self.groupoid.check_boundary(value, self.order, what)
        except ModelError as exc:
            raise ModelError(f"example of model {self.name!r}: {exc}") from None

    # -- identity ---------------------------------------------------------------------
    def fingerprint(self) -> str:
        """Canonical text of everything that determines the generated code."""
        body = self.lagrangian if self.lagrangian is not None else self.discrete_lagrangian
        params = ";".join(f"{s}={v!r}" for s, v in self.parameters)
        extras = [sp.srepr(e) for e in self.constraints] + ["|"] \
            + [sp.srepr(e) for e in self.controls] + ["|"] \
            + [f"{z.name}:{sp.srepr(z.section)}:{sp.srepr(z.potential)}" for z in self.symmetries] \
            + ([self.control_system.fingerprint()] if self.control_system is not None else [])
        return "\n".join([self.name, self.groupoid.fingerprint(), str(self.discretisation),
                          str(self.order), sp.srepr(body), params] + extras)
