"""Result objects of the step map and the whole-trajectory solve (cf. ``solve_ivp``).

Pickling: by name, from symvi
-----------------------------
Each generated package carries its own copy of this file, in a private module
(``_symvi_<name>_<hash>._runtime.core.results``) that no other process can import. So a result
does not pickle by its class: every class here pickles, through ``__reduce__``, as a call
of :data:`HOME`'s ``_rebuild`` (a :class:`Status` as ``HOME.Status(value)``, a
:class:`NewtonError` as ``HOME.NewtonError(result)``) with its fields by name, nested
results, States and Statuses the same way. The pickle records that call as
``getattr(importlib.import_module("symvi._runtime.core.results"), "_rebuild")``: loading it
imports symvi's own copy of this file by name, with the standard library alone, whatever
package made the result — the package itself is never needed. So:

* a result pickled in one process loads in any process that has symvi installed, with
  ``import pickle`` alone; it loads as symvi's class (``symvi._runtime.core.results``), which
  counts as the package's for ``isinstance`` (below);
* where symvi is not installed (a package used standalone, with numpy and cffi), results
  still pickle, but loading them raises ``ModuleNotFoundError: No module named 'symvi'``:
  use the archive of :meth:`_Result.save` (``numpy.load`` reads it) to move results
  without symvi;
* ``HOME``'s names ``_rebuild``, ``Status`` and ``NewtonError`` and the fields' names are
  the pickle format: ``_rebuild`` builds through the constructor, so a field added with
  a default still loads older pickles;
* ``copy.copy`` and ``copy.deepcopy`` call the same reduction but rebuild in this copy
  (:class:`_Found` called here is this module's own), never importing symvi.

Importing this file changes nothing outside it (no registration in ``sys.modules``).

Classes of two copies
---------------------
The copies' classes are distinct objects (``type(a) is not type(b)`` for results of two
packages). Their metaclass (:class:`_Shared`) makes ``isinstance`` and ``issubclass`` treat
a class of another copy with the same name and the same fields (a Status: the same
members) as this copy's: a :class:`State` made with ``symvi.State`` starts a package's run,
a result of one package (or one loaded from a pickle) is another package's warm start.
``except`` clauses match by identity only: catch a package's own ``NewtonError``.

This file imports nothing of its package (its copies must be interchangeable) and needs
numpy only.
"""
from __future__ import annotations

import enum
import importlib
import os
import secrets
from dataclasses import dataclass, fields, is_dataclass

import numpy as np

#: The module a pickle names for every class of this file: symvi's own copy, imported
#: by name when the pickle loads (see the docstring).
HOME = "symvi._runtime.core.results"


class _Shared(type):
    """Metaclass of the classes of this file: a class of another copy of it with the
    same :meth:`symvi_layout` counts as this class for ``isinstance`` and ``issubclass``."""

    def symvi_layout(cls) -> tuple:
        """What two copies' classes must share to stand for each other: their name and
        their fields (a Status: its members)."""
        if issubclass(cls, enum.Enum):
            parts = tuple((m.name, m.value) for m in cls)
        elif is_dataclass(cls):
            parts = tuple(f.name for f in fields(cls))
        else:
            parts = ()
        return cls.__qualname__, parts

    def __instancecheck__(cls, obj) -> bool:
        return cls.__subclasscheck__(type(obj))

    def __subclasscheck__(cls, sub) -> bool:
        if type.__subclasscheck__(cls, sub):
            return True
        # only a class of some copy of this file can stand for one: the layouts (fields)
        # are compared for those alone, so that isinstance(array, State) stays cheap
        others = [k for k in getattr(sub, "__mro__", ())
                  if getattr(type(k), "symvi_layout", None) is not None]
        if not others:
            return False
        layout = cls.symvi_layout()
        return any(type(k).symvi_layout(k) == layout for k in others)


class _SharedEnum(_Shared, enum.EnumMeta):
    """:class:`_Shared` for :class:`Status`, an enumeration."""


class _Home:
    """symvi's copy of this module (:data:`HOME`), in a pickle: loading imports it by
    name."""

    def __reduce__(self):
        return importlib.import_module, (HOME,)


