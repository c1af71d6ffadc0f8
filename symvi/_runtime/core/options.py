"""The solvers' options, one frozen object per solver: :class:`SolveOptions` for the
whole-trajectory solve (``solve_bvp``, ``solve_bvp_many``, ``continuation``) and
:class:`StepOptions` for the step map (``integrate``, ``integrate_many``).

Each option is declared once, as a field here with its default, its meaning and the
check of its value (:func:`option`); the calls take the object (``options=``) or its
fields as keywords (:meth:`Options.of`), and pass it whole to every phase, which reads
the fields it needs. A new option is its field here and the code of the phase that
reads it: the calls, the batch calls, Dask and the command line (``symvi run``/``sweep``
make a flag of every number and switch here) pass it on unchanged. A name that is not
an option is refused by name, with the list of the valid ones.
"""
from __future__ import annotations

import difflib
import functools
import math
from dataclasses import MISSING, dataclass, field, fields, is_dataclass, replace
from typing import Callable, ClassVar, Mapping

from . import arguments


#: The fewest steps of a mesh sequence's coarse solve (``SolveOptions.coarse``): enough
#: free nodes for every order and boundary data (2, 3, 4 failed with raw IndexErrors).
MIN_COARSE = 10
#: The largest first barrier parameter of an interior point started near a solution (the
#: optimum without bounds, a start moved toward the bounds, a resampled coarse solution):
#: a larger μ pushes it out of its basin — the cart-pole swing-up from its upper minimum
#: itself, at μ = 10, went to the lower one; the planar flyer's penalised start took 248
#: iterations at N = 100 with μ = 10, 67 with μ = 0.1; the swing-up at N = 10⁴ from its
#: resampled coarse solution 25 at μ = 10, 9 at μ = 0.1.
NEAR_MU = 0.1


def option(default, doc: str, check: Callable[[object, str], object]):
    """A field of an options class: its ``default``, what it means (``doc``; the command
    line's help) and ``check(value, name)``, which returns the value normalised or raises
    a ValueError/TypeError naming the option."""
    return field(default=default, metadata={"doc": doc, "check": check})


def positive(value, what: str) -> float:
    """A positive, finite real number."""
    value = arguments.real(value, what)
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{what} must be positive and finite, got {value}")
    return value


def at_most(value, what: str, largest: float) -> float:
    """A positive, finite real number no larger than ``largest`` (beyond it the
    iteration's arithmetic overflows: μ = 1e200 raised OverflowError in the filter)."""
    value = positive(value, what)
    if value > largest:
        raise ValueError(f"{what} must be at most {largest:g}, got {value:g}")
    return value


def increasing(value, what: str) -> tuple[float, ...]:
    """A non-empty tuple of positive, finite, strictly increasing real numbers."""
    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise ValueError(f"{what} must be a sequence of positive numbers, got {value!r}")
    values = tuple(positive(v, f"{what}: each value") for v in value)
    if not values or any(b <= a for a, b in zip(values, values[1:])):
        raise ValueError(f"{what} must be a non-empty, increasing sequence, got {values}")
    return values


def one_of(value, what: str, choices: tuple[str, ...]) -> str:
    """One of the strings ``choices``."""
    if value not in choices:
        raise ValueError(f"{what} must be one of {', '.join(map(repr, choices))}, got "
                         f"{value!r}")
    return value


class Unset:
    """A call's default for an option it names in its signature (``solve_bvp(...,
    maxiter=100)``): equal to the option's default, so that ``inspect.signature`` and
    ``help()`` show it, but told apart from a value given (:meth:`Options.of` drops it,
    and the options' own default holds)."""


class _UnsetInt(Unset, int):
    pass


class _UnsetFloat(Unset, float):
    pass


