"""The command line's arguments, checked before any work: the numbers (steps, the step h,
the workers), the solvers' options (``--xtol``, ``--maxiter``, ``--verbose``, …), the
files a command writes (their folder, their suffix, never a directory), the checks to
run, and the parameters against their declared signs — so that a bad one costs no build
and no finished run is lost to a name that cannot be written."""
from __future__ import annotations

import argparse
import importlib.util
import math
import os
from dataclasses import Field, fields
from pathlib import Path
from typing import Sequence

import numpy as np

from ._runtime.core.signs import SIGNS
from ._runtime.core.options import SolveOptions, StepOptions
from .declaration.symbols import sign

#: What ``--output`` writes: a NumPy archive (``save``), whatever the name's suffix.
RESULT_SUFFIXES = (".npz",)


#: The options classes whose numbers and switches ``symvi run`` and ``symvi sweep`` take
#: as flags: the step map's and the whole trajectory's.
SOLVERS = (StepOptions, SolveOptions)
#: What the help calls each.
SOLVER_NAMES = {StepOptions: "for the step map", SolveOptions: "for the whole-trajectory solve"}
#: The field types a flag can give (sequences are for the Python calls).
FLAG_TYPES = {"int": int, "float": float, "bool": bool, "str": str}


def option_fields() -> dict[str, tuple[Field, tuple[type, ...]]]:
    """Each option that can be a flag: name → (its field, the options classes that have
    it), in declaration order."""
    out: dict[str, tuple[Field, tuple[type, ...]]] = {}
    for solver in SOLVERS:
        for f in fields(solver):
            if f.type in FLAG_TYPES:
                field, owners = out.get(f.name, (f, ()))
                out[f.name] = (field, owners + (solver,))
    return out


def flag_of(name: str) -> str:
    """The flag of option ``name``: ``--kappa-epsilon``."""
    return "--" + name.replace("_", "-")


def add_option_flags(parser) -> None:
    """A flag for every option of :func:`option_fields`, its help the option's own
    description (``_runtime/core/options.py``): a new option needs no edit here."""
    group = parser.add_argument_group(
        "solver options", "Newton's options, of the step map (integrate) or of the whole-"
        "trajectory solve (optimal control); default: the solver's")
    for name, (field, owners) in option_fields().items():
        defaults = ", ".join(f"{next(f.default for f in fields(solver) if f.name == name)!r}"
                             f" {SOLVER_NAMES[solver]}" for solver in owners)
        only = "" if len(owners) == len(SOLVERS) else \
            f"; {SOLVER_NAMES[owners[0]]} only"
        text = f"{field.metadata['doc']}{only} (default {defaults})".replace("%", "%%")
        if FLAG_TYPES[field.type] is bool:
            group.add_argument(flag_of(name), dest=name, action="store_const", const=True,
                               default=None, help=text)
        else:
            group.add_argument(flag_of(name), dest=name, type=FLAG_TYPES[field.type],
                               default=None, metavar=name.upper(), help=text)


def check_option_flags(args) -> None:
    """The options given as flags, each checked by its own option's check, in the flag's
    words (``--xtol must be finite and non-negative, got -1``)."""
    for name, (field, _) in option_fields().items():
        value = getattr(args, name)
        if value is not None:
            try:
                field.metadata["check"](value, flag_of(name))
            except TypeError as exc:
                raise ValueError(str(exc)) from None


def solver_options(args, whole_trajectory: bool) -> dict:
    """The options given as flags, by name, for the example's solver (the whole-trajectory
    solve's or the step map's); a flag of the other solver only is refused, naming it."""
    solver, given = SolveOptions if whole_trajectory else StepOptions, {}
    for name, (_, owners) in option_fields().items():
        value = getattr(args, name)
        if value is None:
            continue
        if solver not in owners:
            other = "the step map" if whole_trajectory else "the whole-trajectory solve"
            this = "solves a whole trajectory" if whole_trajectory else \
                "integrates step by step"
            raise ValueError(f"{flag_of(name)} is an option of {other} only; this "
                             f"example {this}")
        given[name] = value
    return given


def check_run_arguments(args) -> None:
    """``symvi run``'s numbers, options and files, refused before the model is even
    loaded: a run that ends in a bad name or a missing folder loses its work."""
    check_option_flags(args)
    check_count(args.steps, "--steps")
    check_count(args.keep_every, "--keep-every")
    if args.h is not None:
        check_step(args.h, "--h")
    check_build_dir(args.build_dir)
    check_file(args.output, "--output", RESULT_SUFFIXES)
    check_plot(args.plot)


