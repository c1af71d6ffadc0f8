"""The solvers' options as one object each (issue 49, item 1): ``SolveOptions`` passed
whole from ``solve_bvp``/``solve_bvp_many``/``continuation`` to every phase, ``StepOptions``
for the step map, unknown names refused by name, the command line's flags.

A new option is declared once, as a field of ``_runtime/core/options.py`` (its default, its
meaning and its check), and read by the phase that uses it: the calls, the batch calls,
Dask and the command line pass it on without naming it. The tests below show real fields
flowing from the public call to the phase that reads them, and changing what it does.
"""
from __future__ import annotations

import dataclasses
import re
import importlib
from pathlib import Path

import numpy as np
import pytest

from symvi._runtime.core.options import SolveOptions as SymviSolveOptions
from symvi.cli import main
from symvi.models import get
from symvi.sweep import _replicate

ROOT = Path(__file__).resolve().parents[1]


def runtime_module(package, name: str):
    """The generated package's own copy of the run-time module ``name``
    (``"<part>.<module>"``, e.g. ``"bvp.newton"``)."""
    return importlib.import_module(f"{package.__name__}._runtime.{name}")


@pytest.fixture(scope="module")
def oc(compiled):
    """The double pendulum's optimal control (no bounds): the whole-trajectory Newton."""
    module = compiled("double_pendulum_oc")
    ex = get("double_pendulum_oc").example
    return module, ex, dict(guess=ex.guess_nodes(ex.n_steps, module.model.order))


@pytest.fixture(scope="module")
def slew(compiled):
    """The torque-limited slew: the bounded solve (interior point, penalty, certificate)."""
    module = compiled("spacecraft_slew")
    ex = get("spacecraft_slew").example
    return module, np.asarray(ex.start, float), np.asarray(ex.end, float), 60


def _solve(oc, **options):
    module, ex, guess = oc
    return module.solve_bvp(ex.start, ex.end, ex.n_steps, ex.h, **guess, **options)


def _same(a, b) -> None:
    """Two results equal to the bit: every array, number and message."""
    for field in dataclasses.fields(a):
        x, y = getattr(a, field.name), getattr(b, field.name)
        if isinstance(x, tuple) and x and isinstance(x[0], np.ndarray):
            for u, v in zip(x, y, strict=True):
                np.testing.assert_array_equal(u, v, err_msg=field.name)
        elif isinstance(x, np.ndarray):
            np.testing.assert_array_equal(x, y, err_msg=field.name)
        elif isinstance(x, dict):
            assert x.keys() == y.keys()
            for k in x:
                np.testing.assert_array_equal(x[k], y[k], err_msg=f"{field.name}[{k}]")
        else:
            assert x == y or (x != x and y != y), field.name


# -- one object, from the call to the phase ----------------------------------------------
def test_a_keyword_option_reaches_the_whole_trajectory_newton(oc, monkeypatch):
    """``solve_bvp(..., xtol=1e-7, verbose=True)``: the fixed-horizon phase calls the Newton
    iteration (``_runtime/bvp/newton.py``) with one ``SolveOptions`` holding both (the package's
    own class), the other fields at their defaults."""
    module = oc[0]
    bvp = runtime_module(module, "bvp.bvp")
    seen = []
    real = bvp.newton

    def spy(problem, path, options, *args):
        seen.append(options)
        return real(problem, path, options, *args)
    monkeypatch.setattr(bvp, "newton", spy)
    result = _solve(oc, xtol=1e-7, verbose=True)
    assert result.success and len(seen) == 1
    options = seen[0]
    assert type(options) is runtime_module(module, "core.options").SolveOptions
    assert (options.xtol, options.verbose, options.maxiter, options.ftol) == (1e-7, True, 100, 0.0)


