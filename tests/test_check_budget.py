"""`symvi check` reports as it goes and keeps to a time budget (issue 26, item 5).

The regularity check's singular locus of a planar Kepler model (factoring the step
matrix's determinant, 222 s measured) is the costly part the budget cuts: the check's
verdict (the generic rank) still comes, the summary and the closing lines say what was
skipped, and the signal handler and timer are left as they were.
"""
import signal
import threading
import time

import pytest

from symvi import Model
from symvi.checks import budget as budget_module
from symvi.checks import check, runner
from symvi.checks.budget import SKIPPED, Budget
from symvi.cli import main

KEPLER = '''
import sympy as sp
from symvi import Model, PairGroupoid, Symmetry
G = PairGroupoid("x y")
x, y = G.q
mu = sp.Symbol("mu", positive=True)
model = Model(name="kepler", groupoid=G, parameters={mu: 1.0},
              lagrangian=sum(v**2 for v in G.qdot) / 2 + mu / sp.sqrt(x**2 + y**2),
              symmetries=[Symmetry("angular_momentum", [-y, x])])
'''


def kepler() -> Model:
    """The model of :data:`KEPLER`, the model file the command-line test writes."""
    namespace: dict = {}
    exec(KEPLER, namespace)
    return namespace["model"]


def spin() -> None:
    while True:
        pass


def test_the_singular_locus_is_cut_at_the_budget_not_the_verdict(monkeypatch):
    monkeypatch.setattr(runner, "SLOW_CHECK", 0.3)
    handler, seen, lines = signal.getsignal(signal.SIGALRM), [], []
    start = time.monotonic()
    report = check(kepler(), only=["regularity", "noether"], budget=1.0,
                   on_result=seen.append, progress=lines.append)
    elapsed = time.monotonic() - start
    assert elapsed < 15, elapsed
    assert seen == list(report.results)                  # each as it finished, in order
    regularity = report["regularity"]
    assert regularity.status == "pass" and regularity.data["rank"] == 2
    assert regularity.data["skipped_for_budget"] == ("singular locus",)
    assert "singular locus skipped: over the check's time budget of 1 s" in regularity.summary
    assert "skipped_for_budget" not in report["noether"].data
    assert "skipped for the time budget: regularity (singular locus)" in report.format()
    assert any("check regularity is running" in line for line in lines), lines
    assert any(line.startswith("check regularity took") for line in lines), lines
    assert signal.getsignal(signal.SIGALRM) is handler
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)


def test_budget_interrupts_python_work_and_restores_the_timer():
    budget = Budget(0.2)
    budget.begin()
    start = time.monotonic()
    assert budget.attempt("spin", spin) is SKIPPED
    assert time.monotonic() - start < 2
    assert budget.attempt("after", lambda: 1) is SKIPPED      # nothing left: not called
    assert budget.skipped == ["spin", "after"]
    budget.begin()
    assert budget.attempt("quick", lambda a: a + 1, 1) == 2 and budget.skipped == []
    # off the main thread nothing can interrupt the part: it runs, within budget, to its end
    out = []
    worker = threading.Thread(target=lambda: out.append(budget.attempt("quick", sum, [1, 2])))
    worker.start()
    worker.join()
    assert out == [3]
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)
    for bad in (0, float("inf"), True):
        with pytest.raises(ValueError, match="positive, finite number of seconds"):
            Budget(bad)


def test_a_callers_timer_is_left_to_fire_on_time():
    """With another timer pending (a caller's alarm, pytest-timeout's) the budget does not
    take SIGALRM over: the part runs to its end and the caller's alarm fires when due."""
    fired = []
    previous = signal.signal(signal.SIGALRM, lambda s, f: fired.append(time.monotonic()))
    try:
        start = time.monotonic()
        signal.setitimer(signal.ITIMER_REAL, 0.3)
        budget = Budget(5.0)
        budget.begin()

        def work():
            while time.monotonic() - start < 1.0:
                pass
            return "done"
        assert budget.attempt("work", work) == "done"
        assert len(fired) == 1 and fired[0] - start < 0.6, [f - start for f in fired]
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def test_cli_prints_each_check_and_what_the_budget_skipped(tmp_path, capsys):
    model_file = tmp_path / "kepler.py"
    model_file.write_text(KEPLER)
    code = main(["check", str(model_file), "--only", "regularity,noether", "--budget", "1"])
    out = capsys.readouterr().out.splitlines()
    assert code == 0
    assert out[0] == "symvi check kepler"
    assert out[1].startswith("  PASS  regularity") and "time budget of 1 s" in out[1]
    assert out[2].startswith("  PASS  noether")
    assert out[-1] == ("skipped for the time budget: regularity (singular locus) (a larger "
                       "--budget runs them)")
    with pytest.raises(SystemExit) as exc:
        main(["check", str(model_file), "--budget", "-3"])
    assert exc.value.code == 2
    assert "positive number of seconds" in capsys.readouterr().err


def test_default_budget_and_none():
    from symvi.cli_arguments import budget
    assert budget_module.DEFAULT_BUDGET == 20.0
    assert budget("none") is None and budget("2.5") == 2.5