@dataclass(frozen=True)
class _Found:
    """The attribute ``name`` of :data:`HOME`, in a pickle (loading imports HOME and
    takes the attribute). Called here — by ``copy``, or by pickle's check that what it
    records is callable — it is this copy's own."""

    name: str

    def __reduce__(self):
        return getattr, (_Home(), self.name)

    def __call__(self, *args):
        return _LOCAL[self.name](*args)


#: The three calls a pickle records, one object each: a pickle holding many results
#: (a BVPBatch) spells each out once and refers back to it.
_REBUILD, _STATUS, _NEWTON_ERROR = _Found("_rebuild"), _Found("Status"), _Found("NewtonError")


class Status(enum.IntEnum, metaclass=_SharedEnum):
    """Outcome of a solve; the values match the C return codes."""

    SUCCESS = 0
    MAX_ITERATIONS = 1
    SINGULAR_JACOBIAN = 2
    NON_FINITE = 3
    STALLED = 4
    OUTSIDE_CHART = 5
    DIVERGED = 6
    ILL_CONDITIONED = 7
    #: A KKT point of an optimal-control problem that is not a verified minimum (the
    #: Hessian of the Lagrangian is not positive definite on the constraints' tangent
    #: space): a saddle or maximum of the cost (:mod:`.optimality`).
    SADDLE = 8
    #: The inequalities admit no solution near the start: the least violation the
    #: penalty stages reach stopped falling as the penalty grew (:mod:`.penalty`).
    INFEASIBLE = 9

    def __str__(self) -> str:
        # IntEnum prints its value since Python 3.11; a status reads as its name
        return self.name

    def __format__(self, spec: str) -> str:
        # numeric format specs (``{status:d}``, ``{status:>3}`` stays text) keep the value
        if spec and spec[-1] in "bcdoxXneEfFgG%":
            return format(int(self), spec)
        return format(self.name, spec)

    def __reduce_ex__(self, protocol):
        return _STATUS, (int(self),)


class NewtonError(RuntimeError, metaclass=_Shared):
    """Newton's method failed; ``result`` holds the partial result and its message."""

    def __init__(self, result):
        super().__init__(result.message)
        self.result = result

    def __reduce__(self):
        return _NEWTON_ERROR, (self.result,)


def _rebuild(kind: str, state: dict):
    """The object of class ``kind`` (a result or a :class:`State`) from its fields by
    name: what a pickle of one calls (part of the pickle format, see the docstring)."""
    cls = _REBUILT[kind]
    unknown = set(state) - {f.name for f in fields(cls)}
    if unknown:
        raise TypeError(f"a pickled {kind} has fields this {kind} has not: "
                        f"{', '.join(sorted(unknown))} (pickled by another version of symvi?)")
    if "status" in state:
        state = state | {"status": Status(state["status"])}
    return cls(**state)


def _reduce(obj) -> tuple:
    """How ``obj`` (a result or a State) pickles: a call of :data:`HOME`'s ``_rebuild``
    with its class's name and its fields."""
    return _REBUILD, (type(obj).__name__, {f.name: getattr(obj, f.name) for f in fields(obj)})


def _brief(values) -> str:
    """A short text of the last entry of ``values``: a path array, or a tuple of them
    (one per group factor)."""
    if values is None:
        return "None"
    if isinstance(values, tuple):
        return "(" + ", ".join(_brief(v) for v in values) + ")"
    if len(values) == 0:
        return "[]"
    last = np.asarray(values[-1])
    return np.array2string(last, precision=6, threshold=9, edgeitems=1 if last.ndim > 1 else 2,
                           separator=", ", max_line_width=10**6).replace("\n", "")


def _velocity_or_fibres(result) -> dict:
    """The last element of ``result``'s path for its one-line summary: its fibres ``f``,
    except those that copy the element's target node (a pair factor's f = q_{k+1}, which
    the final ``x`` already shows: ``labels["fibre_nodes"]``), shown instead as the
    velocity ``v`` = (x_N − x_{N−1})/h where the path's last two nodes are both kept."""
    nodes = np.asarray((result.labels or {}).get("fibre_nodes", ()), dtype=int)
    if result.f is None or nodes.size == 0 or not (nodes >= 0).any():
        return {"f": result.f}
    copies = nodes >= 0
    out = {}
    x, t = result.x, result.t
    if x is not None and len(x) == len(result.f) + 1 >= 2 and len(t) == len(x):
        out["v"] = ((x[-1] - x[-2]) / (t[-1] - t[-2]))[None, nodes[copies]]
    if not copies.all():
        out["f"] = np.asarray(result.f)[:, ~copies]
    return out