def test_an_interior_point_option_reaches_the_interior_point(slew, monkeypatch):
    """``mu_start`` is named by no call, no batch, no Dask function: declared in
    ``SolveOptions`` and read by ``interior.py`` alone, it travels from ``solve_bvp``'s
    keywords through the bounded phase to the interior point, whose first barrier
    parameter it is, and the solve changes with it."""
    module, start, end, N = slew
    bounded = runtime_module(module, "bounded.bounded")
    seen = []

    class Spy(bounded.InteriorPoint):
        def __init__(self, problem, path, options, near=False):
            super().__init__(problem, path, options, near)
            seen.append((options, self.mu))
    monkeypatch.setattr(bounded, "InteriorPoint", Spy)
    default = module.solve_bvp(start, end, N, 1.0 / N)
    assert seen and all(o.mu_start == 10.0 and mu == 10.0 for o, mu in seen)
    seen.clear()
    changed = module.solve_bvp(start, end, N, 1.0 / N, mu_start=1e-3)
    assert seen and all(o.mu_start == 1e-3 and mu == 1e-3 for o, mu in seen)
    assert default.success and changed.success
    assert changed.history["mu"][0] == 1e-3 and default.history["mu"][0] == 10.0
    assert changed.iterations != default.iterations


def test_a_horizon_option_changes_the_free_horizon(compiled):
    """``horizon_maxiter`` (read by ``horizon.py`` alone, the outer iteration that
    ``horizon_method="secant"`` asks for): one secant step is not enough for the minimum-time
    slew, which then ends MAX_ITERATIONS naming it; the default, the horizon an unknown
    of Newton, finds the same T as the secant."""
    module = compiled("minimum_time_slew")
    ex = get("minimum_time_slew").example
    guess = ex.guess_nodes(ex.n_steps, module.model.order)
    solved = module.solve_bvp(ex.start, ex.end, ex.n_steps, ex.h, guess=guess)
    cut = module.solve_bvp(ex.start, ex.end, ex.n_steps, ex.h, guess=guess, horizon_maxiter=1,
                           horizon_method="secant")
    secant = module.solve_bvp(ex.start, ex.end, ex.n_steps, ex.h, guess=guess,
                              horizon_method="secant")
    assert solved.success, solved.message
    assert secant.success and abs(secant.T - solved.T) <= 1e-8, (secant.T, solved.T)
    assert cut.status.name == "MAX_ITERATIONS"
    assert cut.message.startswith("the free horizon did not converge in 1 steps")


def test_maxiter_one_is_max_iterations(oc):
    result = _solve(oc, maxiter=1)
    assert result.status.name == "MAX_ITERATIONS" and result.iterations <= 1
    assert "did not converge in 1 iterations" in result.message


def test_the_penalty_stages_reach_the_certificate(slew):
    """``penalty_stages`` and ``certifying_stages`` (read by ``penalty.py``): an infeasible
    torque limit is certified over the stages given, and the certificate names them."""
    module, start, end, N = slew
    default = module.solve_bvp(start, end, N, 1.0 / N, {"tau_max": 3.0})
    fewer = module.solve_bvp(start, end, N, 1.0 / N, {"tau_max": 3.0},
                             certifying_stages=(1e5, 1e6, 1e7))
    assert default.status.name == fewer.status.name == "INFEASIBLE"
    assert "to 1e+08 h" in default.message and "to 1e+07 h" in fewer.message


def test_verbose_prints_each_newton_iteration(oc, capsys):
    """``verbose=True`` (issue 50, item 7): under an IPOPT-like header, one line per Newton
    iteration on stderr — cost, infeasibilities, correction, step, shift, trials — the
    same as the result's ``history``, whose infeasibilities are the residual norms;
    nothing without it, and the same solve."""
    quiet = _solve(oc)
    assert capsys.readouterr().err == ""
    loud = _solve(oc, verbose=True)
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "symvi: whole trajectory: Newton" and err[1].startswith(" iter   objective")
    rows, h = err[2:], loud.history
    # a row per iteration, the last one's update (if any) counted among the iterations
    assert len(rows) == len(h["dual"]) and loud.iterations <= len(rows) <= loud.iterations + 1
    assert rows[-1].endswith(": SUCCESS")
    # residual_norms also holds the norm after the last update
    np.testing.assert_array_equal(np.maximum(h["primal"], h["dual"]),
                                  loud.residual_norms[:len(rows)])
    for k, row in enumerate(rows):
        fields = row.split()
        assert int(fields[0]) == k and float(fields[1]) == float(f"{h['objective'][k]:.7e}")
        assert float(fields[2]) == float(f"{h['primal'][k]:.2e}")
    assert np.isnan(h["mu"]).all() and (h["alpha"][:-1] > 0).all() and h["trials"][0] >= 1
    _same(quiet, loud)


