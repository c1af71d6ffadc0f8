"""``symvi check`` on every bundled model exits 0 (issue 5); the paper fixtures, which exit
1, are tests/test_check_equations.py's."""
from __future__ import annotations

import json

import pytest

from symvi.checks import CHECKS
from symvi.cli import main
from symvi.models import BUNDLED, get


@pytest.mark.parametrize("name", BUNDLED)
def test_every_check_passes_or_does_not_apply_on_bundled_models(name, capsys):
    """Each check once per bundled model (the per-check tests use small models of their
    own): geometry, consistency and regularity pass, never skipped, with the numbers
    each check is about — but for pure minimum time, whose Lagrangian is zero."""
    code = main(["check", name, "--json"])
    report = json.loads(capsys.readouterr().out)
    failed = [(r["name"], r["summary"], r["details"]) for r in report["results"]
              if r["status"] == "fail"]
    assert code == 0 and not failed, failed
    assert [r["name"] for r in report["results"]] == list(CHECKS)
    results = {r["name"]: r for r in report["results"]}
    statuses = {c: r["status"] for c, r in results.items()}
    model = get(name)
    if model.control_system is not None and model.control_system.pure_minimum_time:
        # the cost is T alone: a zero Lagrangian, no step map to check (issue 50)
        assert all(statuses[c] == "skip" and "pure minimum time" in results[c]["summary"]
                   for c in ("consistency", "regularity", "structure")), statuses
        assert statuses["algebroid"] == statuses["routes"] == "pass", statuses
        return
    assert all(statuses[c] == "pass" for c in ("algebroid", "consistency", "regularity")), \
        statuses
    order = model.order
    if order <= 2:
        # the Σ_{L_d} route of paper §4.2 agrees with the engine's residual to 50 digits
        routes = results["routes"]["data"]
        assert statuses["routes"] == "pass"
        assert routes["order"] == order and routes["max_relative_difference"] < 1e-28
        assert ("+R" if order == 1 else "−R") in routes["convention"]
    else:   # the paper builds Σ_{L_d} for orders 1 and 2 only
        assert statuses["routes"] == "skip" and "order" in results["routes"]["summary"]
    consistency = results["consistency"]
    data = consistency["data"]
    assert (data["power"], data["sign"], data["order"], data["next_power"]) == (1, 1, 2, 3)
    assert data["seconds"] < 20
    assert consistency["summary"].startswith("consistent: R = +h^1·E + O(h^3) (order 2)")
    if model.constraints:
        assert data["constraints"]["power"] == 1 and data["constraints"]["order"] == 2
        assert "constraints Φ_d = +h^1·Φ + O(h^3) (order 2)" in consistency["summary"]
    regularity = results["regularity"]["data"]
    assert regularity["rank"] == regularity["size"]
    if model.constraints:       # the step matrix bordered by the constraints' Jacobian
        assert results["regularity"]["summary"].startswith("bordered step matrix")


def test_bad_input_exits_2(capsys):
    assert main(["check", "no_such_model"]) == 2
    assert main(["check", "pendulum", "--only", "sanity"]) == 2
    assert "unknown check" in capsys.readouterr().err