@dataclass(frozen=True)
class State(metaclass=_Shared):
    """A state to start :func:`integrate` from instead of its first nodes (first-order
    models): the velocity ``v`` — q̇ on a pair groupoid, the body velocity ξ = g⁻¹ġ on a
    matrix Lie group — at the position ``x`` (a pair groupoid's q₀, an action groupoid's
    base point; none on a Lie group) and the configuration ``g`` (a (d, d) matrix, a
    sequence of them with several group factors; the identity by default). The first
    element is the one whose discrete momentum F⁻L_d equals the continuous one ∂L/∂v at
    the state (the discrete Legendre transform), so that the path approximates the
    solution from that state at the method's order, whatever the step.

    Also the boundary data of a second-order :func:`solve_bvp` at t = 0 and t = T (every
    groupoid; a group acting on itself may leave x out): each fixes the element whose midpoint it is
    (:mod:`.boundary_states`). A solve's ``states`` is a State of arrays, one row per
    time."""

    v: object
    x: object = None
    g: object = None

    __reduce__ = _reduce


class _Result(metaclass=_Shared):
    """What the result classes share: status checks, saving, pickling and a short repr."""

    status: Status
    message: str

    @property
    def success(self) -> bool:
        return self.status == Status.SUCCESS

    @property
    def q(self) -> np.ndarray | None:
        """Alias of ``x`` (the nodes of a pair-groupoid path)."""
        return self.x

    def raise_for_status(self):
        """Raise :class:`NewtonError` unless the solve succeeded; return self otherwise."""
        if not self.success:
            raise NewtonError(self)
        return self

    def save(self, file: str | os.PathLike) -> None:
        """Write the result to the NumPy archive ``file`` (``numpy.load`` reads it back):
        every array under its attribute's name — several configurations as ``g_0``,
        ``g_1``, …, the interior point's log as ``history_mu`` and so on — the status by
        name, the message and the scalars as 0-d arrays; absent (None) ones left out.
        Written atomically: the archive appears whole or not at all."""
        arrays = {}
        for field in fields(self):
            arrays.update(_entries(field.name, getattr(self, field.name)))
        write_npz(file, arrays)

    __reduce__ = _reduce

    def plot(self):
        """This result drawn as a matplotlib ``Figure``, one panel per quantity against
        time, labelled with the model's declared names: coordinates, world position and
        attitude of group configurations, velocities, and the controls, energy error or
        conserved quantities' drift (:mod:`.plotting`; needs matplotlib). Save it with
        ``fig.savefig("path.png")``."""
        return importlib.import_module(".plotting", __package__).figure(self)

    def _summary(self, counts: str, final: dict) -> str:
        message = self.message if len(self.message) <= 100 else self.message[:99] + "…"
        finals = ", ".join(f"{name} = {_brief(values)}" for name, values in final.items())
        return (f"<{type(self).__name__} {self.status.name}: {message!r}; {counts}"
                f"{'; final ' + finals if finals else ''}>")


