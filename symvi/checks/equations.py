"""Placeholder: check equations is being written (issue 5)."""
from .report import CheckResult


def run(ctx):
    return CheckResult.skipped("equations", "not written yet")
