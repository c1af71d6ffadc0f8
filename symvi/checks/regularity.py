"""Placeholder: check regularity is being written (issue 5)."""
from .report import CheckResult


def run(ctx):
    return CheckResult.skipped("regularity", "not written yet")