@dataclass(frozen=True, repr=False)
class StepResult(_Result):
    """Discrete path computed by the step map.

    Attributes
    ----------
    t : (E+1,) times of the base points (node k at k·h).
    x : (E+1, m) base points α(E_0), β(E_0), …, β(E_{E−1}); for the pair groupoid the
        nodes q_k (also available as ``q``).
    f : (E, n) fibre parts of the elements E_0, …, E_{E−1} (Lie groups: ξ_k).
    g : (E+1, d, d) reconstructed configurations g_{k+1} = g_k τ(hξ_k) on a matrix Lie
        group, else None.
    momenta : discrete Legendre transforms at each state: (E+1, n) for first order
        (p_0 from F⁻L_d, p_k for k ≥ 1 from F⁺L_d), (E, 2, n) for second order (state k
        is the node pair (ν_k, ν_{k+1}); states 0, 1 from F⁻L_d, the rest from F⁺L_d);
        (E − r + 2, r, n) at order r — but a path of fewer than 3r − 2 elements
        determines only its first E − 2r + 2 states, and holds those (a longer run's).
    energy : (E,) discrete energy −∂L_d/∂h per element (first-order models), else None.
    noether : (E−2r+2, s) conserved quantities F_Z of the model's declared symmetries at
        nodes r−1, r, … (paper §4.4), one column per symmetry, else None. Momenta,
        energies and conserved quantities are None with ``integrate(...,
        quantities=False)``.
    newton_iterations : (E − K + 1,) Newton iterations of each computed step (the first
        K − 1 elements, given or from the Legendre transform, took none).
    status, success, message : outcome; on failure the arrays hold the path up to the
        failing step. Success means every step converged and every array is finite.

    With ``keep_every=k`` each array holds only the entries of the nodes 0, k, 2k, …
    (see :func:`stepping.integrate`).
    """

    t: np.ndarray
    x: np.ndarray
    f: np.ndarray
    g: np.ndarray | tuple | None
    newton_iterations: np.ndarray
    status: Status
    message: str
    momenta: np.ndarray | None = None
    energy: np.ndarray | None = None
    noether: np.ndarray | None = None
    labels: dict | None = None

    def __repr__(self) -> str:
        final = {"x": self.x} | _velocity_or_fibres(self) \
            | ({"g": self.g} if self.g is not None else {})
        end = f", t = {self.t[-1]:.6g}" if len(self.t) else ""
        return self._summary(f"{len(self.t)} nodes{end}", final)