# -- keywords and the object: the same solve ---------------------------------------------
def test_keywords_and_an_options_object_give_the_same_bits(oc, slew):
    module, ex, guess = oc
    options = module.model.SolveOptions(xtol=1e-11, maxiter=60)
    _same(_solve(oc, xtol=1e-11, maxiter=60), _solve(oc, options=options))
    _same(_solve(oc), _solve(oc, options=module.model.SolveOptions()))
    # another package's (or symvi's own) copy of the class, and a mapping, are accepted
    _same(_solve(oc, options=SymviSolveOptions(xtol=1e-11, maxiter=60)),
          _solve(oc, options={"xtol": 1e-11, "maxiter": 60}))
    bounded, start, end, N = slew
    for a, b in [(bounded.solve_bvp(start, end, N, 1.0 / N, maxiter=80),
                  bounded.solve_bvp(start, end, N, 1.0 / N, options={"maxiter": 80}))]:
        _same(a, b)
    starts, ends = (np.repeat(x[None], 2, axis=0) for x in (start, end))
    many = bounded.solve_bvp_many(starts, ends, N, 1.0 / N, xtol=1e-8, workers=1)
    also = bounded.solve_bvp_many(starts, ends, N, 1.0 / N, workers=1,
                                  options=bounded.model.SolveOptions(xtol=1e-8))
    path = {"tau_max": [11.0, 12.0]}
    walk = bounded.continuation(start, end, N, 1.0 / N, path, xtol=1e-8)
    again = bounded.continuation(start, end, N, 1.0 / N, path,
                                 options=SymviSolveOptions(xtol=1e-8))
    for x, y in zip(list(many) + list(walk), list(also) + list(again)):
        _same(x, y)


def test_step_options_as_keywords_or_object_give_the_same_bits(compiled):
    module = compiled("pendulum")
    ex = get("pendulum").example
    StepOptions = module.model.StepOptions
    a = module.integrate(ex.run_from, 500, ex.h, xtol=1e-13, maxiter=20)
    b = module.integrate(ex.run_from, 500, ex.h, options=StepOptions(xtol=1e-13, maxiter=20))
    _same(a, b)
    initial = _replicate(ex.run_from, 3)
    many = module.integrate_many(initial, 500, ex.h, xtol=1e-13, workers=1)
    also = module.integrate_many(initial, 500, ex.h, workers=1,
                                 options=StepOptions(xtol=1e-13))
    _same(many, also)
    short = module.integrate(ex.run_from, 500, ex.h, maxiter=1, xtol=1e-15)
    assert short.status.name == "MAX_ITERATIONS"


# -- refusals --------------------------------------------------------------------------
VALID = r"maxiter, xtol, ftol, verbose, mu_start"


