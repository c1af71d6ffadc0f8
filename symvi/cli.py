"""Command line: ``symvi compile``, ``symvi run``, ``symvi sweep``, ``symvi check`` and
``symvi list``.

Exit codes: 0 success, 1 a build, a solve or a check failed, 2 bad input (model or
arguments), with one line on stderr in argparse's words (``symvi run: error: ...``).
Every argument — numbers, the files to write, the checks to run — is checked before
anything is compiled or run: a bad one costs no build, and no finished run is lost to
a file name that cannot be written.
"""
from __future__ import annotations

import argparse
import contextlib
import cProfile
import importlib
import pstats
import shutil
import sys
import textwrap
import time
import warnings
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from . import cli_arguments as arguments
from .version import __version__
from .errors import BuildError, ModelError
from .checks.budget import DEFAULT_BUDGET
from .models import BUNDLED, load


def _to_stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings (e.g. a damaged cached build being rebuilt) as one line, no source."""
    _to_stderr(f"symvi: warning: {message}")


def _compile(args) -> int:
    from .build import compile_model
    from .build.stages import StageClock
    # --timeout counts from here: loading the model file is the build's first stage
    clock = StageClock(args.model, args.timeout, None if args.quiet else _to_stderr,
                       args.verbose)
    with clock.stage("load model"):
        model = _load(args.model)
    _warn_if_shadowed(args.model, model.name)
    start = time.perf_counter()
    profiler = cProfile.Profile() if args.profile else contextlib.nullcontext()
    with warnings.catch_warnings(), profiler:
        warnings.showwarning = _show_warning
        compile_model(model, args.output, force=args.force, verbose=args.verbose,
                      clock=clock)
    target = Path(args.output) / model.name
    print(f"{model.name}: {target} ready in {time.perf_counter() - start:.2f} s "
          f"(import {model.name} with {args.output} on sys.path)")
    if args.profile:
        _print_profile(profiler)
    return 0


def _print_profile(profiler: cProfile.Profile) -> None:
    """``symvi compile --profile``: where the build's time went, on stderr — symvi's own
    functions by cumulative time (the stages and what they call), then the functions
    that spent the most time themselves (SymPy's, SymEngine's, the wait for the C
    compiler)."""
    stats = pstats.Stats(profiler, stream=sys.stderr)
    stats.sort_stats("cumulative").print_stats(r"symvi[/\\](derivation|codegen|discretisation|"
                                               r"declaration|build)", 20)
    stats.sort_stats("tottime").print_stats(12)


def _run(args) -> int:
    from .build import compile_model
    arguments.check_run_arguments(args)
    model = _load(args.model)
    ex = _example(model)
    params = arguments.parameters(args.param, model)
    steps = arguments.steps(args.steps, model, ex)
    options = arguments.solver_options(args, ex.whole_trajectory)
    start = time.perf_counter()
    module = compile_model(model, args.build_dir)
    built = time.perf_counter() - start
    # an optimal-control example keeps its horizon when only the steps change
    h = args.h if args.h is not None else \
        ex.h * ex.n_steps / steps if ex.whole_trajectory else ex.h
    print(f"model      {model.name} — {model.description}")
    print(f"build      {built:.2f} s ({Path(args.build_dir) / model.name})")
    if params:
        print(f"params     {', '.join(f'{k} = {v:g}' for k, v in params.items())}")
    _print_options(options)
    result = (_solve if ex.whole_trajectory else _integrate)(module, ex, steps, h, params,
                                                             args, options)
    _outputs(result, args)
    return 0 if result.success else 1


def _load(spec: str, loader: Callable = load):
    """``loader(spec)`` (the model; :func:`symvi.models.load_with_equations` for the
    checks) with a model file's folder first on ``sys.path`` while the file runs, as
    ``python model.py`` has it: the file may import the modules beside it."""
    with _folder_on_path(spec):
        return loader(spec)


@contextlib.contextmanager
def _folder_on_path(spec: str) -> Iterator[None]:
    """The folder of the model file ``spec`` first on ``sys.path`` inside the block (a
    bundled model's name: nothing), removed after it: the build and the run import the
    generated package, which a model file named like its model would shadow."""
    if Path(spec).suffix != ".py":
        yield
        return
    folder = str(Path(spec).parent.resolve())
    sys.path.insert(0, folder)
    try:
        yield
    finally:
        with contextlib.suppress(ValueError):     # the file took it out itself
            sys.path.remove(folder)


def _example(model):
    """The example run ``model`` declares (``symvi run`` and ``symvi sweep`` run it)."""
    if model.example is None:
        raise ModelError(f"model {model.name!r} declares no example run")
    return model.example


def _print_options(options: dict) -> None:
    """The solver's options given on the command line, if any."""
    if options:
        given = (name if value is True else f"{name} = {value:g}"
                 for name, value in options.items())
        print(f"options    {', '.join(given)}")


def _integrate(module, ex, steps: int, h: float, params: dict, args, options: dict):
    """The step-by-step example: integrate (the step map's ``options``) and summarise."""
    start = time.perf_counter()
    result = module.integrate(ex.run_from, steps, h, params, keep_every=args.keep_every,
                              **options)
    elapsed = time.perf_counter() - start
    if ex.state is not None:
        print(f"start      the state v = {np.array2string(np.asarray(ex.state.v, float))}"
              f"{'' if ex.state.x is None else f', x = {np.array2string(np.asarray(ex.state.x, float))}'}"
              f" (the first element by the discrete Legendre transform at this h)")
    print(f"integrate  {steps} steps, h = {h:g}, t = {result.t[0]:g} … {result.t[-1]:g}: "
          f"{elapsed * 1e3:.1f} ms ({steps / max(elapsed, 1e-9):,.0f} steps/s)")
    print(f"status     {result.status.name}: {result.message}")
    if len(result.newton_iterations):
        print(f"newton     mean {result.newton_iterations.mean():.2f} iterations per step")
    if result.energy is not None and len(result.energy):
        e = result.energy
        print(f"energy     E_0 = {e[0]:.12g}, max |E − E_0| = {np.abs(e - e[0]).max():.3e}")
    if result.g is not None:
        print(f"final      xi = {np.array2string(result.f[-1], precision=6)}, "
              f"g = {np.array2string(result.g[-1].ravel(), precision=6)}")
    else:
        print(f"final      q = {np.array2string(result.q[-1], precision=6)}")
    return result


def _solve(module, ex, steps: int, h: float, params: dict, args, options: dict):
    """The whole-trajectory example (optimal control): solve (under ``options``) and
    summarise. SciPy, which the solve imports on first use, is imported before the clock
    starts."""
    for name in ("scipy.linalg", "scipy.sparse.linalg"):
        importlib.import_module(name)
    start = time.perf_counter()
    result = module.solve_bvp(ex.start, ex.end, steps, h, params,
                              guess=ex.guess_nodes(steps, module.model.order), **options)
    elapsed = time.perf_counter() - start
    free = module.model.info.free_horizon
    # a free horizon's T and h are the solve's, not the guess passed in
    T, step = (result.T, float(result.t[1])) if free else (steps * h, h)
    print(f"solve_bvp  N = {steps}, h = {step:g}, T = {T:g}{' (free)' if free else ''}: "
          f"{elapsed * 1e3:.1f} ms, {result.iterations} Newton iterations")
    print(f"status     {result.status.name}: {result.message}")
    print(f"cost       {result.cost:.12g}")
    if free:
        print(f"horizon    T = {T:.10g} (free, from the guess {steps * h:g}; h = {step:.6g})")
    if result.end_multipliers is not None:
        ends = module.model.info.end_conditions
        print(f"end        ν = {np.array2string(result.end_multipliers, precision=6)} "
              f"for {', '.join(ends)}")
    if result.controls is not None:
        peak = np.abs(result.controls).max(axis=0)
        print(f"controls   max |u| per control = {np.array2string(peak, precision=6)}")
    if result.multipliers is not None:
        print(f"multipliers max |λ| = {np.abs(result.multipliers).max():.6g}")
    if result.active is not None:
        active = [f"{name} on {count}" for name, count in
                  zip(result.inequalities, result.active.sum(axis=0)) if count]
        print(f"bounds     active of {result.active.shape[0]} windows: "
              f"{', '.join(active) or 'none'}")
    return result


def _outputs(result, args) -> None:
    """``--output`` (the result's arrays, its ``save``) and ``--plot``."""
    if args.output is not None:
        result.save(args.output)
        print(f"output     {args.output}")
    if args.plot is not None:
        from .plots import plot_result
        plot_result(result, args.plot)
        print(f"plot       {args.plot}")


def _sweep(args) -> int:
    """``symvi sweep``: the example once per value of one swept parameter or step."""
    from .build import compile_model
    from .sweep import run_sweep
    arguments.check_sweep_arguments(args)
    model = _load(args.model)
    ex = _example(model)
    name, values, params = arguments.swept(args, model, ex)
    steps = arguments.steps(args.steps, model, ex)
    options = arguments.solver_options(args, ex.whole_trajectory)
    h = arguments.finite(args.h, "--h") if args.h is not None and name != "h" else \
        ex.h * ex.n_steps / steps if ex.whole_trajectory else ex.h
    output = args.output if args.output is not None else f"{model.name}_sweep.npz"
    arguments.check_file(output, "--output", arguments.RESULT_SUFFIXES)
    module = compile_model(model, args.build_dir)
    print(f"model      {model.name} — {model.description}")
    print(f"sweep      {name} = {values[0]:g} … {values[-1]:g} ({len(values)} values, "
          f"{args.spacing}), {steps} steps{'' if name == 'h' else f' of h = {h:g}'}")
    if name == "h" and ex.state is None:
        print("note       the example starts from nodes: its initial velocity (q₁ − q₀)/h "
              "changes with h")
    _print_options(options)
    start = time.perf_counter()
    result = run_sweep(module, ex, name, values, steps=steps, h=h, params=params,
                       workers=args.workers, keep_every=args.keep_every,
                       progress=False if args.quiet else None, options=options)
    print(f"time       {time.perf_counter() - start:.2f} s")
    for line in result.format():
        print(line)
    result.save(output)
    print(f"output     {output}")
    if args.plot is not None:
        from .plots import plot_sweep
        plot_sweep(result, f"{model.name}: {result.succeeded.sum()} of {len(values)} "
                           f"succeeded", args.plot, log_x=args.spacing == "log")
        print(f"plot       {args.plot}")
    return 0 if result.success else 1


def _check(args) -> int:
    from .checks import check
    from .checks.runner import CHECKS, selected
    from .models import load_with_equations
    only = None if args.only is None else selected(args.only, "--only")
    model, equations = _load(args.model, load_with_equations)
    if args.json:
        report = check(model, only=only, equations=equations, budget=args.budget,
                       progress=_stderr)
        print(report.to_json())
        return report.exit_code
    width = max(map(len, only or CHECKS))
    print(f"symvi check {model.name}", flush=True)
    report = check(model, only=only, equations=equations, budget=args.budget,
                   on_result=lambda r: print("\n".join(r.lines(width)), flush=True),
                   progress=_stderr)
    print("\n".join(report.closing()))
    return report.exit_code


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _list(args) -> int:
    """The bundled models, one per paragraph: the name, then its description wrapped to
    the terminal's width under a column as wide as the longest name."""
    from .models import get
    width = max(len(name) for name in BUNDLED) + 2
    columns = max(shutil.get_terminal_size((100, 24)).columns, width + 30)
    for name in BUNDLED:
        lines = textwrap.wrap(get(name).description, columns - width) or [""]
        print(f"{name:<{width}}{lines[0]}")
        for line in lines[1:]:
            print(" " * width + line)
    return 0


def _warn_if_shadowed(spec: str, name: str) -> None:
    """A model file named like its model (``planar_slew.py`` declaring ``planar_slew``)
    shadows the generated package for every script run from the file's folder: ``import
    planar_slew`` finds the file first. Say so, and how to avoid it."""
    path = Path(spec)
    if path.suffix == ".py" and path.stem == name:
        _to_stderr(f"symvi: warning: the model file {path.name} is named like its model "
                   f"{name!r}: a script run from {path.parent.resolve()} that imports "
                   f"{name} gets this file, not the generated package (it has no "
                   f"integrate or solve_bvp); rename the file, e.g. to {name}_model.py")


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="symvi", description="Compiler for structure-preserving "
                                "integrators on Lie groupoids.")
    p.add_argument("--version", action="version", version=f"symvi {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    c = sub.add_parser("compile", help="compile MODEL into an importable package")
    c.add_argument("model", help="a model file (.py defining `model`) or a bundled model name")
    c.add_argument("-o", "--output", default="generated", help="output directory")
    c.add_argument("--force", action="store_true", help="rebuild even if cached")
    c.add_argument("--verbose", action="store_true", help="show the compiler's output and "
                                                         "the time of each stage")
    c.add_argument("--timeout", type=arguments.seconds, default=None, metavar="SECONDS",
                   help="give up (exit 1) if the build takes longer, naming the stage "
                        "that was running")
    c.add_argument("--quiet", action="store_true", help="no progress lines (a stage that "
                                                       "runs over 2 s is announced otherwise)")
    c.add_argument("--profile", action="store_true", help="print where the time went: the "
                                                         "build's functions by time, on stderr")
    c.set_defaults(func=_compile)
    r = sub.add_parser("run", help="compile MODEL and run its example (integrate, or "
                                   "solve the whole trajectory of an optimal-control problem)",
                       description="Compile MODEL (cached) and run the example it declares: "
                                   "integrate it step by step, or solve the whole trajectory "
                                   "of an optimal-control problem; print a summary. Exit 0 on "
                                   "SUCCESS, 1 otherwise, 2 on bad input.")
    r.add_argument("model", help="a model file (.py defining `model`) or a bundled model name "
                                 "(symvi list)")
    r.add_argument("--build-dir", default="generated", metavar="DIR",
                   help="where the compiled package goes (default: generated)")
    r.add_argument("--param", action="append", metavar="NAME=VALUE",
                   help="override a parameter of the model (repeat for several)")
    r.add_argument("--steps", type=int, default=None,
                   help="number of steps (N for a whole-trajectory example, whose horizon "
                        "is kept unless --h is given); default: the example's")
    r.add_argument("--h", type=float, default=None, help="time step; default: the example's")
    r.add_argument("--keep-every", type=int, default=1, metavar="K",
                   help="store only every K-th node (long integrations)")
    r.add_argument("-o", "--output", default=None, metavar="FILE.npz",
                   help="write the result's arrays to a NumPy archive (numpy.load reads it)")
    r.add_argument("--plot", default=None, metavar="FILE.png",
                   help="write a plot of the result: configuration, velocities, and the "
                        "energy error or the controls (needs matplotlib)")
    arguments.add_option_flags(r)
    r.set_defaults(func=_run)
    _sweep_parser(sub)
    k = sub.add_parser("check", help="run the derivation checks on MODEL (exit 0: all "
                                     "pass, 1: a check failed, 2: bad input)")
    k.add_argument("model", help="a model file (.py defining `model` and optionally "
                                 "`equations`), a bundled model or a paper fixture "
                                 "(paper_rigid_body, paper_heavy_top_rotors)")
    k.add_argument("--only", default=None, help="comma-separated checks to run (default: "
                                                "all)")
    k.add_argument("--json", action="store_true", help="print the report as JSON")
    k.add_argument("--budget", type=arguments.budget, default=DEFAULT_BUDGET, metavar="SECONDS",
                   help=f"each check's time budget (default {DEFAULT_BUDGET:g}; 'none': "
                        f"unlimited): past it the costly optional parts (the singular "
                        f"locus, where a hand display differs) are skipped with a note, "
                        f"never a verdict")
    k.set_defaults(func=_check)
    ls = sub.add_parser("list", help="list the bundled models")
    ls.set_defaults(func=_list)
    return p


def _sweep_parser(sub) -> None:
    w = sub.add_parser("sweep", help="run MODEL's example over a range of one parameter or "
                                     "of the step; write the batch to .npz",
                       description="Compile MODEL (cached) and run its example once per "
                                   "value of one swept quantity — a parameter "
                                   "(--param NAME=start:stop:count) or the step "
                                   "(--h start:stop:count) — as one batch on all cores "
                                   "(an optimal-control example: a continuation, each solve "
                                   "warm-started from the last). Each run is judged by its "
                                   "energy error (or conserved quantities' drift, or Newton "
                                   "iterations), or by the optimal cost. Writes the batch "
                                   "to a NumPy archive and, with --plot, the judgement "
                                   "against the swept values. Exit 0 when every run "
                                   "succeeded, 1 otherwise, 2 on bad input.")
    w.add_argument("model", help="a model file (.py defining `model`) or a bundled model "
                                 "name (symvi list)")
    w.add_argument("--param", action="append", metavar="NAME=start:stop:count",
                   help="the swept parameter (start:stop:count), or a fixed one (NAME=VALUE); "
                        "repeat for several")
    w.add_argument("--h", default=None, metavar="H|start:stop:count",
                   help="the step, fixed or swept (a swept step keeps the number of steps); "
                        "default: the example's")
    w.add_argument("--steps", type=int, default=None,
                   help="steps per run (N of an optimal-control example, whose horizon is "
                        "kept); default: the example's")
    w.add_argument("--spacing", choices=("linear", "log"), default="linear",
                   help="spacing of the swept values (log: geometric, e.g. for steps)")
    w.add_argument("--workers", type=int, default=None,
                   help="threads (default: the usable cores)")
    w.add_argument("--keep-every", type=int, default=1, metavar="K",
                   help="store only every K-th node of each run (long or many runs)")
    w.add_argument("--build-dir", default="generated", metavar="DIR",
                   help="where the compiled package goes (default: generated)")
    w.add_argument("-o", "--output", default=None, metavar="FILE.npz",
                   help="the archive to write (default: MODEL_sweep.npz); numpy.load "
                        "reads it")
    w.add_argument("--plot", default=None, metavar="FILE.png",
                   help="write the summary plot: the judgement against the swept values "
                        "(needs matplotlib)")
    w.add_argument("--quiet", action="store_true", help="no progress bar")
    arguments.add_option_flags(w)
    w.set_defaults(func=_sweep)


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, MemoryError) as exc:
        # bad input (a ModelError is a ValueError) or a request refused before allocating
        # (with its estimate): one line in argparse's words, "symvi run: error: ..."
        print(f"symvi {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BuildError as exc:
        print(f"symvi: build failed: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:   # a file symvi did not expect to fail (the message names it)
        print(f"symvi: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("symvi: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
