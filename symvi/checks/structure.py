"""Placeholder: check structure is being written (issue 5)."""
from .report import CheckResult


def run(ctx):
    return CheckResult.skipped("structure", "not written yet")
