"""Placeholder: check routes is being written (issue 5)."""
from .report import CheckResult


def run(ctx):
    return CheckResult.skipped("routes", "not written yet")
