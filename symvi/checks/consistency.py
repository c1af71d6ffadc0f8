"""Placeholder: check consistency is being written (issue 5)."""
from .report import CheckResult


def run(ctx):
    return CheckResult.skipped("consistency", "not written yet")
