"""Derivation checks that catch wrong models, wrong equations and wrong papers (issue 5).

``symvi check MODEL`` on the command line, :func:`check` from Python. Each check reports
pass, fail (with the offending expression or sample point) or skip; see :data:`CHECKS`.
"""
from .report import FAIL, PASS, SKIP, CheckReport, CheckResult
from .runner import CHECKS, Context, check, run_check

__all__ = ["check", "run_check", "CHECKS", "Context", "CheckReport", "CheckResult",
           "PASS", "FAIL", "SKIP"]
