"""Placeholder: check noether is being written (issue 5)."""
from .report import CheckResult


def run(ctx):
    return CheckResult.skipped("noether", "not written yet")