@dataclass(frozen=True, repr=False)
class BVPResult(_Result):
    """Whole-trajectory solution with fixed end nodes.

    Attributes
    ----------
    t : (N+1,) times of the nodes.
    x : (N+1, m) base points of the nodes (pair groupoid: the nodes q; also ``q``), None
        on a Lie group.
    g : (N+1, d, d) configurations of the matrix-group factor (a tuple of such arrays with
        several factors), boundary ones included, else None.
    f : (N, n) fibres of the elements (Lie groups: ξ_k = τ⁻¹(g_k⁻¹g_{k+1})/h; pair
        factors: the next node).
    multipliers : (N−r+1, s) multipliers λ^k of the windows (constrained models), else None.
    controls : (N−r+1, c) controls u_k at each window's quadrature point (optimal-control
        problems: u = EL(L)_a of the discrete path), else None; at the times
        ``t_controls`` (a property: the windows' middle nodes).
    bound_multipliers : (N−r+1, I) multipliers z ≥ 0 of the inequalities c ≤ 0 of every
        window (bounded optimal control, named by ``inequalities``), else None.
    active : (N−r+1, I) where an inequality is active (its multiplier exceeds its slack
        −c), else None.
    inequalities : the names of the inequalities, e.g. ``"tau1 <= tau_max"``.
    active_set : per window, the names of its active inequalities (a property).
    T : the horizon (a property): t[-1], or t_states[-1] from States; the optimal one
        with a free final time.
    end_multipliers : (P,) multipliers ν of the end conditions ψ = 0 (``end=`` of
        :func:`symvi.optimal_control`), else None.
    history : per Newton (or interior-point) iteration, arrays ``objective``,
        ``primal`` and ``dual`` infeasibility, ``correction`` (the full Newton
        correction), ``alpha`` (the step taken relative to it; 0 where none or where μ
        fell), ``shift`` (the inertia correction's, relative to W's scale), ``trials``
        and ``T`` (the horizon, where it is an unknown; else NaN), and for the interior
        point ``mu`` (barrier parameter per unit time) and ``complementarity`` (max s·z),
        NaN for the equality Newton — the columns of the ``verbose`` log, like IPOPT's
        (:mod:`._runtime.core.log`).
    cost : Σ_k L_d over the windows — the discrete cost J_d of an optimal-control problem,
        the action sum otherwise. A window of a second-order problem spans nodes k … k+2
        and weighs its integrand by h at node k+1. From States (``solve_bvp(model,
        State(...), State(...), ...)``) the windows are centred at (k + ½)h and J_d is
        the midpoint rule on [0, T]: it converges at order 2 (:mod:`.boundary_states`).
        From nodes it is a midpoint sum over [h/2, T − h/2]: it differs from ∫₀ᵀ by the
        two end half-windows, O(h) where the integrand does not vanish at the ends (a
        rest-to-rest slew starts and ends with its largest torques).
    states : from States, the states at the times ``t_states`` = k·h on [0, T] (the
        elements' midpoints): a :class:`State` whose ``v`` is (N+1, n), ``x`` (N+1, m) on
        a pair groupoid and ``g`` (N+1, d, d) on Lie groups; else None.
    t_states : (N+1,) the times k·h of ``states``, else None. From States the nodes sit
        at the half steps: ``t`` = (k − ½)h, k = 0 … N+1.
    iterations : Newton iterations taken.
    residual_norms : max-norm of the residual before each iteration and at the end.
    step_norms : max-norm of each Newton update actually taken (after line search).
    status, success, message : outcome; a failed solve keeps the last iterate.
    """

    t: np.ndarray
    iterations: int
    residual_norms: np.ndarray
    step_norms: np.ndarray
    status: Status
    message: str
    x: np.ndarray | None = None
    g: np.ndarray | tuple | None = None
    f: np.ndarray | None = None
    multipliers: np.ndarray | None = None
    controls: np.ndarray | None = None
    cost: float | None = None
    kind: str = ""
    bound_multipliers: np.ndarray | None = None
    active: np.ndarray | None = None
    inequalities: tuple[str, ...] = ()
    history: dict | None = None
    end_multipliers: np.ndarray | None = None
    states: State | None = None
    t_states: np.ndarray | None = None
    labels: dict | None = None

    @property
    def T(self) -> float:
        """The horizon N·h: with a free final time (``time_cost``), the optimal one."""
        if self.t_states is not None:
            return float(self.t_states[-1])
        return float(self.t[-1]) if len(self.t) else 0.0

    @property
    def t_controls(self) -> np.ndarray | None:
        """The times of :attr:`controls`: window w's middle node t_{w+1}, where both
        second-order rules (three-point, Lie midpoint) and the variational controlled
        equations centre it; None without controls."""
        if self.controls is None:
            return None
        return self.t[1:1 + len(self.controls)]

    @property
    def active_set(self) -> list[tuple[str, ...]] | None:
        """Per window, the names of its active inequalities (from :attr:`active`)."""
        if self.active is None:
            return None
        return [tuple(n for n, a in zip(self.inequalities, row) if a) for row in self.active]

    def __repr__(self) -> str:
        final = {name: getattr(self, name) for name in ("x", "g") if getattr(self, name)
                 is not None} | (_velocity_or_fibres(self) if self.f is not None else {})
        cost = "" if self.cost is None else f", cost {self.cost:.6g}"
        if self.t_states is not None:
            return self._summary(f"{len(self.t_states) - 1} steps, {len(self.t_states)} "
                                 f"states, {len(self.t)} nodes, {self.iterations} Newton "
                                 f"iterations{cost}", final)
        return self._summary(f"{max(len(self.t) - 1, 0)} steps, {len(self.t)} nodes, "
                             f"{self.iterations} Newton iterations{cost}", final)


#: The fields of a StepResult that a batch stacks, and their padding past a failure.
_STACKED = {"t": np.nan, "x": np.nan, "f": np.nan, "g": np.nan, "momenta": np.nan,
            "energy": np.nan, "noether": np.nan, "newton_iterations": -1}