@pytest.mark.parametrize("call, pattern", [
    (lambda m, ex, g: m.solve_bvp(ex.start, ex.end, ex.n_steps, ex.h, xtoll=1e-9),
     rf"^solve_bvp: unknown option\(s\) 'xtoll' \(did you mean 'xtol'\?\); the options "
     rf"\(SolveOptions\) are {VALID}"),
    (lambda m, ex, g: m.model.SolveOptions(xtoll=1e-9),
     rf"^SolveOptions: unknown option\(s\) 'xtoll' .* are {VALID}"),
    (lambda m, ex, g: m.model.SolveOptions().replace(mu_strat=1.0),
     r"^SolveOptions: unknown option\(s\) 'mu_strat' \(did you mean 'mu_start'\?\)"),
    (lambda m, ex, g: dataclasses.replace(m.model.SolveOptions(), tolerance=1.0),
     r"^SolveOptions: unknown option\(s\) 'tolerance'; the options"),
    (lambda m, ex, g: m.solve_bvp(ex.start, ex.end, ex.n_steps, ex.h, options={"xtoll": 1}),
     r"^solve_bvp: unknown option\(s\) 'xtoll'"),
    (lambda m, ex, g: m.solve_bvp(ex.start, ex.end, ex.n_steps, ex.h, xtol=1e-8,
                                  options=m.model.SolveOptions(maxiter=5)),
     r"^solve_bvp: option\(s\) 'xtol' given twice, as a keyword and in options="),
    (lambda m, ex, g: m.solve_bvp(ex.start, ex.end, ex.n_steps, ex.h, options=5),
     r"^solve_bvp: options must be a SolveOptions"),
    (lambda m, ex, g: m.solve_bvp_many(np.asarray(ex.start)[None], np.asarray(ex.end)[None],
                                       ex.n_steps, ex.h, verbosity=2),
     r"^solve_bvp_many: unknown option\(s\) 'verbosity' \(did you mean 'verbose'\?\)"),
], ids=["solve_bvp", "SolveOptions", "replace", "dataclasses.replace", "a mapping",
        "twice", "not options", "solve_bvp_many"])
def test_an_unknown_option_is_refused_by_name(oc, call, pattern):
    module, ex, guess = oc
    with pytest.raises(TypeError, match=pattern):
        call(module, ex, guess)


def test_an_unknown_step_option_is_refused_by_name(compiled):
    module = compiled("pendulum")
    ex = get("pendulum").example
    with pytest.raises(TypeError, match=r"^integrate: unknown option\(s\) 'mu_start'; the "
                                        r"options \(StepOptions\) are maxiter, xtol, ftol$"):
        module.integrate(ex.run_from, 10, ex.h, mu_start=1.0)
    with pytest.raises(TypeError, match=r"^integrate_many: unknown option\(s\) 'xtoll'"):
        module.integrate_many(_replicate(ex.run_from, 1), 10, ex.h, xtoll=1.0)


@pytest.mark.parametrize("given, error, pattern", [
    (dict(maxiter=0), ValueError, r"^maxiter must be at least 1, got 0"),
    (dict(xtol="1e-3"), ValueError, r"^xtol must be a real number"),
    (dict(ftol=-1.0), ValueError, r"^ftol must be finite and non-negative"),
    (dict(verbose=1), TypeError, r"^verbose must be True or False"),
    (dict(mu_start=0.0), ValueError, r"^mu_start must be positive and finite"),
    (dict(penalty_stages=(1e4, 1e2)), ValueError, r"^penalty_stages must be a non-empty, "
                                                  r"increasing sequence"),
    (dict(horizon_retries=-1), ValueError, r"^horizon_retries must be at least 0"),
    (dict(penalty_stages=(1e6,), certifying_stages=(1e2, 1e3)), ValueError,
     r"^certifying_stages must continue penalty_stages: its first penalty 100 is not "
     r"above their last 1e\+06"),
])
def test_each_value_is_checked_once_where_it_is_declared(given, error, pattern):
    with pytest.raises(error, match=pattern):
        SymviSolveOptions(**given)


def test_a_new_option_touches_only_options_and_its_phase():
    """What a new option costs, read from the code: the plumbing — the calls, the batch
    calls, their argument checks, Dask, the command line — names no option beyond the
    three its signatures show (``maxiter``, ``xtol``, ``ftol``, kept for ``help()``), and
    every option is read (``options.<name>``) by a phase of the runtime. So a new option
    is its field in ``options.py`` and the phase that reads it: two files."""
    runtime = ROOT / "symvi" / "_runtime"
    plumbing = [runtime / f"{name}.py" for name in (
        "bvp/bvp", "bvp/bvp_batch", "step/batch_arguments", "bvp/solve_arguments",
        "step/batch", "step/batch_loop", "step/stepping", "compiled")] + [
        ROOT / "symvi" / f"{name}.py" for name in (
            "dask", "cli", "cli_arguments", "sweep")]
    names = [f.name for f in dataclasses.fields(SymviSolveOptions)]
    for name in names:
        readers = [p.name for p in runtime.rglob("*.py")
                   if re.search(rf"options\.{name}\b", p.read_text())]
        assert readers, name
        if name not in ("maxiter", "xtol", "ftol", "verbose"):
            named = [p.name for p in plumbing if re.search(rf"\b{name}\b", p.read_text())]
            assert named == [], (name, named)


