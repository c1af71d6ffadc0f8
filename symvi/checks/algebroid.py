"""Placeholder: check algebroid is being written (issue 5)."""
from .report import CheckResult


def run(ctx):
    return CheckResult.skipped("algebroid", "not written yet")