@dataclass(frozen=True, repr=False)
class BatchResult(_Result):
    """A batch of stepped paths (``integrate_many``), stacked on a leading axis b.

    Attributes
    ----------
    t, x, f, g, momenta, energy, noether, newton_iterations : the arrays of
        :class:`StepResult`, each with a leading batch axis (B, …) (g: a tuple of such
        arrays with several group factors). Past a failed trajectory's last entry they
        are NaN (``newton_iterations``: −1); ``lengths[name][b]`` is how many entries
        of trajectory b are its own.
    statuses : (B,) the :class:`Status` value of each trajectory; ``messages`` their
        messages; ``succeeded`` a (B,) mask.
    status, message : SUCCESS when every trajectory succeeded, else the status of the
        first that failed and a message counting the failures and naming the first few.

    ``result[b]`` is trajectory b as the :class:`StepResult` of the single call (equal
    to it bit for bit); ``len(result)`` is B.
    """

    t: np.ndarray
    x: np.ndarray
    f: np.ndarray
    g: np.ndarray | tuple | None
    newton_iterations: np.ndarray
    statuses: np.ndarray
    messages: tuple
    lengths: dict
    status: Status
    message: str
    momenta: np.ndarray | None = None
    energy: np.ndarray | None = None
    noether: np.ndarray | None = None
    labels: dict | None = None

    @classmethod
    def stacked(cls, results: list) -> "BatchResult":
        """One result from the StepResults of a batch's trajectories."""
        arrays, lengths = {}, {}
        for name, pad in _STACKED.items():
            values = [getattr(r, name) for r in results]
            if values[0] is None:
                arrays[name] = None
            elif isinstance(values[0], tuple):
                parts = [_pad([v[i] for v in values], pad) for i in range(len(values[0]))]
                arrays[name], lengths[name] = tuple(p for p, _ in parts), parts[0][1]
            else:
                arrays[name], lengths[name] = _pad(values, pad)
        statuses = np.array([int(r.status) for r in results], dtype=np.int8)
        messages = tuple(r.message for r in results)
        status, message = cls.summary(statuses, messages)
        return cls(status=status, message=message, statuses=statuses, messages=messages,
                   lengths=lengths, labels=results[0].labels if results else None, **arrays)

    @classmethod
    def joined(cls, parts: list) -> "BatchResult":
        """One batch from the consecutive batches ``parts`` of one run (the chunks of a
        run on a cluster)."""
        arrays = {}
        for name, pad in _STACKED.items():
            values = [getattr(part, name) for part in parts]
            if values[0] is None:
                arrays[name] = None
            elif isinstance(values[0], tuple):
                arrays[name] = tuple(_join([v[i] for v in values], pad)
                                     for i in range(len(values[0])))
            else:
                arrays[name] = _join(values, pad)
        statuses = np.concatenate([part.statuses for part in parts])
        messages = tuple(m for part in parts for m in part.messages)
        lengths = {k: np.concatenate([part.lengths[k] for part in parts])
                   for k in parts[0].lengths}
        status, message = cls.summary(statuses, messages)
        return cls(status=status, message=message, statuses=statuses, messages=messages,
                   lengths=lengths, labels=parts[0].labels, **arrays)

    @staticmethod
    def summary(statuses: np.ndarray, messages, one: str = "trajectory",
                many: str = "trajectories") -> tuple[Status, str]:
        """The batch's status and message from its members' (``one``, ``many``: what
        they are called)."""
        failed = np.flatnonzero(statuses != Status.SUCCESS)
        status = Status(statuses[failed[0]]) if failed.size else Status.SUCCESS
        message = f"{len(statuses) - failed.size} of {len(statuses)} {many} succeeded"
        if failed.size:
            message += "; failed: " + "; ".join(
                f"{one} {b} ({Status(statuses[b]).name}: {messages[b]})"
                for b in failed[:3]) + ("; …" if failed.size > 3 else "")
        return status, message

    @property
    def succeeded(self) -> np.ndarray:
        return self.statuses == Status.SUCCESS

    def __len__(self) -> int:
        return len(self.statuses)

    def __getitem__(self, b: int) -> StepResult:
        def own(name):
            value = getattr(self, name)
            if value is None:
                return None
            n = self.lengths[name][b]
            return tuple(v[b, :n] for v in value) if isinstance(value, tuple) else value[b, :n]
        return StepResult(status=Status(self.statuses[b]), message=self.messages[b],
                          labels=self.labels, **{name: own(name) for name in _STACKED})

    def plot(self):
        raise TypeError("plot one trajectory of the batch: result[b].plot()")

    def __repr__(self) -> str:
        return (f"<BatchResult {self.status.name}: {self.message[:100]!r}; "
                f"{len(self)} trajectories of up to {self.t.shape[1]} nodes>")