# -- the command line ------------------------------------------------------------------
def test_symvi_run_takes_the_options(build_dir, capsys):
    """``--maxiter 1`` stops the whole-trajectory Newton after one iteration (exit 1,
    MAX_ITERATIONS); ``--verbose`` prints its iterations on stderr; ``--xtol`` reaches
    the solve."""
    code = main(["run", "double_pendulum_oc", "--build-dir", str(build_dir), "--maxiter", "1"])
    out = capsys.readouterr().out
    assert code == 1 and "status     MAX_ITERATIONS" in out and "options    maxiter = 1" in out
    code = main(["run", "double_pendulum_oc", "--build-dir", str(build_dir), "--verbose",
                 "--xtol", "1e-8"])
    captured = capsys.readouterr()
    assert code == 0 and "options    xtol = 1e-08, verbose" in captured.out
    assert "symvi: whole trajectory: Newton\n iter   objective" in captured.err


@pytest.mark.parametrize("argv, message", [
    (["run", "double_pendulum_oc", "--xtol", "-1"], "--xtol must be finite and non-negative"),
    (["run", "double_pendulum_oc", "--maxiter", "0"], "--maxiter must be at least 1, got 0"),
    (["run", "double_pendulum_oc", "--mu-start", "0"], "--mu-start must be positive"),
    (["run", "pendulum", "--verbose"],
     "--verbose is an option of the whole-trajectory solve only; this example integrates "
     "step by step"),
    (["sweep", "pendulum", "--h", "0.01:0.02:3", "--ftol", "nan"],
     "--ftol must be finite and non-negative"),
])
def test_a_bad_option_flag_is_refused_before_the_build(tmp_path, capsys, argv, message):
    build = tmp_path / "never"
    code = main(argv + ["--build-dir", str(build)])
    err = capsys.readouterr().err
    assert code == 2 and message in err and not build.exists(), err


def test_symvi_sweep_takes_the_options(build_dir, tmp_path, capsys):
    """A sweep's runs use the options given: ``--maxiter 1 --xtol 1e-15`` fails every step
    of the pendulum's runs."""
    output = tmp_path / "s.npz"
    code = main(["sweep", "pendulum", "--build-dir", str(build_dir), "--h", "0.01:0.02:2",
                 "--steps", "100", "--maxiter", "1", "--xtol", "1e-15", "-o", str(output),
                 "--quiet"])
    out = capsys.readouterr().out
    assert code == 1 and "options    maxiter = 1, xtol = 1e-15" in out
    assert (np.load(output)["statuses"] == "MAX_ITERATIONS").all()


def test_options_objects_travel_to_dask_workers(slew, compiled):
    """An options object (the package's own class, which a fresh worker cannot unpickle
    before it loads the package) reaches the workers as its fields: the cluster's batch
    is the local one to the bit."""
    distributed = pytest.importorskip("distributed")
    import symvi.dask

    module, start, end, N = slew
    starts, ends = (np.repeat(x[None], 2, axis=0) for x in (start, end))
    options = module.model.SolveOptions(xtol=1e-8, maxiter=60)
    pendulum = compiled("pendulum")
    ex = get("pendulum").example
    initial = _replicate(ex.run_from, 2)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        remote = symvi.dask.solve_bvp_many(client, module, starts, ends, N, 1.0 / N,
                                           options=options, chunk=1)
        steps = symvi.dask.integrate_many(client, pendulum, initial, 200, ex.h,
                                          options=pendulum.model.StepOptions(xtol=1e-13))
    for x, y in zip(remote, module.solve_bvp_many(starts, ends, N, 1.0 / N, options=options)):
        _same(x, y)
    _same(steps, pendulum.integrate_many(initial, 200, ex.h, xtol=1e-13))
