"""``symvi check`` on every bundled model exits 0; the paper fixtures exit 1 (issue 5)."""
from __future__ import annotations

import json

import pytest

from symvi.checks import CHECKS
from symvi.cli import main
from symvi.fixtures import FIXTURES
from symvi.models import BUNDLED


@pytest.mark.parametrize("name", BUNDLED)
def test_every_check_passes_or_does_not_apply_on_bundled_models(name, capsys):
    code = main(["check", name, "--json"])
    report = json.loads(capsys.readouterr().out)
    failed = [(r["name"], r["summary"], r["details"]) for r in report["results"]
              if r["status"] == "fail"]
    assert code == 0 and not failed, failed
    assert [r["name"] for r in report["results"]] == list(CHECKS)
    statuses = {r["name"]: r["status"] for r in report["results"]}
    # Every model is checked for geometry, consistency and regularity, never skipped.
    assert all(statuses[c] == "pass" for c in ("algebroid", "routes", "consistency",
                                               "regularity")), statuses


@pytest.mark.parametrize("fixture", FIXTURES)
def test_paper_fixtures_fail_with_their_slips(fixture, capsys):
    assert main(["check", fixture, "--only", "equations"]) == 1
    text = capsys.readouterr().out
    assert "FAIL  equations" in text and "agree:" in text


def test_bad_input_exits_2(capsys):
    assert main(["check", "no_such_model"]) == 2
    assert main(["check", "pendulum", "--only", "sanity"]) == 2
    assert "unknown check" in capsys.readouterr().err