def check_sweep_arguments(args) -> None:
    """``symvi sweep``'s numbers, options and files that need no model (the default
    ``--output`` is named after it, and checked once it is loaded)."""
    check_option_flags(args)
    check_count(args.steps, "--steps")
    check_count(args.keep_every, "--keep-every")
    check_count(args.workers, "--workers")
    if args.h is not None and ":" not in args.h:
        check_step(finite(args.h, "--h"), "--h")
    check_build_dir(args.build_dir)
    check_file(args.output, "--output", RESULT_SUFFIXES)
    check_plot(args.plot)


def check_count(value: int | None, flag: str, fewest: int = 1, why: str = "") -> None:
    """Refuse an integer option below ``fewest`` (None: not given, the default holds);
    ``why`` explains the bound."""
    if value is not None and value < fewest:
        raise ValueError(f"{flag} must be an integer ≥ {fewest}{why}, got {value}")


def check_step(value: float, flag: str) -> None:
    """Refuse a time step that is not positive and finite."""
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{flag} must be a positive, finite time step, got {value:g}")


def check_build_dir(path: str) -> None:
    """``--build-dir``: the build creates it and the folders above it, so refuse only
    what would stop it — a file in the place of one of them, or an existing folder it
    cannot write in."""
    for folder in (Path(path), *Path(path).absolute().parents):
        if folder.is_dir():
            if not os.access(folder, os.W_OK | os.X_OK):
                raise ValueError(f"--build-dir {path!r}: the folder {str(folder)!r} is not "
                                 f"writable")
            return
        if folder.exists():
            raise ValueError(f"--build-dir {path!r}: {str(folder)!r} is a file, not a folder")