class Options:
    """What the options classes share: construction that refuses an unknown name by name
    (``SolveOptions(xtoll=1e-9)``, ``options.replace(xtoll=1e-9)`` and
    ``dataclasses.replace`` alike), each field checked once in ``__post_init__``."""

    #: The default options (set below each class; a call naming no option shares them).
    DEFAULT: ClassVar[Options]

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, f.metadata["check"](getattr(self, f.name), f.name))

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The options' names, in declaration order."""
        return tuple(f.name for f in fields(cls))

    @classmethod
    def refuse_unknown(cls, given, call: str, note: str = "") -> None:
        """A TypeError naming each name in ``given`` that is not an option (with the
        closest option, where one is close) and listing the valid ones."""
        names = cls.names()
        unknown = [name for name in given if name not in names]
        if not unknown:
            return
        close = [difflib.get_close_matches(str(name), names, 1) for name in unknown]
        hints = [f"{name!r}" + (f" (did you mean {match[0]!r}?)" if match else "")
                 for name, match in zip(unknown, close)]
        raise TypeError(f"{call}: unknown option(s) {', '.join(hints)}; the options "
                        f"({cls.__name__}) are {', '.join(names)}{note}")

    @classmethod
    def unset(cls, name: str):
        """Option ``name``'s default as a call's signature shows it (:class:`Unset`)."""
        default = next(f.default for f in fields(cls) if f.name == name)
        return (_UnsetInt if isinstance(default, int) else _UnsetFloat)(default)

    @classmethod
    def of(cls, options=None, keywords: Mapping | None = None, call: str | None = None,
           note: str = ""):
        """The options of a call given ``options=`` (an instance, another package's copy
        of this class, a mapping, or None for the defaults) and ``keywords``, the options
        given by name (those left at a signature's :class:`Unset` default dropped); an
        option given both ways, or a name that is not an option, is refused."""
        call = call or cls.__name__
        keywords = {k: v for k, v in (keywords or {}).items() if not isinstance(v, Unset)}
        cls.refuse_unknown(keywords, call, note)
        if options is None:
            return cls(**keywords) if keywords else cls.DEFAULT
        if isinstance(options, cls) and not keywords:
            return options
        given = _fields_of(options, cls, call)
        cls.refuse_unknown(given, call, note)
        twice = sorted(set(given) & set(keywords))
        if twice:
            raise TypeError(f"{call}: option(s) {', '.join(map(repr, twice))} given twice, "
                            f"as a keyword and in options=; give each once")
        return cls(**given, **keywords)

    def replace(self, **changes):
        """A copy with ``changes`` (checked; an unknown name refused)."""
        return replace(self, **changes)

    def changed(self) -> dict:
        """The options that differ from their defaults, by name."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if f.default is MISSING or getattr(self, f.name) != f.default}

    @classmethod
    def describe(cls, name: str) -> str:
        """What option ``name`` means."""
        return next(f.metadata["doc"] for f in fields(cls) if f.name == name)


def _fields_of(options, cls, call: str) -> dict:
    """``options=`` as a mapping name → value: from an instance (or a copy of ``cls``
    from another package's runtime: every package carries its own) or a mapping."""
    if isinstance(options, Mapping):
        return dict(options)
    if is_dataclass(options) and not isinstance(options, type) \
            and type(options).__name__ == cls.__name__:
        return {f.name: getattr(options, f.name) for f in fields(options)}
    raise TypeError(f"{call}: options must be a {cls.__name__} (or a mapping of its "
                    f"fields), got {type(options).__name__}")


def _refusing_unknown(cls):
    """``cls`` whose constructor refuses a name that is not a field by name, listing the
    valid ones (the dataclass's own says only 'unexpected keyword argument')."""
    init = cls.__init__

    @functools.wraps(init)
    def __init__(self, **given):
        cls.refuse_unknown(given, cls.__name__)
        init(self, **given)
    cls.__init__ = __init__
    return cls


@_refusing_unknown
@dataclass(frozen=True, kw_only=True)
class SolveOptions(Options):
    """The options of the whole-trajectory solve, passed whole from ``solve_bvp``,
    ``solve_bvp_many`` and ``continuation`` to every phase: the fixed-horizon Newton
    (:mod:`.newton`), the bounded solve's start, penalty stages and interior point
    (:mod:`.bounded`, :mod:`.penalty`, :mod:`.interior`), the active-set Newton that
    finishes it (:mod:`.polish`) and the free horizon's outer iteration
    (:mod:`.horizon`). The defaults are the tested ones; the tuning knobs among them
    (barrier, penalty, active-set and horizon settings) were module constants before,
    with the same values."""

    maxiter: int = option(100, (
        "Newton iterations of each solve before MAX_ITERATIONS (each phase's own: the "
        "whole-trajectory Newton, the start without bounds, each penalty stage, each "
        "interior-point run). The default (SLSQP's) leaves room for constrained problems "
        "started far from feasibility: the non-planar heavy top from the chord guess "
        "takes 52–73"), arguments.iterations)
    xtol: float = option(1e-9, (
        "SUCCESS when the full Newton correction ‖Δ‖∞ plus its rounding floor is at most "
        "xtol·(1 + size), size the largest unknown (with bounds: the correction of the KKT "
        "system, μ = 0); the free horizon's distance to the optimal T within xtol·(1 + T)"),
        arguments.tolerance)
    ftol: float = option(0.0, (
        "SUCCESS also when the residual ‖R‖∞ ≤ ftol (unused with inequalities and in the "
        "phases that start them)"), arguments.tolerance)
    verbose: bool = option(False, (
        "print each iteration of the whole-trajectory Newton (its residual norm and the "
        "step taken) and of the interior point (barrier parameter, infeasibilities) on "
        "stderr"), arguments.flag)
    mu_start: float = option(10.0, (
        "the interior point's first barrier parameter μ (per unit time: a window's barrier "
        "term is μh log s), at most 1e10"), lambda value, what: at_most(value, what, 1e10))
    identify: float = option(1e-3, (
        "the interior point hands its iterate to the active-set Newton when its node "
        "correction is within identify·(1 + max |x|) (an active set again only from ten "
        "times closer)"), positive)
    interior_start: str = option("guess", (
        "where the interior point starts: 'guess', or 'unbounded' (the optimum of the "
        "problem without its inequalities, solved from the guess first; where the start "
        "from the guess fails, the solve goes on from there anyway)"),
        lambda value, what: one_of(value, what, ("guess", "unbounded")))
    line_search: str = option("filter", (
        "the interior point's line search: 'filter' (Wächter & Biegler's filter, the "
        "merit's step where it finds none) or 'merit' (Armijo on the barrier problem's "
        "ℓ1 penalty)"), lambda value, what: one_of(value, what, ("filter", "merit")))
    mu_strategy: str = option("probing", (
        "how μ falls once its barrier problem is solved: 'probing' (Mehrotra's: the "
        "affine-scaling step's complementarity decides, μ ← σ·sᵀz/m with σ = "
        "(μ_aff/μ)³, at most 0.2μ) or 'monotone' (μ ← 0.2μ)"),
        lambda value, what: one_of(value, what, ("monotone", "probing")))
    mu_floor: float = option(1e-3, (
        "the barrier parameter's floor, as a factor on xtol: μ falls no lower than "
        "mu_floor·xtol"), positive)
    kappa_epsilon: float = option(10.0, (
        "the barrier problem counts as solved, and μ falls, when its residuals per unit "
        "time are within kappa_epsilon·μ, or its Newton correction within the tolerance "
        "(IPOPT's κ_ε)"), positive)
    stagnation: int = option(6, (
        "interior-point iterations over which the KKT correction must halve to count as "
        "still converging (else rounding limits it: ILL_CONDITIONED, or finished by the "
        "active-set Newton)"), arguments.iterations)
    penalty_stages: tuple = option((1e2, 1e4), (
        "the penalties ρ/h of the stages that move a start toward violated bounds when "
        "the interior point fails from the optimum without them"),
        increasing)
    certifying_stages: tuple = option((1e5, 1e6, 1e7, 1e8), (
        "the penalties ρ/h after penalty_stages that test local infeasibility: a "
        "certificate where the largest violation stops falling"), increasing)
    polish_steps: int = option(6, (
        "Newton steps per active set of the active-set Newton that finishes the interior "
        "point"),
        arguments.iterations)
    polish_rounds: int = option(8, (
        "active sets the active-set Newton tries before it gives up"), arguments.iterations)
    coarse: int = option(250, (
        "mesh sequencing: a solve of N ≥ 8·coarse steps from no guess of its own (guess "
        "None, 'cubic' or 'chord') starts from the solution at `coarse` steps, resampled "
        "on the groupoid (boundary data: States, or ends at rest, or a pair groupoid's "
        "nodes); each solve has its own maxiter, and the result counts both solves' "
        "iterations; 0: from the guess, else at least 10"),
        lambda value, what: value if arguments.count(value, what, 0, arguments.INT_MAX) == 0
        else arguments.count(value, what, MIN_COARSE, arguments.INT_MAX,
                             " (or 0: no mesh sequencing)"))
    horizon_method: str = option("newton", (
        "how a free horizon is found: 'newton' (T an unknown of the Newton system; with "
        "inequalities, where it fails, the outer iteration follows) or 'secant' (the outer "
        "iteration of fixed-horizon solves alone, from nodes as boundary data)"),
        lambda value, what: one_of(value, what, ("newton", "secant")))
    horizon_maxiter: int = option(40, (
        "outer (secant) iterations of a free horizon before MAX_ITERATIONS"),
        arguments.iterations)
    horizon_retries: int = option(6, (
        "retries halfway back to the last solved horizon when a trial horizon's solve "
        "fails"), lambda value, what: arguments.count(value, what, 0, arguments.INT_MAX))

    def __post_init__(self) -> None:
        super().__post_init__()
        # the certificate's test (the violation stopped falling as ρ grew) holds only
        # where ρ goes on growing from the penalty stages
        if self.certifying_stages[0] <= self.penalty_stages[-1]:
            raise ValueError(
                f"certifying_stages must continue penalty_stages: its first penalty "
                f"{self.certifying_stages[0]:g} is not above their last "
                f"{self.penalty_stages[-1]:g}")


@_refusing_unknown
@dataclass(frozen=True, kw_only=True)
class StepOptions(Options):
    """The options of the step map's Newton iteration (in C, per step), for ``integrate``
    and ``integrate_many``.

    How each step is solved is an option; what a run computes and keeps is an argument of
    the call: ``keep_every``/``final_only`` and ``quantities`` change the result's
    contents and shape (and the memory it is refused for), not the numbers of the path, so
    they stay beside ``n_steps`` and ``h``, where the call's docstring states them."""

    maxiter: int = option(50, "Newton iterations of each step before MAX_ITERATIONS",
                          arguments.iterations)
    xtol: float = option(1e-12, "a step converges when ‖Δf‖∞ ≤ xtol·(1 + ‖f‖∞)",
                         arguments.tolerance)
    ftol: float = option(0.0, "a step converges also when ‖R‖∞ ≤ ftol",
                         arguments.tolerance)


# The defaults, checked once: a call that names no option shares them (they are frozen).
SolveOptions.DEFAULT = SolveOptions()
StepOptions.DEFAULT = StepOptions()