@dataclass(frozen=True, repr=False)
class BVPBatch(_Result):
    """Whole-trajectory solves of a batch (``solve_bvp_many``, ``continuation``), in order.

    ``result[b]`` is solve b's :class:`BVPResult`; ``statuses``, ``succeeded``, ``cost``
    and ``T`` are arrays over the batch (cost NaN where a solve has none), and
    :meth:`stack` stacks one field of every solve. ``status`` is SUCCESS only when every
    solve succeeded; ``message`` counts the failures and names the first few.
    """

    results: tuple
    status: Status
    message: str

    @classmethod
    def of(cls, results: list) -> "BVPBatch":
        statuses = np.array([int(r.status) for r in results], dtype=np.int8)
        status, message = BatchResult.summary(statuses, [r.message for r in results],
                                              "solve", "solves")
        return cls(results=tuple(results), status=status, message=message)

    @property
    def statuses(self) -> np.ndarray:
        return np.array([int(r.status) for r in self.results], dtype=np.int8)

    @property
    def succeeded(self) -> np.ndarray:
        return self.statuses == Status.SUCCESS

    @property
    def cost(self) -> np.ndarray:
        return np.array([np.nan if r.cost is None else r.cost for r in self.results])

    @property
    def T(self) -> np.ndarray:
        return np.array([r.T for r in self.results])

    def stack(self, name: str) -> np.ndarray:
        """Field ``name`` (``"x"``, ``"g"``, ``"controls"``, …) of every solve, stacked."""
        return np.stack([getattr(r, name) for r in self.results])

    def __len__(self) -> int:
        return len(self.results)

    def __getitem__(self, b: int) -> BVPResult:
        return self.results[b]

    def save(self, file) -> None:
        raise TypeError("save each solve (result[b].save(...)) or the arrays of stack(...)")

    def plot(self):
        raise TypeError("plot one solve of the batch: result[b].plot()")

    def __repr__(self) -> str:
        return f"<BVPBatch {self.status.name}: {self.message[:100]!r}; {len(self)} solves>"


def _entries(name: str, value) -> dict:
    """``value`` as archive entries under ``name``: none for None, a status by its name,
    the parts of a dict or a State as ``name_part`` (``states_v``, ``history_mu``),
    several arrays as ``name_0``, ``name_1``, …, anything else as one array."""
    if value is None:
        return {}
    if isinstance(value, Status):
        return {name: np.array(value.name)}
    if isinstance(value, State):
        value = {part: getattr(value, part) for part in ("v", "x", "g")}
    if isinstance(value, dict):
        return {k: v for part, item in value.items() for k, v in
                _entries(f"{name}_{part}", item).items()}
    if isinstance(value, tuple) and value and isinstance(value[0], np.ndarray):
        return {f"{name}_{i}": v for i, v in enumerate(value)}
    return {name: np.asarray(value)}


def write_npz(file: str | os.PathLike, arrays: dict) -> None:
    """Write ``arrays`` to the NumPy archive ``file`` atomically: it appears whole or not
    at all (written beside it, then renamed, with the umask's mode)."""
    target = os.path.abspath(os.fspath(file))
    temporary = f"{target}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
    try:
        with open(temporary, "xb") as out:
            np.savez(out, **arrays)
        os.replace(temporary, target)
    except BaseException:
        if os.path.exists(temporary):
            os.unlink(temporary)
        raise


def _join(batches: list, pad) -> np.ndarray:
    """Batched arrays (B_i, L_i, …) joined on the batch axis, padded to the longest L."""
    width = max(b.shape[1] for b in batches)
    out = np.full((sum(len(b) for b in batches), width, *batches[0].shape[2:]), pad,
                  dtype=batches[0].dtype)
    at = 0
    for b in batches:
        out[at:at + len(b), :b.shape[1]] = b
        at += len(b)
    return out


def _pad(arrays: list, pad) -> tuple[np.ndarray, np.ndarray]:
    """The arrays stacked on a new first axis, the shorter ones padded at the end; and
    the length of each."""
    return _join([a[None] for a in arrays], pad), np.array([len(a) for a in arrays])


#: What :func:`_rebuild` builds, by the class's name.
_REBUILT = {cls.__name__: cls for cls in (StepResult, BVPResult, BatchResult, BVPBatch, State)}
#: What :class:`_Found` names, as this copy's own (its call here).
_LOCAL = _REBUILT | {"_rebuild": _rebuild, "Status": Status, "NewtonError": NewtonError}