def check_file(path: str | None, flag: str, suffixes: Sequence[str]) -> None:
    """Refuse a file the command could not write when it ends: a name without one of
    ``suffixes`` (the format written), a directory, or a folder that is missing or not
    writable. An existing file or symlink is fine: it is replaced (never written through)."""
    if path is None:
        return
    target = Path(path)
    if target.is_dir() and not target.is_symlink():
        raise ValueError(f"{flag} {path!r} is a directory: give a file name, e.g. "
                         f"{str(target / ('result' + suffixes[0]))!r}")
    if target.suffix.lower() not in suffixes:
        raise ValueError(f"{flag} {path!r}: give a file name ending in "
                         f"{', '.join(suffixes)} (the format written)")
    folder = target.parent
    if not folder.is_dir():
        raise ValueError(f"{flag} {path!r}: the folder {str(folder)!r} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ValueError(f"{flag} {path!r}: the folder {str(folder)!r} is not writable")


def check_plot(path: str | None) -> None:
    """``--plot``: matplotlib installed, and a file it can write (its formats' suffixes)."""
    if path is None:
        return
    check_plot_support()
    from .plots import formats
    check_file(path, "--plot", formats())


def steps(given: int | None, model, ex) -> int:
    """``--steps`` (default: the example's), at least the fewest the example's run takes."""
    if given is None:
        return ex.n_steps
    check_count(given, "--steps", *fewest_steps(model, ex))
    return given


def fewest_steps(model, ex) -> tuple[int, str]:
    """The fewest steps of the example's run and why, counted as the run time counts them
    (``integrate``'s ``step_count``, ``solve_bvp``'s ``n_steps``) but before the build:
    an order-r integration's initial data spans 2r − 1 elements; a whole trajectory has r
    fixed nodes at each end (States: one element each) and a free node between."""
    from ._runtime.core.results import State
    r = model.order
    if not ex.whole_trajectory:
        return 2 * r - 1, (f" (the initial data's {2 * r - 1} elements count among the steps)"
                           if r > 1 else " (the initial data's element counts among the steps)")
    if isinstance(ex.start, State):
        return 2 * r - 1, (" (States fix the first and last elements, and one free node lies "
                           "between them)")
    return 2 * r, (f" ({r} fixed node{'s' if r > 1 else ''} at each end of an order-{r} "
                   f"problem and at least one free node between them)")


def swept(args, model, ex) -> tuple[str, np.ndarray, dict[str, float]]:
    """``symvi sweep``'s swept quantity: its name (a parameter's, or ``"h"``), its values
    (spaced as ``--spacing`` says), and the fixed ``--param`` values."""
    swept = [item for item in args.param or () if ":" in item.partition("=")[2]]
    h_values = range(args.h, "--h") if args.h is not None else None
    if len(swept) + (h_values is not None) != 1:
        raise ValueError("sweep one quantity: give exactly one --param NAME=start:stop:count "
                         "or --h start:stop:count (the other --param values are fixed)")
    params = parameters([item for item in args.param or () if item not in swept], model)
    if swept:
        name, _, text = swept[0].partition("=")
        name = parameter_name(name, model)
        flag, values = f"--param {name}", range(text, f"--param {name}")
    else:
        name, flag, values = "h", "--h", h_values
    if name == "h" and ex.whole_trajectory:
        raise ValueError("an optimal-control sweep varies a parameter; the step of a whole "
                         "trajectory follows from --steps and its horizon")
    if args.spacing == "log":
        values = geometric(values, flag)
    if name == "h":
        for value in (values[0], values[-1]):     # the ends bound every value between
            check_step(value, flag)
    else:
        check_sign(name, values, model, flag)
    return name, values, params


def parameters(given: list[str] | None, model) -> dict[str, float]:
    """``--param NAME=VALUE`` (repeated) as a mapping, each name a parameter of ``model``
    and each value a finite number of the sign its symbol was declared with."""
    out = {}
    for item in given or ():
        name, sep, text = item.partition("=")
        if not sep or not name.strip():
            raise ValueError(f"--param expects NAME=VALUE, got {item!r}")
        name = parameter_name(name, model)
        out[name] = finite(text, f"--param {name}")
        check_sign(name, np.array([out[name]]), model, f"--param {name}")
    return out


def check_sign(name: str, values: np.ndarray, model, flag: str) -> None:
    """Refuse, before the build, values the run time refuses for parameter ``name``
    declared with a sign (a mass declared ``positive=True`` cannot be −1), in its words."""
    declared = sign(next(s for s, _ in model.parameters if str(s) == name))
    if declared is None:
        return
    test, bound = SIGNS[declared]
    for value in values:
        if not test(value):
            raise ValueError(f"{flag}: parameter {name} is declared {declared} (its symbol's "
                             f"assumption): it must be {bound}, got {value:g}")


def parameter_name(name: str, model) -> str:
    """``name`` (stripped), which must be a parameter of ``model``."""
    name, known = name.strip(), [str(k) for k, _ in model.parameters]
    if name not in known:
        raise ValueError(f"--param {name}: model {model.name!r} has no parameter "
                         f"{name!r}; its parameters: {known or 'none'}")
    return name


def range(text: str, what: str) -> np.ndarray | None:
    """``start:stop:count`` as ``count`` values from start to stop (linear spacing), or
    None when ``text`` is one value (no colon)."""
    if ":" not in text:
        return None
    parts = text.split(":")
    if len(parts) != 3:
        raise ValueError(f"{what}: expected start:stop:count, got {text!r}")
    start, stop = (finite(part, what) for part in parts[:2])
    try:
        count = int(parts[2])
    except ValueError:
        count = 0
    if count < 2:
        raise ValueError(f"{what}: the count of start:stop:count must be an integer ≥ 2, "
                         f"got {parts[2]!r}")
    return np.linspace(start, stop, count)


def geometric(values: np.ndarray, what: str) -> np.ndarray:
    """The same count of values from the first to the last, geometrically spaced."""
    if not (values[0] > 0 and values[-1] > 0):
        raise ValueError(f"{what}: a logarithmic spacing needs positive end points, got "
                         f"{values[0]:g} and {values[-1]:g}")
    return np.geomspace(values[0], values[-1], len(values))


def check_plot_support() -> None:
    """Refuse ``--plot`` before building and running when matplotlib is missing."""
    if importlib.util.find_spec("matplotlib") is None:
        from .plots import MISSING
        raise ValueError(MISSING)


def budget(text: str) -> float | None:
    """``--budget``'s value: positive seconds, or 'none' for no limit."""
    return None if text.strip().lower() == "none" else seconds(text)


def number(text: str) -> float:
    """``text`` as a float, NaN where it is not a number."""
    try:
        return float(text)
    except ValueError:
        return math.nan


def finite(text: str, what: str) -> float:
    """``text`` as a finite number, else a ValueError naming ``what``."""
    value = number(text)
    if not math.isfinite(value):
        raise ValueError(f"{what}: expected a finite number, got {text!r}")
    return value


def seconds(text: str) -> float:
    """``--timeout``'s value: a positive, finite number of seconds."""
    value = number(text)
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return value
